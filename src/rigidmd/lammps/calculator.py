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
(positions, forces and stress rotated back), and an orthogonal box that gets
tilted becomes triclinic once.  A change in the number or kind of atoms,
their charges or their molecules builds a new instance.

Molecules (for ``neigh_modify exclude molecule/intra all``) are the bodies of
the rigid dynamics the atoms are in (a ``mol-id`` array, tags or
``molecule_ids`` that group the atoms otherwise are refused); outside a
dynamics they come from the ``mol-id`` array (ASE's ``lammps-data`` reader
sets it), else from non-zero tags, else from ``molecule_ids``.

Masses never enter a force call: atoms of one element share a type whatever
their masses (H and D).  LAMMPS's warnings at set-up are passed on as Python
warnings; positions and cells that are not finite are refused before LAMMPS
sees them (LAMMPS would hang on them).
"""

import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
from ase.calculators.calculator import Calculator, all_changes

from rigidmd.core.checks import check_finite, quick_check_state
from rigidmd.lammps.atomarrays import AtomArrays
from rigidmd.lammps.boxplugin import BoxPluginUnavailable, box_plugin, warn_fallback
from rigidmd.lammps.data import MASSLESS_SITE_MASS
from rigidmd.lammps.library import (
    DEFAULT_CMDARGS,
    LAMMPS_METAL_QQR2E,
    LammpsError,
    charge_factor,
    check_atom_types,
    flatten,
    lammps_warnings,
    load_lammps,
)

__all__ = ["LAMMPSCalculator", "lower_triangular"]

_COULOMB = ("coul", "kspace_style", "tip4p")


def lower_triangular(cell):
    """Rotation ``Q`` with ``cell @ Q`` lower triangular with a positive diagonal.

    Returns
    -------
    Q : numpy.ndarray, shape (3, 3) or None
        None when the cell is lower triangular already.
    lammps_cell : numpy.ndarray, shape (3, 3)
    """
    if abs(cell[0, 1]) + abs(cell[0, 2]) + abs(cell[1, 2]) == 0 and np.all(np.diag(cell) > 0):
        return None, cell
    if np.linalg.det(cell) <= 0:
        raise ValueError("LAMMPSCalculator: the cell is left-handed (negative determinant); "
                         "LAMMPS needs a right-handed cell")
    Q, R = np.linalg.qr(cell.T)
    signs = np.sign(np.diag(R))
    Q, R = Q * signs, (R.T * signs).T
    lammps_cell = R.T
    lammps_cell[np.abs(lammps_cell) < 1e-14 * np.abs(lammps_cell).max()] = 0.0
    return Q, lammps_cell


def _threads(threads):
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"LAMMPSCalculator: threads must be a positive whole number, got "
                         f"{threads!r}")
    return int(threads)


def _distinct(ids):
    """Molecule IDs with every atom in no molecule (ID <= 0) in a group of its own."""
    return np.where(ids > 0, ids, -np.arange(len(ids)))


def _check_same_grouping(bodies, given, source):
    """Refuse molecules (``source``) that merge or split the rigid bodies, naming two atoms.

    ``bodies``: body index + 1 of each atom (0: a free atom); ``given``: the
    molecule IDs read from ``source`` (<= 0: no molecule).
    """
    b, m = _distinct(bodies), _distinct(given)
    pairs = np.unique(np.stack([b, m], axis=1), axis=0)
    if len(pairs) == len(np.unique(b)) == len(np.unique(m)):
        return
    for key, other, verb in ((m, b, "put atoms {i} and {j} in one molecule but they are in "
                              "different rigid bodies"),
                             (b, m, "split a rigid body: atoms {i} and {j} are in one body but "
                              "in different molecules")):
        order = np.lexsort((other, key))
        k, o = key[order], other[order]
        clash = np.flatnonzero((k[1:] == k[:-1]) & (o[1:] != o[:-1]))
        if clash.size:
            i, j = sorted((int(order[clash[0]]), int(order[clash[0] + 1])))
            remedy = {"tags": "atoms.set_tags(0)", "mol-id array": "del atoms.arrays['mol-id']",
                      "molecule_ids": "molecule_ids=None"}[source]
            raise ValueError(
                f"LAMMPSCalculator: the atoms' {source} {verb.format(i=i, j=j)}; in a rigid "
                f"dynamics the bodies are the molecules: remove them ({remedy}) "
                "or make them group the atoms as the bodies do")


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
        Molecule of each atom, when the atoms have neither a ``mol-id`` array
        nor tags.
    exclude_intramolecular : bool, default True
        ``neigh_modify exclude molecule/intra all``: no interactions inside a
        molecule, so energy, forces and stress equal native LAMMPS with that
        setting (and those of rigid molecules have no constant offset).
    ase_constants : bool, default False
        Scale the charges so that Coulomb energies use ASE's Coulomb constant
        instead of LAMMPS's ``metal`` one (2.4e-8 apart); see
        :mod:`rigidmd.lammps.library`.  The default reproduces native LAMMPS.
    skin : float, default 2.0
        Neighbour skin (Å), LAMMPS's ``neighbor`` default for metal units.
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
    :func:`rigidmd.run.checkpoint.save_checkpoint` and ``load_checkpoint``.
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress"]
    _lmp = None
    _grouping_checked = None  # the bodies and molecules last found to agree
    _plugin = None            # True (loaded), or why the box plugin is not there
    _box_fix = False          # fix rigidmd/box declared (at the first new cell)
    _box_moved = False        # the box changed through the plugin since the last step
    _arrays = None            # AtomArrays of the instance

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
        self.molecule_ids = None if molecule_ids is None else np.asarray(molecule_ids)
        self.exclude_intramolecular = bool(exclude_intramolecular)
        self.ase_constants = bool(ase_constants)
        self.skin = float(skin)
        self.cmdargs = cmdargs
        self.threads = None if threads is None else _threads(threads)
        if self.threads is not None:
            self.cmdargs = list(DEFAULT_CMDARGS if cmdargs is None else cmdargs) + [
                "-sf", "omp", "-pk", "omp", str(self.threads)]
        self._lmp = None
        self._kspace_parameters = None
        self._pinned_for = None  # the system whose first cell chose the parameters
        self.kspace_parameters = kspace_parameters
        self._signature = None  # what a new instance is needed for
        self._cell = None       # the cell LAMMPS has
        self._rotation = None

    @property
    def kspace_parameters(self):
        """The ``kspace_modify`` command that fixes the k-space parameters (str or None).

        LAMMPS chooses the Ewald parameter and PPPM's mesh and order (or
        Ewald's k-vectors) for the first cell; they are then kept for every
        later cell, and for a new LAMMPS instance after an error (see
        :meth:`_pin_kspace`); other atoms (another number, kind, charges or
        molecules) get their own.  None until a periodic system with a
        ``kspace_style`` has been set up, unless given.  Given ones (here or
        to the constructor) are kept for any atoms.  Setting it
        (a ``kspace_modify gewald ... mesh ... order ...`` or ``... kmax/ewald
        ...`` command) makes the next call start LAMMPS with these parameters:
        how a continued run keeps the energy of the run it continues.
        """
        return self._kspace_parameters

    @kspace_parameters.setter
    def kspace_parameters(self, value):
        if value is not None and (not isinstance(value, str) or "\n" in value
                                  or value.split()[:2] != ["kspace_modify", "gewald"]):
            raise ValueError("LAMMPSCalculator: kspace_parameters must be one "
                             f"'kspace_modify gewald ...' command or None, got {value!r}")
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
    def _types(self, atoms):
        symbols = atoms.get_chemical_symbols()
        if self.atom_types is None:
            table = {s: i + 1 for i, s in enumerate(dict.fromkeys(symbols))}
        else:
            table = self.atom_types
            missing = sorted(set(symbols) - set(table))
            if missing:
                raise ValueError(f"LAMMPSCalculator: element {missing[0]} has no LAMMPS type in "
                                 f"atom_types {table}")
        types = np.array([table[s] for s in symbols], dtype=np.int64)
        # Masses never enter a force call (LAMMPS's per-type mass is only stored): atoms
        # of one type may differ in mass (H and D, 16O and 18O).  LAMMPS refuses a mass of
        # 0 (a virtual site), so a type gets the largest mass of its atoms, or a tiny one.
        masses = atoms.get_masses()
        largest = np.zeros(max(table.values()) + 1)
        np.maximum.at(largest, types, masses)
        type_mass = {t: float(largest[t]) if largest[t] > 0 else MASSLESS_SITE_MASS
                     for t in range(1, len(largest))}
        labels = {t: s for s, t in table.items()}
        return types, type_mass, labels

    def _molecules(self, atoms):
        """Molecule ID of each atom (1-based; <= 0: in no molecule) and where they came from.

        The bodies of a rigid dynamics the atoms are in come first: they are the
        molecules.  A ``mol-id`` array, non-zero tags or ``molecule_ids`` that group
        the atoms otherwise are refused (they would exclude pairs between bodies, or
        count pairs inside one).  Without a rigid dynamics: ``mol-id``, else non-zero
        tags, else ``molecule_ids``.
        """
        n = len(atoms)
        given, source = None, None
        if "mol-id" in atoms.arrays:
            given, source = np.asarray(atoms.arrays["mol-id"], dtype=np.int64), "mol-id array"
        elif np.any(atoms.get_tags() != 0):
            given, source = np.asarray(atoms.get_tags(), dtype=np.int64), "tags"
        elif self.molecule_ids is not None:
            if self.molecule_ids.shape != (n,):
                raise ValueError(f"LAMMPSCalculator: molecule_ids has shape "
                                 f"{self.molecule_ids.shape}, the atoms are {n}")
            given, source = self.molecule_ids.astype(np.int64), "molecule_ids"
        bodies = next((np.asarray(c.body_ids, dtype=np.int64) for c in atoms.constraints
                       if getattr(c, "body_ids", None) is not None), None)
        if bodies is None:
            return given, source
        if bodies.shape != (n,):
            raise ValueError(f"LAMMPSCalculator: the rigid bodies cover {bodies.size} atoms, "
                             f"the atoms are {n}")
        if given is not None:
            key = (bodies.tobytes(), given.tobytes())  # checked once, not at every step
            if key != self._grouping_checked:
                _check_same_grouping(bodies, given, source)
                self._grouping_checked = key
        return bodies, "bodies"

    def _signature_of(self, atoms, molecules):
        return (len(atoms), atoms.numbers.tobytes(), atoms.get_initial_charges().tobytes(),
                tuple(atoms.pbc), None if molecules is None else molecules.tobytes())

    def _check(self, atoms):
        if len(atoms) == 0:
            raise ValueError("LAMMPSCalculator: no atoms (LAMMPS needs at least one)")
        charges = atoms.get_initial_charges()
        if any(word in command for command in self.commands for word in _COULOMB) \
                and not np.any(charges):
            raise ValueError("LAMMPSCalculator: the commands have Coulomb interactions but the "
                             "atoms have no charges; set them with atoms.set_initial_charges()")
        if atoms.pbc.any() and not atoms.pbc.all():
            raise ValueError(f"LAMMPSCalculator: mixed periodicity {atoms.pbc.tolist()}; "
                             "make the cell periodic in all or no directions")

    def _start(self, atoms, molecules, source):
        self._close()
        signature = self._signature_of(atoms, None if source is None else molecules)
        if self._pinned_for is not None and self._pinned_for != signature:
            # Other atoms (not a restart after an error): LAMMPS chooses for them anew.
            self._kspace_parameters = self._pinned_for = None
        types, type_mass, labels = self._types(atoms)
        n = len(atoms)
        if molecules is None:
            molecules = np.arange(1, n + 1)  # every atom its own molecule: nothing excluded
            if self.exclude_intramolecular:
                warnings.warn("LAMMPSCalculator: the atoms carry no molecules (no mol-id "
                              "array, no tags, no molecule_ids): no pair is excluded",
                              stacklevel=4)
        else:
            # LAMMPS excludes pairs of equal molecule IDs: atoms in no molecule (ID <= 0)
            # get IDs of their own.
            molecules = molecules.copy()
            alone = molecules <= 0
            molecules[alone] = molecules.max(initial=0) + 1 + np.arange(int(alone.sum()))
        lmp = load_lammps(self.cmdargs)
        self._lmp = lmp
        periodic = bool(atoms.pbc.all())
        kspace = periodic and any(c.split()[0] == "kspace_style" for c in self.commands)
        tmp = tempfile.TemporaryDirectory(prefix="rigidmd-lammps-")
        log = Path(tmp.name) / "setup.log"
        try:
            cmds = [f"log {log}", "units metal", "atom_style full", "atom_modify map array",
                    f"boundary {'p p p' if periodic else 's s s'}"]
            self._execute(cmds)
            if periodic:
                self._rotation, cell = lower_triangular(atoms.cell.array)
                self._triclinic = bool(cell[1, 0] or cell[2, 0] or cell[2, 1])
                region = self._region(cell)
            else:
                self._rotation, cell = None, None
                lo, hi = atoms.positions.min(axis=0) - 1.0, atoms.positions.max(axis=0) + 1.0
                self._triclinic = False
                bounds = " ".join(f"{a:.17g} {b:.17g}" for a, b in zip(lo, hi, strict=True))
                region = f"region rmd_box block {bounds} units box"
            ntypes = max(type_mass)
            self._execute([region, f"create_box {ntypes} rmd_box"])
            self._execute([f"mass {t} {m:.17g}" for t, m in type_mass.items()])
            self._execute([f"labelmap atom {t} {s}" for t, s in labels.items()])
            positions = self._to_lammps(atoms.positions)
            if periodic:
                frac = np.linalg.solve(cell.T, positions.T).T
                image = np.floor(frac).astype(np.int64)
                positions = positions - image @ cell
            else:
                image = np.zeros((n, 3), dtype=np.int64)
            created = lmp.create_atoms(n, list(range(1, n + 1)), types.tolist(),
                                       positions.ravel().tolist(),
                                       image=[self._encode(i) for i in image.tolist()])
            if created != n:
                raise LammpsError(f"LAMMPSCalculator: LAMMPS created {created} of {n} atoms")
            self._arrays = AtomArrays(lmp, lmp.extract_global("nlocal"))
            ids = self._arrays.order()
            charge = atoms.get_initial_charges() * charge_factor(self.ase_constants)
            lmp.numpy.extract_atom("q")[:n] = charge[ids]
            lmp.numpy.extract_atom("molecule")[:n] = molecules[ids]
            setup = [f"neighbor {self.skin:.17g} bin", "neigh_modify every 1 delay 0 check yes"]
            if self.exclude_intramolecular:
                setup.append("neigh_modify exclude molecule/intra all")
            self._execute(setup)
            self._execute(self.commands)
            # LAMMPS tallies energy and virial on every thermo step, with `thermo 0` the last
            # of every run (a lone `run 1`: 4.6-5.5 ms against 3.5-4.1 in a long run, 216
            # waters); a variable's thermo step never comes: only calls that ask tally them.
            self._execute(["compute rmd_pressure all pressure NULL virial",
                           "thermo_style custom step", "thermo_modify norm no lost error",
                           "variable rmd_thermo equal 1e18", "thermo v_rmd_thermo",
                           "compute rmd_pe all pe", "uncompute thermo_pe"])
            if self.ase_constants and lmp.extract_global("qqr2e") != LAMMPS_METAL_QQR2E:
                raise LammpsError("LAMMPSCalculator: unexpected LAMMPS Coulomb constant")
            if kspace and self.kspace_parameters is not None:
                self._execute([self.kspace_parameters])
            self._plugin, self._box_fix = None, False  # loaded when first needed
            # One set-up with a log: LAMMPS's warnings, and the k-space parameters it chose.
            self._execute(["run 0 pre yes post no", "log none"])
            text = log.read_text()
        except BaseException as err:
            if isinstance(err, LammpsError):
                err.setup = True
            self._close()
            raise
        finally:
            tmp.cleanup()
        self._signature = signature
        self._cell = atoms.cell.array.copy()
        self._nktv2p = lmp.extract_global("nktv2p")
        self._setup_needed = True
        net = float(atoms.get_initial_charges().sum())
        if kspace and abs(net) > 1e-6:
            warnings.warn(f"LAMMPSCalculator: the atoms carry a net charge of {net:.6g} e and "
                          "the commands have a kspace_style: k-space adds a uniform neutralising "
                          "background; check the charges if the system should be neutral",
                          stacklevel=4)
        for line in lammps_warnings(text):
            warnings.warn(f"LAMMPSCalculator: LAMMPS warns: {line}", stacklevel=4)
        if kspace and self.kspace_parameters is None:
            self._pin_kspace(text)

    def _pin_kspace(self, text):
        """Keep the k-space parameters LAMMPS chose for the first cell for every later cell.

        LAMMPS chooses the Ewald parameter (and PPPM's mesh and order, or
        Ewald's k-vectors) for the requested accuracy at each full set-up.  Its
        own barostats set up once and keep them while the box changes; here a
        new cell runs a full set-up (see :meth:`_change_box`), which would
        choose them anew.  With intramolecular pairs excluded by
        ``neigh_modify exclude``, the reciprocal-space energy of those pairs
        depends on the Ewald parameter, so each new choice would shift the
        energy by up to tenths of an eV for 216 waters (no force on a rigid
        body changes, but the conserved energy of an NPT run jumps).  The
        choices are read from the log ``text`` of the first set-up and fixed
        with ``kspace_modify`` (:attr:`kspace_parameters`), as a native NPT run
        has them.
        """
        number = r"([-+0-9.eE]+)"
        g = re.search(r"G vector \(1/distance\)\s*=\s*" + number, text)
        mesh = re.search(r"grid\s*=\s*(\d+)\s+(\d+)\s+(\d+)", text)
        order = re.search(r"stencil order\s*=\s*(\d+)", text)
        kmax = re.search(r"kxmax kymax kzmax\s*=\s*(\d+)\s+(\d+)\s+(\d+)", text)
        if g is None or (mesh is None or order is None) and kmax is None:
            warnings.warn("LAMMPSCalculator: could not read the k-space parameters LAMMPS "
                          "chose; they are chosen anew at every cell change, so the energy "
                          "of a run that changes the cell jumps", stacklevel=5)
            return
        modify = f"kspace_modify gewald {g.group(1)}"
        if mesh is not None and order is not None:
            modify += f" mesh {' '.join(mesh.groups())} order {order.group(1)}"
        else:
            modify += f" kmax/ewald {' '.join(kmax.groups())}"
        self._execute([modify])
        self._kspace_parameters = modify
        self._pinned_for = self._signature

    def _region(self, cell):
        lengths = " ".join(f"0 {cell[k, k]:.17g}" for k in range(3))
        if cell[1, 0] or cell[2, 0] or cell[2, 1]:
            tilts = f"{cell[1, 0]:.17g} {cell[2, 0]:.17g} {cell[2, 1]:.17g}"
            return f"region rmd_box prism {lengths} {tilts} units box"
        return f"region rmd_box block {lengths} units box"

    def _encode(self, image):
        """LAMMPS image flags (x, y, z) packed into one integer."""
        ix, iy, iz = (int(v) + 512 for v in image)
        return ix | (iy << 10) | (iz << 20)

    def _to_lammps(self, vectors):
        return vectors if self._rotation is None else vectors @ self._rotation

    def _execute(self, commands):
        for command in commands:
            try:
                self._lmp.command(command)
            except Exception as err:  # LAMMPS raises a bare Exception with its message
                self._close()
                raise LammpsError(f"LAMMPS command {command!r} failed: {err}") from None

    def _close(self):
        if self._lmp is not None:
            try:
                self._lmp.close()
            except Exception:  # noqa: BLE001 - closing a broken instance must not mask an error
                pass
        self._lmp = self._arrays = None  # (the views point into the instance's memory)
        self._signature = None

    def __del__(self):
        self._close()

    # ------------------------------------------------------------ a call
    def _change_box(self, cell):
        """Give LAMMPS a new cell, in the same instance with the same k-space parameters.

        With the box plugin (see :mod:`rigidmd.lammps.boxplugin`): one
        ``rigidmd_box`` command (the new box and ``KSpace::setup()``; positions
        are written at the call, in LAMMPS's own images, and the step decides
        whether to re-neighbour).  At the first new cell of an instance (the
        plugin's ``fix rigidmd/box`` is taken in by a set-up), without the
        plugin, or when an orthogonal box gets tilted: ``change_box`` and a
        set-up run at the call.

        The cell is rotated into LAMMPS's lower-triangular frame anew (a
        barostat that shears a general cell turns that frame a little at every
        step): positions are written in the new frame at the next call, and
        forces and stress rotated back, so a turned frame costs nothing more
        than a changed box.  An orthogonal box that gets tilted becomes
        triclinic once; LAMMPS then needs its ``kspace_style`` again, given with the
        same commands and the pinned :attr:`kspace_parameters`.  LAMMPS takes any tilt
        (a large one only runs less efficiently): the cell is never flipped or re-mapped.
        """
        rotation, lammps_cell = lower_triangular(cell)
        tilted = bool(lammps_cell[1, 0] or lammps_cell[2, 0] or lammps_cell[2, 1])
        if self._box_fix and (self._triclinic or not tilted):
            # LAMMPS's barostat path (see rigidmd.lammps.boxplugin): the new box and
            # KSpace::setup() now; the next step re-neighbours if the box moved enough.
            edges = [lammps_cell[0, 0], lammps_cell[1, 1], lammps_cell[2, 2],
                     lammps_cell[1, 0], lammps_cell[2, 0], lammps_cell[2, 1]]
            self._execute(["rigidmd_box " + " ".join(f"{v:.17g}" for v in edges)])
            self._rotation = rotation
            self._cell = cell.copy()
            self._box_moved = True
            return
        commands = []
        if not self._box_fix and self._load_plugin():
            # The first new cell: the set-up below takes in fix rigidmd/box (as it
            # would a barostat fix); later cells then need no set-up.
            commands.append("fix rmd_box all rigidmd/box")
            self._box_fix = True
        if not self._box_fix:
            warn_fallback(self._plugin)
        if tilted and not self._triclinic:
            commands.append("change_box all triclinic")
            commands += [c for c in self.commands
                         if c.split()[0] in ("kspace_style", "kspace_modify")]
            if self.kspace_parameters is not None:
                commands.append(self.kspace_parameters)
            self._triclinic = True
        box = "change_box all " + " ".join(
            f"{axis} final 0 {lammps_cell[k, k]:.17g}" for k, axis in enumerate("xyz"))
        if self._triclinic:
            box += (f" xy final {lammps_cell[1, 0]:.17g} xz final {lammps_cell[2, 0]:.17g} "
                    f"yz final {lammps_cell[2, 1]:.17g}")
        self._execute(commands + [box + " units box"])
        self._rotation = rotation
        self._cell = cell.copy()
        self._setup_needed = True

    def _load_plugin(self):
        """Whether the box plugin is loaded in this instance (tried once per instance)."""
        if self._plugin is None:
            try:
                box_plugin(self._lmp)
                self._plugin = True
            except BoxPluginUnavailable as err:
                self._plugin = str(err)
        return self._plugin is True

    def _lammps_cell(self):
        boxlo, boxhi, xy, yz, xz, _, _ = self._lmp.extract_box()
        lengths = np.array(boxhi) - np.array(boxlo)
        return np.array([[lengths[0], 0, 0], [xy, lengths[1], 0], [xz, yz, lengths[2]]])

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
            self.atoms = atoms.copy()
        atoms = self.atoms
        # NaN or infinite coordinates hang LAMMPS (deaf to Ctrl-C): refused first.
        check_finite(atoms.positions, "position", "Å", "given to LAMMPSCalculator")
        if atoms.pbc.any():
            check_finite(atoms.cell.array, "cell", "Å", "given to LAMMPSCalculator")
        self._check(atoms)
        molecules, source = self._molecules(atoms)
        signature = self._signature_of(atoms, None if source is None else molecules)
        if self._lmp is None or signature != self._signature:
            self._start(atoms, molecules, source)
        elif atoms.pbc.all() and not np.array_equal(atoms.cell.array, self._cell):
            self._change_box(atoms.cell.array)
        lmp, arrays = self._lmp, self._arrays
        # LAMMPS's order as the last step left it (anew after a set-up run, which sorts)
        positions = self._to_lammps(atoms.positions)[arrays.order(self._setup_needed)]
        if atoms.pbc.all() and self._setup_needed:
            # A new cell (a set-up follows anyway): every atom into the box, with image
            # flags to match.  LAMMPS's change_box re-mapped the previous positions into
            # the new box, and their images need not suit these after a large change.
            cell = self._lammps_cell()
            image = np.floor(np.linalg.solve(cell.T, positions.T).T)
            positions -= image @ cell
            arrays.view("image")[:] = arrays.pack_images(image)
        elif atoms.pbc.all():
            # LAMMPS's own image of each atom: only real motion counts against the skin.
            cell, image = self._lammps_cell(), arrays.images()
            positions -= image @ cell
            # An atom more than a box out (a new box without a set-up, or atoms given in
            # another image: a restart from unwrapped positions) would be lost: LAMMPS
            # wraps by one box.  Such atoms are shifted by whole cell vectors first.
            frac = positions @ np.linalg.inv(cell)  # 40 us on 5184 atoms (solve: 400 us)
            if np.any(frac < -0.5) or np.any(frac >= 1.5):
                shift = np.floor(frac)
                positions -= shift @ cell
                arrays.view("image")[:] = arrays.pack_images(image + shift)
        arrays.view("x")[:] = positions
        # Energy and virial are tallied only on steps asked for (as native thermo steps).
        want_energy = bool({"energy", "free_energy"} & set(properties))
        want_stress = "stress" in properties and atoms.pbc.all()
        moved = "positions" in system_changes or "cell" in system_changes
        step = lmp.extract_global("ntimestep")
        if self._setup_needed:
            command = "run 0 pre yes post no"
        else:  # a step without set-up (also for the same positions asked for more)
            command, step = "run 1 pre no post no", step + 1
        if want_stress and not want_energy and not self._setup_needed and self._load_plugin():
            command = f"rigidmd_tally rmd_pressure {step}\n{command}"  # not the costly energy
        elif want_energy or want_stress:
            lmp.addstep_compute(step)  # every energy and pressure compute
        self._execute(command.splitlines())
        self._setup_needed = self._box_moved = False
        # (thermo's lost-atom check would come only at the next call)
        if (nlocal := lmp.extract_global("nlocal")) != len(atoms):
            self._close()
            raise LammpsError(f"LAMMPSCalculator: LAMMPS lost {len(atoms) - nlocal} of "
                              f"{len(atoms)} atoms (an atom moved far out of the box)")
        forces = np.empty((len(atoms), 3))  # LAMMPS may have sorted its atoms: IDs anew
        forces[arrays.order(refresh=True)] = arrays.view("f")
        if self._rotation is not None:
            forces = forces @ self._rotation.T
        results = {"forces": forces}
        if want_energy:
            energy = float(lmp.numpy.extract_compute("rmd_pe", 0, 0))
            results.update(energy=energy, free_energy=energy)
        if want_stress:
            xx, yy, zz, xy, xz, yz = np.asarray(lmp.numpy.extract_compute(
                "rmd_pressure", 0, 1), dtype=float)[:6]
            pressure = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) / self._nktv2p
            if self._rotation is not None:
                pressure = self._rotation @ pressure @ self._rotation.T
            stress = -pressure  # σ = -W/V, and LAMMPS's virial pressure is W/V
            results["stress"] = stress[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]
        if moved:
            self.results = results
        else:
            self.results.update(results)

    def write_data(self, atoms, path):
        """Write ``atoms`` as this calculator gives them to LAMMPS to a data file.

        Types, masses, charges, molecule IDs, the box in LAMMPS's frame (see
        :func:`lower_triangular`) and image flags, by LAMMPS's ``write_data``
        (``nocoeff``), after one force call (which also fixes
        :attr:`kspace_parameters`).  An engine in another process reads it
        (:class:`rigidmd.lammps.engine.LAMMPSEngine`).
        """
        self.get_forces(atoms)
        self._execute([f"write_data {Path(path)} nocoeff"])
