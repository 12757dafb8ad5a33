r"""One LAMMPS instance of :class:`~rigidmd.lammps.LAMMPSCalculator`, set up for one system.

:class:`LammpsInstance` creates the box and the atoms (types, masses,
charges, molecules, image flags), gives the interaction commands, declares
the computes a call reads (``rmd_pe``, ``rmd_pressure``) and runs one set-up
with a log: LAMMPS's warnings, and the k-space parameters it chose
(:func:`chosen_kspace`).  The calculator writes positions and reads forces
through :attr:`LammpsInstance.arrays`; the box and its changes are
:attr:`LammpsInstance.box` (:mod:`rigidmd.lammps.box`).
"""

import re
import tempfile
from pathlib import Path

import numpy as np

from rigidmd.lammps.atomarrays import AtomArrays
from rigidmd.lammps.box import LammpsBox, lammps_box, region_command
from rigidmd.lammps.library import LAMMPS_METAL_QQR2E, LammpsError, charge_factor

__all__ = ["LammpsInstance", "chosen_kspace"]


def _encode(image):
    """LAMMPS image flags (x, y, z) packed into one integer."""
    ix, iy, iz = (int(v) + 512 for v in image)
    return ix | (iy << 10) | (iz << 20)


def chosen_kspace(text):
    """The ``kspace_modify`` command that fixes the k-space parameters LAMMPS chose.

    LAMMPS chooses the Ewald parameter (and PPPM's mesh and order, or
    Ewald's k-vectors) for the requested accuracy at each full set-up.  Its
    own barostats set up once and keep them while the box changes; here a
    new cell may run a full set-up (see :meth:`rigidmd.lammps.box.LammpsBox.change`),
    which would choose them anew.  With intramolecular pairs excluded by
    ``neigh_modify exclude``, the reciprocal-space energy of those pairs
    depends on the Ewald parameter, so each new choice would shift the
    energy by up to tenths of an eV for 216 waters (no force on a rigid
    body changes, but the conserved energy of an NPT run jumps).  The
    choices are read from the log ``text`` of the first set-up and fixed
    with ``kspace_modify``
    (:attr:`rigidmd.lammps.LAMMPSCalculator.kspace_parameters`), as a native
    NPT run has them.

    Returns
    -------
    str or None
        ``kspace_modify gewald ... mesh ... order ...`` (PPPM) or ``... kmax/ewald
        ...`` (Ewald); None when the log does not say.
    """
    number = r"([-+0-9.eE]+)"
    g = re.search(r"G vector \(1/distance\)\s*=\s*" + number, text)
    mesh = re.search(r"grid\s*=\s*(\d+)\s+(\d+)\s+(\d+)", text)
    order = re.search(r"stencil order\s*=\s*(\d+)", text)
    kmax = re.search(r"kxmax kymax kzmax\s*=\s*(\d+)\s+(\d+)\s+(\d+)", text)
    if g is None or (mesh is None or order is None) and kmax is None:
        return None
    modify = f"kspace_modify gewald {g.group(1)}"
    if mesh is not None and order is not None:
        modify += f" mesh {' '.join(mesh.groups())} order {order.group(1)}"
    else:
        modify += f" kmax/ewald {' '.join(kmax.groups())}"
    return modify


