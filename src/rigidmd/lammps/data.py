"""LAMMPS data files (``atom_style full``, ``units metal``) from ASE Atoms and bodies."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from ase import Atoms

from rigidmd.core.bodies import RigidBodies
from rigidmd.core.velocities import rigid_velocities
from rigidmd.lammps.library import charge_factor, velocity_factor

__all__ = ["LammpsData", "write_data", "check_body_ids", "atom_types_of", "lammps_box",
           "MASSLESS_SITE_MASS"]

#: Mass (amu) written for a massless site: LAMMPS needs every mass positive.  Inside a
#: ``fix rigid/small`` body it shifts the centre of mass by about 1e-22 Å (M of TIP4P
#: water: 1e-20 amu at 0.15 Å in 18 amu), far below roundoff.
MASSLESS_SITE_MASS = 1e-20


@dataclass(frozen=True)
class LammpsData:
    """What :func:`write_data` wrote.

    Atom ``i`` of the ASE ``Atoms`` has LAMMPS atom ID ``i + 1``.

    Attributes
    ----------
    path : pathlib.Path
        The data file.
    types : dict of str to int
        Atom type label -> LAMMPS atom type (1-based), in order of first
        appearance in the atoms.  One type per distinct (element, mass) pair;
        the label is the element symbol, or ``"<symbol>_<k>"`` (k = 1, 2, ...)
        when an element occurs with several masses.  The labels are also
        written to the data file (``Atom Type Labels``), so LAMMPS commands
        may use them (``pair_coeff O O ...``).
    type_masses : numpy.ndarray, shape (ntypes,)
        Mass of each type (index ``type - 1``), amu.
    atom_types : numpy.ndarray of int, shape (n,)
        LAMMPS atom type of each atom.
    molecule_ids : numpy.ndarray of int, shape (n,)
        LAMMPS molecule ID of each atom: ``b + 1`` for rigid body ``b``; free
        atoms get ``n_body_ids + 1``, ``n_body_ids + 2``, ... in atom order.
    n_body_ids : int
        ``max(body_ids) + 1`` (0 when there are no bodies): molecule IDs
        ``1 .. n_body_ids`` are rigid bodies, larger ones free atoms.
    charges : numpy.ndarray, shape (n,)
        Charges written (after the :func:`charge_factor` scaling), e.
    boundary : str
        ``"f f f"`` (cluster) or ``"p p p"`` (periodic).
    velocity_factor : float
        LAMMPS velocity (Å/ps) per ASE velocity, see :func:`velocity_factor`.
    charge_factor : float
        See :func:`charge_factor`.
    """

    path: Path
    types: dict[str, int]
    type_masses: np.ndarray
    atom_types: np.ndarray
    molecule_ids: np.ndarray
    n_body_ids: int
    charges: np.ndarray
    boundary: str
    velocity_factor: float
    charge_factor: float


def check_body_ids(atoms: Atoms, body_ids) -> np.ndarray:
    body_ids = np.asarray(body_ids)
    if body_ids.shape != (len(atoms),):
        raise ValueError(f"body_ids must have shape ({len(atoms)},), got {body_ids.shape}")
    if (
        body_ids.size
        and not np.issubdtype(body_ids.dtype, np.integer)
        and not np.array_equal(body_ids, np.round(body_ids))
    ):
        raise ValueError("body_ids must be integers")
    body_ids = body_ids.astype(np.int64)
    if body_ids.size and body_ids.min() < -1:
        raise ValueError("body_ids must be >= -1 (-1 marks a free atom)")
    return body_ids


def atom_types_of(atoms: Atoms, type_labels=None):
    """One type per (label, mass) pair, in order of first appearance.

    Labels are the chemical symbols unless ``type_labels`` (one string per
    atom) is given.
    """
    symbols = atoms.get_chemical_symbols() if type_labels is None else list(type_labels)
    if len(symbols) != len(atoms):
        raise ValueError(
            f"type_labels must have one label per atom ({len(atoms)}), got {len(symbols)}"
        )
    masses = atoms.get_masses()
    keys: dict[tuple[str, float], int] = {}
    atom_types = np.empty(len(atoms), dtype=np.int64)
    for i, key in enumerate(zip(symbols, masses.tolist(), strict=True)):
        atom_types[i] = keys.setdefault(key, len(keys) + 1)
    n_per_symbol: dict[str, int] = {}
    for sym, _ in keys:
        n_per_symbol[sym] = n_per_symbol.get(sym, 0) + 1
    seen: dict[str, int] = {}
    labels = {}
    for (sym, _), t in keys.items():
        if n_per_symbol[sym] == 1:
            labels[sym] = t
        else:
            seen[sym] = seen.get(sym, 0) + 1
            labels[f"{sym}_{seen[sym]}"] = t
    # LAMMPS refuses a mass of 0 ("Invalid mass value"): a massless site (TIP4P's M) gets
    # MASSLESS_SITE_MASS, as the LAMMPS manual advises for explicit M sites in fix rigid.
    type_masses = np.array([m if m > 0 else MASSLESS_SITE_MASS for _, m in keys])
    return labels, type_masses, atom_types


def lammps_box(atoms: Atoms, margin: float):
    """Box bounds, tilts and boundary string; positions wrapped, image flags."""
    pos = atoms.get_positions()
    pbc = atoms.pbc
    if not pbc.any():
        if len(atoms):
            lo = pos.min(axis=0) - margin
            hi = pos.max(axis=0) + margin
        else:
            lo, hi = np.full(3, -margin), np.full(3, margin)
        return lo, hi, None, "f f f", pos, np.zeros((len(atoms), 3), np.int64)
    if not pbc.all():
        raise ValueError(
            "mixed periodicity is not supported: atoms.pbc must be all True or all False"
        )
    cell = np.array(atoms.cell)
    scale = np.abs(cell).max()
    upper = cell[[0, 0, 1], [1, 2, 2]]
    if np.any(np.abs(upper) > 1e-12 * scale) or np.any(np.diag(cell) <= 0):
        raise ValueError(
            "LAMMPS needs the cell in its lower-triangular form "
            "(a along x, b in the xy plane, positive diagonal); rotate the "
            "atoms first, e.g. with atoms.set_cell(atoms.cell.standard_form()"
            "[0], scale_atoms=True) and matching velocities"
        )
    cell[[0, 0, 1], [1, 2, 2]] = 0.0
    frac = np.linalg.solve(cell.T, pos.T).T
    image = np.floor(frac).astype(np.int64)
    wrapped = pos - image @ cell
    tilt = cell[[1, 2, 2], [0, 0, 1]]  # xy, xz, yz
    tilt = tilt if np.any(tilt != 0.0) else None
    return np.zeros(3), np.diag(cell).copy(), tilt, "p p p", wrapped, image


def write_data(
    atoms: Atoms,
    body_ids,
    path: str | os.PathLike,
    charges=None,
    *,
    ase_constants: bool = True,
    margin: float = 50.0,
    type_labels=None,
) -> LammpsData:
    """Write a LAMMPS data file (``atom_style full``, ``units metal``).

    Parameters
    ----------
    atoms : ase.Atoms
        Positions (Å), masses (amu) and
        velocities (``atoms.get_velocities()``, Å / ASE time unit).
        ``atoms.pbc`` must be all False (a cluster, written in a box with
        ``margin`` around the atoms, for ``boundary f f f``) or all True
        (``boundary p p p``; the cell must be in LAMMPS's lower-triangular
        form, orthorhombic or triclinic).  Periodic bodies are first made
        whole by minimum image (:meth:`RigidBodies.whole_positions`), then
        wrapped into the box with image flags such that LAMMPS's unwrapped
        coordinates are those whole positions.
    body_ids : array_like of int, shape (n,)
        ``b >= 0``: the atom belongs to rigid body ``b`` (molecule ID
        ``b + 1``); ``-1``: free atom (its own molecule ID after the bodies').
    path : str or os.PathLike
        File to write.
    charges : array_like, shape (n,), optional
        Atom charges, e.  Default ``atoms.get_initial_charges()``.
    ase_constants : bool, default True
        Convert velocities and charges so LAMMPS reproduces ASE's constants;
        see the module docstring, :func:`velocity_factor`,
        :func:`charge_factor`.
    margin : float, default 50.0
        Space between a cluster's atoms and its box faces, Å.
    type_labels : sequence of str, shape (n,), optional
        Atom-type label of every atom (default: its chemical symbol), for
        force fields that give one element several types (the O of CO2 and
        of water, say).  Atoms of one label must share one mass to share a
        type; the labels name the types in ``pair_coeff`` commands.

    Returns
    -------
    LammpsData
        Type mapping, molecule IDs and the conversion factors used.
    """
    path = Path(path)
    body_ids = check_body_ids(atoms, body_ids)
    n = len(atoms)
    if charges is None:
        charges = atoms.get_initial_charges()
    charges = np.asarray(charges, dtype=float)
    if charges.shape != (n,):
        raise ValueError(f"charges must have shape ({n},), got {charges.shape}")
    vfac = velocity_factor(ase_constants)
    qfac = charge_factor(ase_constants)
    charges = charges * qfac

    labels, type_masses, atom_types = atom_types_of(atoms, type_labels)
    n_body_ids = int(body_ids.max()) + 1 if n and body_ids.max() >= 0 else 0
    molecule_ids = body_ids + 1
    free = body_ids < 0
    molecule_ids[free] = n_body_ids + 1 + np.arange(int(free.sum()))

    if atoms.pbc.any():
        # Every body whole, as rigidmd sees it, so that LAMMPS's image flags
        # put each molecule's atoms together.
        atoms = atoms.copy()
        atoms.positions = RigidBodies(body_ids).whole_positions(atoms)
    lo, hi, tilt, boundary, pos, image = lammps_box(atoms, margin)
    masses = atoms.get_masses()
    if np.all(masses > 0):
        vel = atoms.get_momenta() / masses[:, None]
    else:  # a massless site moves with its body (its p / m is 0 / 0)
        vel = rigid_velocities(atoms, RigidBodies(body_ids))
    vel = vel * vfac

    g = "{!r}".format
    lines = [
        "LAMMPS data file written by rigidmd (atom_style full, units metal)",
        "",
        f"{n} atoms",
        f"{len(type_masses)} atom types",
        "",
    ]
    for k, ax in enumerate("xyz"):
        lines.append(f"{g(float(lo[k]))} {g(float(hi[k]))} {ax}lo {ax}hi")
    if tilt is not None:
        lines.append(" ".join(g(float(t)) for t in tilt) + " xy xz yz")
    lines += ["", "Atom Type Labels", ""]
    lines += [f"{t} {label}" for label, t in labels.items()]
    lines += ["", "Masses", ""]
    lines += [f"{t} {g(m)}" for t, m in enumerate(type_masses.tolist(), start=1)]

    ids = np.arange(1, n + 1)
    lines += ["", "Atoms # full", ""]
    lines += [
        f"{i} {mol} {typ} {g(q)} {g(x)} {g(y)} {g(z)} {ix} {iy} {iz}"
        for i, mol, typ, q, (x, y, z), (ix, iy, iz) in zip(
            ids.tolist(),
            molecule_ids.tolist(),
            atom_types.tolist(),
            charges.tolist(),
            pos.tolist(),
            image.tolist(),
            strict=True,
        )
    ]
    lines += ["", "Velocities", ""]
    lines += [
        f"{i} {g(vx)} {g(vy)} {g(vz)}"
        for i, (vx, vy, vz) in zip(ids.tolist(), vel.tolist(), strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")

    return LammpsData(
        path=path,
        types=labels,
        type_masses=type_masses,
        atom_types=atom_types,
        molecule_ids=molecule_ids,
        n_body_ids=n_body_ids,
        charges=charges,
        boundary=boundary,
        velocity_factor=vfac,
        charge_factor=qfac,
    )


