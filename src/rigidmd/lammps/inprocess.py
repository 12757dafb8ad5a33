r"""LAMMPS forces at LAMMPS speed: an ASE calculator on one persistent LAMMPS instance.

:class:`LAMMPSCalculator` takes the interaction commands of a LAMMPS input
(``pair_style``, ``pair_coeff``, ``kspace_style``, ...: the same list an
exported deck uses) and creates the atoms once.  Each later call writes the
positions straight into LAMMPS's own array, in LAMMPS's current periodic
image of each atom (so only real motion counts against the neighbour skin),
runs one step without set-up and without an integrator
(``run 1 pre no post no``), and reads energy, forces and the virial back: one
force evaluation per call, about one native LAMMPS step.  As in a native run,
the energy and the virial are tallied only on the steps that ask for them
(a call for forces alone costs neither; a call for the stress alone, with the
box plugin, not the energy).

When the cell changes (a barostat), the new box costs what it costs LAMMPS's
own barostats: a small LAMMPS plugin (:mod:`rigidmd.lammps.boxplugin`, built
once per user at the first cell change) sets the box and re-sets only the
k-space solver (PPPM's Green's function for the new box), and the next step
re-neighbours when the atoms or the box corners have moved by half the skin
(the first new cell of an instance runs one set-up, which takes the plugin's
fix in; a fixed cell loads the plugin only to ask for a stress without the
energy).  Where the plugin cannot be built
or loaded (said once, with the reason), the box is changed with
``change_box`` and that call runs LAMMPS's whole set-up (``run 0 pre yes``).
Either way the k-space parameters of the first cell are kept
(:attr:`LAMMPSCalculator.kspace_parameters`): energies, forces and stress
equal those of a fresh LAMMPS at that cell given those parameters.  The
instance stays whatever the cell does: cells that are not in LAMMPS's
lower-triangular form are rotated into it anew at each cell
(positions, forces and stress rotated back), the basis is reduced to LAMMPS's
tilt limits (the same lattice; PPPM's mesh follows the basis, so a tilt of
several box lengths otherwise gave other numbers; a flip of the reduced basis
runs one set-up), and an orthogonal box that gets tilted becomes triclinic
once.  A change in the number or kind of atoms, their charges or their
molecules builds a new instance.

Molecules (for ``neigh_modify exclude molecule/intra all``) are the bodies of
the rigid dynamics the atoms are in (a ``mol-id`` array, tags or
``molecule_ids`` that group the atoms otherwise are refused); outside a
dynamics they come from ``molecule_ids`` when given (the explicit argument
wins), else from the ``mol-id`` array (ASE's ``lammps-data`` reader sets it),
else from non-zero tags.

Masses never enter a force call: atoms of one element share a type whatever
their masses (H and D).  LAMMPS's warnings at set-up are passed on as Python
warnings; positions and cells that are not finite are refused before LAMMPS
sees them (LAMMPS would hang on them).
"""

import warnings
from pathlib import Path

import numpy as np
from ase.calculators.calculator import Calculator, all_changes
from ase.stress import voigt_6_to_full_3x3_stress

from rigidmd.core.checks import check_finite, copy_atoms, quick_check_state, real_number
from rigidmd.lammps.atomtypes import (
    check_molecule_ids,
    lammps_molecule_ids,
    lammps_types,
    molecules_of,
)
from rigidmd.lammps.box import lower_triangular
from rigidmd.lammps.instance import LammpsInstance, chosen_kspace
from rigidmd.lammps.library import (
    DEFAULT_CMDARGS,
    LammpsError,
    check_atom_types,
    flatten,
    lammps_warnings,
    load_lammps,
)

__all__ = ["LAMMPSCalculator", "check_atoms", "check_kspace_parameters", "check_skin",
           "lower_triangular"]

_COULOMB = ("coul", "kspace_style", "tip4p")
#: LAMMPS's pressure components (xx yy zz xy xz yz) in ASE's Voigt order (xx yy zz yz xz xy).
_ASE_VOIGT = [0, 1, 2, 5, 4, 3]


def _threads(threads):
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"LAMMPSCalculator: threads must be a positive whole number, got "
                         f"{threads!r}")
    return int(threads)


def check_skin(skin, owner):
    """The neighbour skin (Å) as a float: a finite number >= 0, else one error naming
    ``skin`` and ``owner`` (TypeError for what is not a number, ValueError otherwise)."""
    value = real_number(f"{owner}: skin", skin, "a finite number >= 0 (Å)")
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{owner}: skin must be a finite number >= 0 (Å), got {skin!r}")
    return value


