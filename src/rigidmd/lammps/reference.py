"""LAMMPS reference runs: rigid-body trajectories and single-point energies, in ASE units."""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from ase import Atoms

from rigidmd.lammps.data import LammpsData, check_body_ids, write_data
from rigidmd.lammps.deck import integration_commands, setup_commands
from rigidmd.lammps.library import execute_checked, flatten, load_lammps

__all__ = ["RIGID_FIX_STYLES", "RigidReference", "run_rigid_reference", "lammps_energy_forces",
           "read_dump"]

#: Fix styles accepted by :func:`run_rigid_reference`.
RIGID_FIX_STYLES = ("rigid", "rigid/nve", "rigid/small", "rigid/nve/small", "rigid/nvt",
                    "rigid/nvt/small", "rigid/npt", "rigid/npt/small", "rigid/nph",
                    "rigid/nph/small")


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
    stress: bool = False,
):
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

    stress : bool, default False
        Also return the stress of a periodic system.

    Returns
    -------
    energy : float
        Potential energy (LAMMPS ``pe``), eV.
    forces : numpy.ndarray, shape (n, 3)
        Forces in ASE atom order, eV/Å.
    stress : numpy.ndarray, shape (6,)
        With ``stress=True``: the virial stress in ASE's convention (eV/Å³,
        ``xx yy zz yz xz xy``), from ``compute pressure NULL virial`` and
        LAMMPS's ``nktv2p``.
    """
    with _WorkDir(workdir) as wd:
        data = write_data(atoms, body_ids, wd / "data.lmp", charges, ase_constants=ase_constants,
                          type_labels=type_labels)
        lmp = load_lammps()
        try:
            cmds = setup_commands(data, pair_commands)
            cmds += flatten(extra_commands)
            cmds += ["compute rmd_virial all pressure NULL virial",
                     "thermo_style custom step pe c_rmd_virial[1]", "run 0"]
            execute_checked(lmp, cmds)
            energy = float(lmp.get_thermo("pe"))
            if stress:
                xx, yy, zz, xy, xz, yz = np.asarray(
                    lmp.numpy.extract_compute("rmd_virial", 0, 1), dtype=float)[:6]
                sigma = -np.array([xx, yy, zz, yz, xz, xy]) / lmp.extract_global("nktv2p")
            nlocal = lmp.extract_global("nlocal")
            ids = np.array(lmp.numpy.extract_atom("id")[:nlocal], dtype=np.int64)
            f = np.array(lmp.numpy.extract_atom("f")[:nlocal], dtype=float)
        finally:
            lmp.close()
    forces = np.empty((len(atoms), 3))
    forces[ids - 1] = f
    if stress:
        return energy, forces, sigma
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
    volume : numpy.ndarray, shape (nframes,) or None
        Box volume (Å³) of a periodic run; None for a cluster.
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
    volume: np.ndarray | None = None


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
    couplings=(),
    seed: int = 12345,
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
        ``nvt`` fix (``temp T T tdamp``): a Nosé–Hoover thermostat part.
    couplings : sequence of rigidmd.couplings.base.Coupling, optional
        Thermostat and barostat parts; their LAMMPS equivalent
        (:func:`~rigidmd.lammps.deck.coupling_fix`) must match ``fix``.
    seed : int
        Langevin random seed.

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
    from rigidmd.couplings.thermostats import NoseHooverThermostat

    if fix not in RIGID_FIX_STYLES:
        raise ValueError(f"fix must be one of {RIGID_FIX_STYLES}, got {fix!r}")
    if (temperature_K is None) != (tdamp is None):
        raise ValueError("temperature_K and tdamp go together (a Nose-Hoover thermostat)")
    couplings = list(couplings)
    if tdamp is not None:
        couplings.append(NoseHooverThermostat(temperature_K, tdamp))
    nsteps = int(nsteps)
    every = int(every)
    if nsteps < 0 or every < 1:
        raise ValueError("need nsteps >= 0 and every >= 1")
    body_ids = check_body_ids(atoms, body_ids)
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
        cmds = setup_commands(data, pair_commands) + ["thermo_modify norm no"]
        cmds += integration_commands(data, body_ids, timestep, fix, couplings, seed)
        cmds += [
            "compute rmd_ke all ke",
            "variable rmd_vol equal vol",
            (
                f"fix rmd_energy all ave/time {every} 1 {every} c_thermo_pe c_rmd_ke v_rmd_vol"
                f' file "{energy_path}" format " %.17g"'
            ),
            f'dump rmd_dump all custom {every} "{dump_path}" id xu yu zu vx vy vz',
            "dump_modify rmd_dump sort id format float %.17g",
            *flatten(extra_commands),
            f'log "{log_path}"',
            f"run {nsteps}",
        ]
        lmp = load_lammps()
        try:
            execute_checked(lmp, cmds)
        finally:
            lmp.close()
        steps, positions, velocities = _read_dump(dump_path, n)
        energies = np.loadtxt(energy_path, comments="#", ndmin=2)
        timing = _read_timing(log_path)

    if not np.array_equal(energies[:, 0].astype(np.int64), steps):
        raise RuntimeError("LAMMPS dump and energy frames do not match")
    pe = energies[:, 1].copy()
    ke = energies[:, 2].copy()
    volume = energies[:, 3].copy() if data.boundary == "p p p" else None
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
        volume=volume,
    )


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