class LammpsInstance:
    """A LAMMPS instance (``units metal``, ``atom_style full``) set up for ``atoms``.

    Parameters
    ----------
    lmp : lammps.lammps
        A new instance; closed here if the set-up fails.
    atoms : ase.Atoms
        Periodic in all directions or in none.
    types : tuple
        ``(types, type_mass, labels)`` of :func:`rigidmd.lammps.atomtypes.lammps_types`.
    molecules : numpy.ndarray of int, shape (n_atoms,)
        Molecule IDs (all > 0), see :func:`rigidmd.lammps.atomtypes.lammps_molecule_ids`.
    signature : tuple
        What the instance was made for (a call with other atoms needs a new one).
    commands : list of str
        Interaction commands.
    skin : float
        Neighbour skin (Å).
    exclude_intramolecular, ase_constants : bool
        As for :class:`~rigidmd.lammps.LAMMPSCalculator`.
    kspace_parameters : str or None
        A ``kspace_modify gewald ...`` command given after ``commands``.

    Attributes
    ----------
    lmp : lammps.lammps or None
        None once closed.
    arrays : AtomArrays or None
    box : rigidmd.lammps.box.LammpsBox
    signature : tuple or None
        None once closed.
    nktv2p : float
        LAMMPS's pressure unit conversion.
    setup_needed : bool
        Whether the next step must run a set-up (``run 0 pre yes``).
    setup_log : str
        LAMMPS's log of the first set-up.

    Raises
    ------
    LammpsError
        A command failed (``setup`` attribute True), or LAMMPS made fewer atoms.
    """

    def __init__(self, lmp, atoms, types, molecules, signature, *, commands, skin,
                 exclude_intramolecular, ase_constants, kspace_parameters):
        self.lmp, self.arrays, self.signature = lmp, None, None
        types, type_mass, labels = types
        n = len(atoms)
        periodic = bool(atoms.pbc.all())
        tmp = tempfile.TemporaryDirectory(prefix="rigidmd-lammps-")
        log = Path(tmp.name) / "setup.log"
        try:
            cmds = [f"log {log}", "units metal", "atom_style full", "atom_modify map array",
                    f"boundary {'p p p' if periodic else 's s s'}"]
            self.execute(cmds)
            if periodic:
                rotation, cell, flips = lammps_box(atoms.cell.array)
                triclinic = bool(cell[1, 0] or cell[2, 0] or cell[2, 1])
                region = region_command(cell)
            else:
                rotation, cell, flips = None, None, (0, 0, 0)
                lo, hi = atoms.positions.min(axis=0) - 1.0, atoms.positions.max(axis=0) + 1.0
                triclinic = False
                bounds = " ".join(f"{a:.17g} {b:.17g}" for a, b in zip(lo, hi, strict=True))
                region = f"region rmd_box block {bounds} units box"
            ntypes = max(type_mass)
            self.execute([region, f"create_box {ntypes} rmd_box"])
            self.execute([f"mass {t} {m:.17g}" for t, m in type_mass.items()])
            self.execute([f"labelmap atom {t} {s}" for t, s in labels.items()])
            positions = atoms.positions if rotation is None else atoms.positions @ rotation
            if periodic:
                frac = np.linalg.solve(cell.T, positions.T).T
                image = np.floor(frac).astype(np.int64)
                positions = positions - image @ cell
            else:
                image = np.zeros((n, 3), dtype=np.int64)
            created = lmp.create_atoms(n, list(range(1, n + 1)), types.tolist(),
                                       positions.ravel().tolist(),
                                       image=[_encode(i) for i in image.tolist()])
            if created != n:
                raise LammpsError(f"LAMMPSCalculator: LAMMPS created {created} of {n} atoms")
            self.arrays = AtomArrays(lmp, lmp.extract_global("nlocal"))
            ids = self.arrays.order()
            charge = atoms.get_initial_charges() * charge_factor(ase_constants)
            lmp.numpy.extract_atom("q")[:n] = charge[ids]
            lmp.numpy.extract_atom("molecule")[:n] = molecules[ids]
            setup = [f"neighbor {skin:.17g} bin", "neigh_modify every 1 delay 0 check yes"]
            if exclude_intramolecular:
                setup.append("neigh_modify exclude molecule/intra all")
            self.execute(setup)
            self.execute(commands)
            # LAMMPS tallies energy and virial on every thermo step, with `thermo 0` the last
            # of every run (a lone `run 1`: 4.6-5.5 ms against 3.5-4.1 in a long run, 216
            # waters); a variable's thermo step never comes: only calls that ask tally them.
            self.execute(["compute rmd_pressure all pressure NULL virial",
                          "thermo_style custom step", "thermo_modify norm no lost error",
                          "variable rmd_thermo equal 1e18", "thermo v_rmd_thermo",
                          "compute rmd_pe all pe", "uncompute thermo_pe"])
            if ase_constants and lmp.extract_global("qqr2e") != LAMMPS_METAL_QQR2E:
                raise LammpsError("LAMMPSCalculator: unexpected LAMMPS Coulomb constant")
            if kspace_parameters is not None:
                self.execute([kspace_parameters])
            self.box = LammpsBox(lmp, self.execute, atoms.cell.array, rotation, triclinic, flips)
            # One set-up with a log: LAMMPS's warnings, and the k-space parameters it chose.
            self.execute(["run 0 pre yes post no", "log none"])
            self.setup_log = log.read_text()
        except BaseException as err:
            if isinstance(err, LammpsError):
                err.setup = True
            self.close()
            raise
        finally:
            tmp.cleanup()
        self.signature = signature
        self.nktv2p = lmp.extract_global("nktv2p")
        self.setup_needed = True

    def execute(self, commands):
        """Run LAMMPS ``commands`` one by one; a failure closes the instance.

        Raises
        ------
        LammpsError
            With the command and LAMMPS's message.
        """
        for command in commands:
            try:
                self.lmp.command(command)
            except Exception as err:  # LAMMPS raises a bare Exception with its message
                self.close()
                raise LammpsError(f"LAMMPS command {command!r} failed: {err}") from None

    def close(self):
        """Close LAMMPS (idempotent); the instance is then of no use."""
        if self.lmp is not None:
            try:
                self.lmp.close()
            except Exception:  # noqa: BLE001 - closing a broken instance must not mask an error
                pass
        self.lmp = self.arrays = None  # (the views point into the instance's memory)
        self.signature = None