def check_kspace_parameters(value, owner):
    """Refuse ``value`` unless it is one ``kspace_modify gewald ...`` command or None
    (``owner``: the class named in the message)."""
    if value is not None and (not isinstance(value, str) or "\n" in value
                              or value.split()[:2] != ["kspace_modify", "gewald"]):
        raise ValueError(f"{owner}: kspace_parameters must be one "
                         f"'kspace_modify gewald ...' command or None, got {value!r}")


def check_atoms(atoms, commands, atom_types):
    """Refuse what LAMMPS cannot be given with ``commands``, before anything is set up.

    No atoms, Coulomb interactions without charges, mixed periodicity, an element
    without a type in ``atom_types`` and a flat or left-handed periodic cell are
    refused in one ``ValueError`` (``LAMMPSCalculator: ...``).  A calculator checks
    the atoms of a new instance (and :class:`~rigidmd.lammps.engine.LAMMPSEngine` those
    of a new engine) with it before it stops the one it has, so that a refused call
    leaves the running instance and the pinned k-space parameters as they were.

    Parameters
    ----------
    atoms : ase.Atoms
    commands : list of str
        The interaction commands.
    atom_types : dict of str to int or None
        As :func:`rigidmd.lammps.atomtypes.lammps_types` takes it.

    Returns
    -------
    tuple
        What :func:`~rigidmd.lammps.atomtypes.lammps_types` returns for the atoms.
    """
    if len(atoms) == 0:
        raise ValueError("LAMMPSCalculator: no atoms (LAMMPS needs at least one)")
    charges = atoms.get_initial_charges()
    if any(word in command for command in commands for word in _COULOMB) \
            and not np.any(charges):
        raise ValueError("LAMMPSCalculator: the commands have Coulomb interactions but the "
                         "atoms have no charges; set them with atoms.set_initial_charges()")
    if atoms.pbc.any() and not atoms.pbc.all():
        raise ValueError(f"LAMMPSCalculator: mixed periodicity {atoms.pbc.tolist()}; "
                         "make the cell periodic in all or no directions")
    types = lammps_types(atoms, atom_types)
    if atoms.pbc.all():
        lower_triangular(atoms.cell.array)  # (refuses a flat or left-handed cell)
    return types


