r"""rigidmd's water in OpenMM: a second implementation to check a water study against.

OpenMM ships four of :mod:`rigidmd.water`'s models as force-field files
(``tip3p.xml``, ``spce.xml``, ``tip4pew.xml`` and ``opc.xml``, the last
Amber's OPC).  :func:`water_system` builds OpenMM's system for whole water
molecules of one of them (PME, the model's cut-off, its long-range
Lennard-Jones correction, rigid water, M as OpenMM's virtual site), from
the file's parameters or from rigidmd's, so that energies, forces and whole
runs can be compared with rigidmd's LAMMPS set-up.

Two conventions differ from LAMMPS's and are worth knowing when comparing:

- OpenMM reports the force on a virtual site *and* the same force spread
  onto its parent atoms: sum a body's forces without the site's entry
  (:func:`real_atom_forces`).
- OpenMM's dispersion correction averages the Lennard-Jones tail over atom
  pairs that include each atom's pair with itself: it is larger than
  LAMMPS's ``pair_modify tail`` by :math:`(1 + 1/N_O)\,N/(N + 1)` (0.5 % at
  125 TIP3P waters, 0.003 kJ/mol per molecule).

OpenMM is an optional dependency (``pip install openmm``; the ``test`` extra
has it); it is imported when a function here is called.
"""

from __future__ import annotations

import numpy as np
from ase import units

from rigidmd.core.bodies import cell_widths
from rigidmd.water import real_argument, water_model, whole_argument

__all__ = ["FORCE_FIELD_FILES", "water_topology", "water_system", "real_atom_forces"]

#: OpenMM's force-field file of each :mod:`rigidmd.water` model it ships.
FORCE_FIELD_FILES = {"tip3p": "tip3p.xml", "spce": "spce.xml", "tip4pew": "tip4pew.xml",
                     "opc": "opc.xml"}


def _file(model):
    if model.name not in FORCE_FIELD_FILES:
        raise ValueError(f"rigidmd.openmm: OpenMM ships no file for {model.name}; "
                         f"use one of {', '.join(FORCE_FIELD_FILES)}")
    return FORCE_FIELD_FILES[model.name]


def water_topology(model, n_molecules, cell):
    """OpenMM's topology of ``n_molecules`` waters of ``model`` (O, H1, H2 and M if any).

    Parameters
    ----------
    model : str or rigidmd.water.WaterModel
        The model or its name (:func:`rigidmd.water.water_model`).
    n_molecules : int
        A whole number >= 0.
    cell : array_like, shape (3, 3)
        Periodic cell, Å (rows are the cell vectors).

    Returns
    -------
    openmm.app.Topology

    Raises
    ------
    TypeError, ValueError
        An unknown ``model``, ``n_molecules`` not a whole number >= 0.
    """
    from openmm import app, unit

    model = water_model(model)
    n_molecules = whole_argument("rigidmd.openmm", "n_molecules", n_molecules, 0)
    top = app.Topology()
    chain = top.addChain()
    for _ in range(n_molecules):
        res = top.addResidue("HOH", chain)
        oxygen = top.addAtom("O", app.element.oxygen, res)
        for name in ("H1", "H2"):
            top.addBond(oxygen, top.addAtom(name, app.element.hydrogen, res))
        if model.sites == 4:
            top.addAtom("M", None, res)
    top.setPeriodicBoxVectors(np.asarray(cell, dtype=float) / 10 * unit.nanometer)
    return top


def _check_whole(atoms, model):
    """Refuse atoms that are not whole molecules of ``model`` without the minimum image."""
    model.check(atoms)
    x = atoms.positions.reshape(-1, model.sites, 3)
    span = np.linalg.norm(x - x[:, :1], axis=2).max(axis=1)
    size = np.linalg.norm(model.molecule().positions, axis=1).max()
    split = np.flatnonzero(span > size + 1e-3)
    if split.size:
        m = int(split[0])
        raise ValueError(
            f"rigidmd.openmm: molecule {m} (atoms {model.sites * m}-"
            f"{model.sites * m + model.sites - 1}) is split across the cell boundary; OpenMM "
            "needs whole molecules (water_box(..., whole=True), or "
            "RigidBodies.whole_positions)")