class LAMMPSCalculator(Calculator):
    r"""An ASE calculator on one persistent LAMMPS instance (``units metal``).

    Parameters
    ----------
    commands : sequence of str
        Interaction commands: ``pair_style``, ``pair_coeff``, ``pair_modify``,
        ``kspace_style``, ``kspace_modify``, ... (a multi-line string is split
        into lines).  Types in ``pair_coeff`` are numbers (see ``atom_types``)
        or the element symbols (type labels are defined).
    atom_types : dict of str to int, optional
        LAMMPS type of each element; default: the elements numbered 1, 2, ...
        in order of first appearance in the atoms.
    molecule_ids : array_like of int, shape (n_atoms,), optional
        Molecule of each atom; given, they are the molecules whatever the atoms
        carry (a ``mol-id`` array or tags), except in a rigid dynamics, whose
        bodies they must group alike.
    exclude_intramolecular : bool, default True
        ``neigh_modify exclude molecule/intra all``: no interactions inside a
        molecule, so energy, forces and stress equal native LAMMPS with that
        setting (and those of rigid molecules have no constant offset).
    ase_constants : bool, default False
        Scale the charges so that Coulomb energies use ASE's Coulomb constant
        instead of LAMMPS's ``metal`` one (2.4e-8 apart); see
        :mod:`rigidmd.lammps.library`.  The default reproduces native LAMMPS.
    skin : float, default 2.0
        Neighbour skin (Å, finite and >= 0), LAMMPS's ``neighbor`` default for
        metal units.
    cmdargs : sequence of str, optional
        LAMMPS command-line arguments (default: no log, no screen output).
    threads : int, optional
        OpenMP threads: LAMMPS's OPENMP styles with ``-sf omp -pk omp threads``
        added to the instance's command line (``package omp`` cannot be given
        once the box exists).
    kspace_parameters : str, optional
        A ``kspace_modify gewald ...`` command that fixes the k-space
        parameters (see :attr:`kspace_parameters`); default: those LAMMPS
        chooses for the first cell.

    Notes
    -----
    Properties: ``energy`` (and ``free_energy``), ``forces`` (eV/Å) and
    ``stress`` (eV/Å³, ASE's sign and Voigt order ``xx yy zz yz xz xy``; the
    virial only, from LAMMPS's ``compute pressure NULL virial`` converted
    with LAMMPS's own ``nktv2p``).  LAMMPS errors raise
    :class:`~rigidmd.lammps.LammpsError` with LAMMPS's message; the next call
    starts a fresh instance.  LAMMPS's warnings when an instance is set up
    are issued as :class:`UserWarning` (``LAMMPSCalculator: LAMMPS warns:
    ...``), except the ones every rigid-molecule set-up gets (no integrator
    fix; excluded pairs with k-space, whose reciprocal-space part is a
    constant of a rigid molecule); a net charge with a ``kspace_style`` is
    warned of too.  :meth:`get_checkpoint_state` and
    :meth:`set_checkpoint_state` carry the k-space parameters through
    :func:`rigidmd.core.checkpoint.save_checkpoint` and ``load_checkpoint``.
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress"]
    _instance = None          # the LammpsInstance (rigidmd.lammps.instance), box and all
    _grouping_checked = None  # the bodies and molecules last found to agree
    _copy = None              # this calculator's own copy of the atoms (see copy_atoms)

    def __init__(self, commands, *, atom_types=None, molecule_ids=None,
                 exclude_intramolecular=True, ase_constants=False, skin=2.0, cmdargs=None,
                 threads=None, kspace_parameters=None, **kwargs):
        super().__init__(**kwargs)
        if isinstance(commands, str):
            commands = [commands]
        self.commands = flatten(commands)
        if not any(c.split()[0] == "pair_style" for c in self.commands):
            raise ValueError("LAMMPSCalculator: the commands need a pair_style")
        self.atom_types = check_atom_types(atom_types)
        self.molecule_ids = check_molecule_ids(molecule_ids)
        self.exclude_intramolecular = bool(exclude_intramolecular)
        self.ase_constants = bool(ase_constants)
        self.skin = check_skin(skin, "LAMMPSCalculator")
        self.cmdargs = cmdargs
        self.threads = None if threads is None else _threads(threads)
        if self.threads is not None:
            self.cmdargs = list(DEFAULT_CMDARGS if cmdargs is None else cmdargs) + [
                "-sf", "omp", "-pk", "omp", str(self.threads)]
        self._instance = None
        self._kspace_parameters = None
        self._pinned_for = None  # the system whose first cell chose the parameters
        self.kspace_parameters = kspace_parameters

    @property
    def kspace_parameters(self):
        """The ``kspace_modify`` command that fixes the k-space parameters (str or None).

        LAMMPS chooses the Ewald parameter and PPPM's mesh and order (or
        Ewald's k-vectors) for the first cell; they are then kept for every
        later cell, and for a new LAMMPS instance after an error (see
        :func:`rigidmd.lammps.instance.chosen_kspace`); other atoms (another
        number, kind, charges or molecules) get their own.  None until a periodic system with a
        ``kspace_style`` has been set up, unless given.  Given ones (here or
        to the constructor) are kept for any atoms.  Setting it
        (a ``kspace_modify gewald ... mesh ... order ...`` or ``... kmax/ewald
        ...`` command) makes the next call start LAMMPS with these parameters:
        how a continued run keeps the energy of the run it continues.
        """
        return self._kspace_parameters

    @kspace_parameters.setter
    def kspace_parameters(self, value):
        check_kspace_parameters(value, "LAMMPSCalculator")
        if value != self._kspace_parameters:
            self._close()  # the next call sets up LAMMPS with these parameters
        self._kspace_parameters = value
        self._pinned_for = None  # given: kept for any system

    def get_checkpoint_state(self):
        """What a checkpoint must hold to continue with the same energies (JSON-able dict).

        Returns
        -------
        dict
            ``{"kspace_parameters": str or None}``, see :attr:`kspace_parameters`.
        """
        return {"kspace_parameters": self.kspace_parameters}

    def set_checkpoint_state(self, state):
        """Take back what :meth:`get_checkpoint_state` returned (before the first call).

        Parameters
        ----------
        state : dict
            ``{"kspace_parameters": str or None}``; other keys are refused.
        """
        unknown = sorted(set(state) - {"kspace_parameters"})
        if unknown:
            raise ValueError(f"LAMMPSCalculator: unknown checkpoint state {unknown[0]!r}")
        self.kspace_parameters = state.get("kspace_parameters")

    # ------------------------------------------------------------ set-up
    def _signature_of(self, atoms, molecules):
        return (len(atoms), atoms.numbers.tobytes(), atoms.get_initial_charges().tobytes(),
                tuple(atoms.pbc), None if molecules is None else molecules.tobytes())

    def _start(self, atoms, molecules, signature):
        """A new LAMMPS instance for ``atoms`` (see :mod:`rigidmd.lammps.instance`).

        The atoms are checked (:func:`check_atoms`) before the running instance is
        closed and the pinned k-space parameters are forgotten: a refused call leaves
        the calculator as it was.
        """
        types = check_atoms(atoms, self.commands, self.atom_types)
        self._close()
        if self._pinned_for is not None and self._pinned_for != signature:
            # Other atoms (not a restart after an error): LAMMPS chooses for them anew.
            self._kspace_parameters = self._pinned_for = None
        if molecules is None and self.exclude_intramolecular:
            warnings.warn("LAMMPSCalculator: the atoms carry no molecules (no mol-id "
                          "array, no tags, no molecule_ids): no pair is excluded",
                          stacklevel=4)
        molecules = lammps_molecule_ids(molecules, len(atoms))
        kspace = bool(atoms.pbc.all()) and any(c.split()[0] == "kspace_style"
                                               for c in self.commands)
        instance = LammpsInstance(
            load_lammps(self.cmdargs), atoms, types, molecules, signature,
            commands=self.commands, skin=self.skin,
            exclude_intramolecular=self.exclude_intramolecular,
            ase_constants=self.ase_constants,
            kspace_parameters=self.kspace_parameters if kspace else None)
        self._instance = instance
        net = float(atoms.get_initial_charges().sum())
        if kspace and abs(net) > 1e-6:
            warnings.warn(f"LAMMPSCalculator: the atoms carry a net charge of {net:.6g} e and "
                          "the commands have a kspace_style: k-space adds a uniform neutralising "
                          "background; check the charges if the system should be neutral",
                          stacklevel=4)
        for line in lammps_warnings(instance.setup_log):
            warnings.warn(f"LAMMPSCalculator: LAMMPS warns: {line}", stacklevel=4)
        if kspace and self.kspace_parameters is None:
            # Kept for every later cell and instance (see chosen_kspace): as a native NPT run.
            modify = chosen_kspace(instance.setup_log)
            if modify is None:
                warnings.warn("LAMMPSCalculator: could not read the k-space parameters LAMMPS "
                              "chose; they are chosen anew at every cell change, so the energy "
                              "of a run that changes the cell jumps", stacklevel=4)
            else:
                instance.execute([modify])
                self._kspace_parameters = modify
                self._pinned_for = signature
        return instance

    def _close(self):
        if self._instance is not None:
            self._instance.close()
        self._instance = None

    def __del__(self):
        self._close()

    # ------------------------------------------------------------ a call
    def check_state(self, atoms, tol=1e-15):
        """What changed since the last call: ASE's comparison, in a few array operations.

        The same test as ASE's ``compare_atoms`` (each of ``all_changes`` within
        ``tol`` absolute plus ``tol`` relative, as ``numpy.allclose``), without
        its general-purpose per-array machinery: it runs at every property a
        dynamics asks for (two or three times a step), and ASE's took 0.44 ms
        per call on 5184 atoms where this takes 0.12 ms.  ASE's own is asked
        when the atoms differ in size or arrays, or with ``ignored_changes``.
        """
        return quick_check_state(self, atoms, tol, super().check_state)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        if atoms is not None:  # ASE's Calculator.calculate, without its directory check
            self.atoms = self._copy = copy_atoms(atoms, self._copy)
        atoms = self.atoms
        # NaN or infinite coordinates hang LAMMPS (deaf to Ctrl-C): refused first.
        check_finite(atoms.positions, "position", "Å", "given to LAMMPSCalculator")
        if atoms.pbc.any():
            check_finite(atoms.cell.array, "cell", "Å", "given to LAMMPSCalculator")
        molecules, source, self._grouping_checked = molecules_of(
            atoms, self.molecule_ids, self._grouping_checked)
        signature = self._signature_of(atoms, None if source is None else molecules)
        instance = self._instance
        if instance is None or signature != instance.signature:
            # (what is checked is in the signature: once per instance)
            instance = self._start(atoms, molecules, signature)
        elif atoms.pbc.all() and not np.array_equal(atoms.cell.array, instance.box.cell):
            # (see rigidmd.lammps.box: the box plugin, or change_box and a set-up)
            if instance.box.change(atoms.cell.array, self.commands, self.kspace_parameters):
                instance.setup_needed = True
        lmp, arrays, box, setup_needed = (instance.lmp, instance.arrays, instance.box,
                                          instance.setup_needed)
        rotation = box.rotation
        positions = atoms.positions if rotation is None else atoms.positions @ rotation
        if atoms.pbc.all() and setup_needed:
            # A new cell (a set-up follows anyway): every atom into the box, with image
            # flags to match.  LAMMPS's change_box re-mapped the previous positions into
            # the new box, and their images need not suit these after a large change.
            # LAMMPS's order anew: the set-up run sorted its atoms.
            positions = positions[arrays.order(refresh=True)]
            cell = box.lammps_cell()
            image = np.floor(np.linalg.solve(cell.T, positions.T).T)
            positions -= image @ cell
            arrays.view("image")[:] = arrays.pack_images(image)
            arrays.view("x")[:] = positions
        elif atoms.pbc.all():
            # LAMMPS's own image of each atom: only real motion counts against the skin
            # (atoms more than half a box out are shifted by whole cell vectors first).
            arrays.write_positions(positions, box.lammps_cell())
        else:
            arrays.view("x")[:] = positions[arrays.order(setup_needed)]
        # Energy and virial are tallied only on steps asked for (as native thermo steps).
        want_energy = bool({"energy", "free_energy"} & set(properties))
        want_stress = "stress" in properties and atoms.pbc.all()
        moved = "positions" in system_changes or "cell" in system_changes
        step = lmp.extract_global("ntimestep")
        if setup_needed:
            command = "run 0 pre yes post no"
        else:  # a step without set-up (also for the same positions asked for more)
            command, step = "run 1 pre no post no", step + 1
        if want_stress and not want_energy and not setup_needed and box.load_plugin():
            command = f"rigidmd_tally rmd_pressure {step}\n{command}"  # not the costly energy
        elif want_energy or want_stress:
            lmp.addstep_compute(step)  # every energy and pressure compute
        instance.execute(command.splitlines())
        instance.setup_needed = False
        # (thermo's lost-atom check would come only at the next call)
        if (nlocal := lmp.extract_global("nlocal")) != len(atoms):
            self._close()
            raise LammpsError(f"LAMMPSCalculator: LAMMPS lost {len(atoms) - nlocal} of "
                              f"{len(atoms)} atoms (an atom moved far out of the box)")
        forces = np.empty((len(atoms), 3))  # LAMMPS may have sorted its atoms: IDs anew
        arrays.read_forces(forces)
        if rotation is not None:
            forces = forces @ rotation.T
        results = {"forces": forces}
        if want_energy:
            energy = float(lmp.extract_compute("rmd_pe", 0, 0))
            results.update(energy=energy, free_energy=energy)
        if want_stress:
            # LAMMPS's xx yy zz xy xz yz; σ = -W/V, and LAMMPS's virial pressure is W/V
            # (LAMMPS's pointer read as six floats: its NumPy wrapper costs 3 times more)
            pressure = np.array(lmp.extract_compute("rmd_pressure", 0, 1)[:6])[_ASE_VOIGT]
            if rotation is None:
                results["stress"] = -(pressure / instance.nktv2p)
            else:
                stress = -(rotation @ voigt_6_to_full_3x3_stress(pressure / instance.nktv2p)
                           @ rotation.T)
                results["stress"] = stress[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]
        if moved:
            self.results = results
        else:
            self.results.update(results)

    def write_data(self, atoms, path):
        """Write ``atoms`` as this calculator gives them to LAMMPS to a data file.

        Types, masses, charges, molecule IDs, the box in LAMMPS's frame and its
        reduced basis (see :func:`rigidmd.lammps.box.lammps_box`) and image flags,
        by LAMMPS's ``write_data``
        (``nocoeff``), after one force call (which also fixes
        :attr:`kspace_parameters`).  An engine in another process reads it
        (:class:`rigidmd.lammps.engine.LAMMPSEngine`).
        """
        self.get_forces(atoms)
        self._instance.execute([f"write_data {Path(path)} nocoeff"])