def _check_reduced_cell(cell):
    """Refuse a cell OpenMM cannot take: it needs its reduced form (OpenMM's ``System``).

    That is a along x, b in the xy plane (lower-triangular, positive diagonal)
    and each tilt at most half the length below it: ``|b_x| <= a_x/2``,
    ``|c_x| <= a_x/2``, ``|c_y| <= b_y/2``.  OpenMM checks these exactly
    (``System::setDefaultPeriodicBoxVectors``: ``a_y``, ``a_z`` and ``b_z``
    must be 0, ``a_x >= 2 |b_x|`` and so on), so they are checked here exactly
    too; the Å to nm conversion (a division by 10, rounded alike on both
    sides) keeps them.
    """
    cell = np.asarray(cell, dtype=float)
    lower = np.all(cell[[0, 0, 1], [1, 2, 2]] == 0)
    tilts = [(1, 0, 0), (2, 0, 0), (2, 1, 1)]
    reduced = lower and np.all(np.diag(cell) > 0) and all(
        2 * abs(cell[row, column]) <= cell[length, length] for row, column, length in tilts)
    if not reduced:
        raise ValueError(
            f"rigidmd.openmm: OpenMM takes a cell in its reduced form (a along x, b in the xy "
            f"plane, exact zeros above the diagonal, each tilt at most half the length below "
            f"it), not {cell.tolist()}; "
            "give the atoms that cell first (ase.cell.Cell.standard_form rotates it, "
            "ase.geometry.minkowski_reduce reduces the tilts)")


def water_system(atoms, model, cutoff, *, tail=True, parameters="file",
                 error_tolerance=1e-6):
    """OpenMM's topology and system for whole waters of ``model`` in a periodic cell.

    Parameters
    ----------
    atoms : ase.Atoms
        Whole molecules of ``model`` in its order (O, H, H, M), periodic.
    model : str or rigidmd.water.WaterModel
        One of :data:`FORCE_FIELD_FILES`, or its name.
    cutoff : float
        Real-space cut-off of Lennard-Jones and Coulomb, Å, at most half the
        cell's smallest width.
    tail : bool, default True
        OpenMM's dispersion correction (see the module's note on its counting).
    parameters : {"file", "rigidmd"}
        Charges, σ and ε from OpenMM's file, or rigidmd's ``model``'s.
    error_tolerance : float, default 1e-6
        PME's ``ewaldErrorTolerance``.

    Returns
    -------
    (openmm.app.Topology, openmm.System)
        The system's :class:`openmm.NonbondedForce` is in force group 1, the
        rest in group 0.

    Raises
    ------
    TypeError
        ``cutoff`` not a number.
    ValueError
        An unknown model or one OpenMM has no file for, atoms that are not
        whole molecules of it, a cut-off beyond half the cell, an unknown
        ``parameters``.
    """
    import openmm
    from openmm import app, unit

    model = water_model(model)
    name = _file(model)
    if parameters not in ("file", "rigidmd"):
        raise ValueError(f"rigidmd.openmm: parameters must be 'file' or 'rigidmd', "
                         f"got {parameters!r}")
    if not atoms.pbc.all():
        raise ValueError("rigidmd.openmm: the atoms need a periodic cell (PME)")
    _check_reduced_cell(atoms.cell.array)
    half = cell_widths(atoms.cell).min() / 2
    cutoff = real_argument("rigidmd.openmm", "cutoff", cutoff, unit=" Å")
    if not cutoff <= half:
        raise ValueError(f"rigidmd.openmm: cutoff {cutoff} Å must be positive and at most "
                         f"half the cell's smallest width ({half:.3f} Å)")
    _check_whole(atoms, model)
    n = len(atoms) // model.sites
    top = water_topology(model, n, atoms.cell.array)
    system = app.ForceField(name).createSystem(
        top, nonbondedMethod=app.PME, nonbondedCutoff=cutoff / 10 * unit.nanometer,
        rigidWater=True, ewaldErrorTolerance=error_tolerance)
    for force in system.getForces():
        force.setForceGroup(1 if isinstance(force, openmm.NonbondedForce) else 0)
    nonbonded = next(f for f in system.getForces() if isinstance(f, openmm.NonbondedForce))
    nonbonded.setUseDispersionCorrection(bool(tail))
    if parameters == "rigidmd":
        kj = units.kJ / units.mol
        charges = model.charges(n)
        for i, z in enumerate(atoms.numbers):
            lj = z == 8
            nonbonded.setParticleParameters(i, charges[i], model.sigma / 10 if lj else 0.1,
                                            model.epsilon / kj if lj else 0.0)
    return top, system


def real_atom_forces(system, forces):
    """``forces`` (n_atoms, 3) with the virtual sites' rows zeroed (OpenMM spread them)."""
    forces = np.array(forces, dtype=float)
    forces[[system.isVirtualSite(i) for i in range(system.getNumParticles())]] = 0.0
    return forces
