"""LAMMPS input decks: the set-up and integration commands, and the export of a rigidmd run."""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import numpy as np
from ase import Atoms, units

from rigidmd.lammps.data import LammpsData, check_body_ids, write_data
from rigidmd.lammps.library import flatten

__all__ = ["setup_commands", "integration_commands", "coupling_fix", "export_lammps", "number"]


def number(x):
    """A float for a deck: the shortest form that is at most 1e-15 off (``0.02``, not
    ``0.019999999999999997``)."""
    return f"{float(x):.15g}"


def setup_commands(data: LammpsData, pair_commands: Iterable[str]) -> list[str]:
    """Units, atom style, box and data file, then the interaction commands."""
    return [
        "units metal",
        "atom_style full",
        "atom_modify map array",
        f"boundary {data.boundary}",
        f'read_data "{data.path}"',
        *flatten(pair_commands),
    ]


def coupling_fix(couplings=(), time_unit=1.0, seed=12345, free_atoms=False):
    """The LAMMPS fixes of a run's coupling parts (thermostat and barostat), combined.

    Each part says what it is in LAMMPS (:meth:`rigidmd.couplings.base.Coupling.lammps_fix`);
    here they are joined into one rigid fix: ``nve`` (NVE or Langevin),
    ``nvt`` (Nosé–Hoover), ``npt`` (Nosé–Hoover and MTK) or ``nph`` (MTK alone).

    Parameters
    ----------
    couplings : sequence of rigidmd.couplings.base.Coupling
    time_unit : float
        The LAMMPS time unit in ASE time units.
    seed : int
        Random seed of a Langevin thermostat.
    free_atoms : bool
        Whether the system has atoms in no body (LAMMPS's rigid barostats do
        not move them with the box).

    Returns
    -------
    rigidmd.couplings.base.LammpsFix

    Raises
    ------
    rigidmd.couplings.base.NotExportable
        A part, or a combination of parts, LAMMPS cannot do.
    """
    from rigidmd.couplings.base import LammpsFix, NotExportable

    fixes = {part.section: part.lammps_fix(time_unit=time_unit, seed=seed)
             for part in couplings}
    thermostat, barostat = fixes.get("thermostat"), fixes.get("barostat")
    if barostat is None:
        return thermostat or LammpsFix("nve", "", ("nve",))
    if thermostat is not None and thermostat.body_style != "nvt":
        raise NotExportable("thermostat.kind: LAMMPS's rigid barostat (fix rigid/npt) takes "
                            "Nose-Hoover chains only; use nose_hoover with a barostat")
    if free_atoms:
        raise NotExportable("barostat: LAMMPS's fix rigid/npt/small does not move atoms in no "
                            "body with the box; export works for systems of bodies only")
    if thermostat is None:
        return LammpsFix("nph", barostat.body_keywords)
    return LammpsFix("npt", f"{thermostat.body_keywords} {barostat.body_keywords}",
                     notes=thermostat.notes)


def integration_commands(data, body_ids, timestep, fix, couplings=(), seed=12345):
    """Time step, neighbour settings and the fixes that move bodies and free atoms.

    Parameters
    ----------
    data : LammpsData
    body_ids : numpy.ndarray of int
    timestep : float
        ASE time units.
    fix : str
        The rigid fix style: ``"rigid"`` (Richardson), or ``"rigid/<style>"``
        and ``"rigid/<style>/small"`` where ``<style>`` must be what the
        couplings make (``nve``, ``nvt``, ``npt``, ``nph``).
    couplings : sequence of rigidmd.couplings.base.Coupling
    seed : int
    """
    vf = data.velocity_factor
    n = len(body_ids)
    nb = data.n_body_ids
    free = bool(np.any(body_ids < 0))
    combined = coupling_fix(couplings, time_unit=vf, seed=seed, free_atoms=free)
    if fix != "rigid" and fix.split("/")[1] != combined.body_style:
        raise ValueError(f"fix {fix!r} does not match the couplings, which need "
                         f"rigid/{combined.body_style}")
    cmds = [f"# note: {note}" for note in combined.notes]
    cmds.append(f"timestep {number(timestep / vf)}")
    if data.boundary == "f f f":
        one = max(2000, n)
        cmds.append(f"neigh_modify one {one} page {max(100000, 10 * one)}")
    cmds.append("neigh_modify every 1 delay 0 check yes")
    keywords = f" {combined.body_keywords}" if combined.body_keywords else ""
    if np.any(body_ids >= 0):
        cmds += [f"group rigidgroup molecule <= {nb}",
                 f"fix 1 rigidgroup {fix} molecule{keywords}"]
    if free:
        cmds.append(f"group freegroup molecule > {nb}")
        cmds += [f"fix {2 + i} freegroup {style}" for i, style in enumerate(combined.free_fixes)]
    return cmds


def export_lammps(
    atoms: Atoms,
    body_ids,
    directory: str | os.PathLike,
    pair_commands: Iterable[str],
    timestep: float,
    nsteps: int,
    *,
    couplings=(),
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

    The deck uses ``fix rigid/<style>/small molecule`` (NO_SQUISH, the default
    integrator of :class:`~rigidmd.RigidVerlet`), with the style and keywords
    that the run's coupling parts make (:func:`coupling_fix`): ``nve``,
    ``nve ... langevin`` (:class:`~rigidmd.RigidLangevin`), ``nvt``
    (:class:`~rigidmd.RigidNoseHoover`), ``npt`` (:class:`~rigidmd.RigidNPT`,
    ``iso`` or ``aniso``) or ``nph``; free atoms get ``fix nve`` / ``nvt`` /
    ``langevin``.  LAMMPS's own ``metal`` constants are used (the deck is for
    production runs, e.g. ``mpirun -np 64 lmp -in in.rigidmd``), so it
    follows rigidmd to about 1e-7 Å over 100 steps, not to roundoff.  It
    writes thermo output (with volume and pressure under a barostat), a
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
    couplings : sequence of rigidmd.couplings.base.Coupling, optional
        The run's thermostat and barostat parts.
    temperature_K, tdamp, friction : float, optional
        A thermostat given by value instead: ``tdamp`` (ASE time) for
        Nosé–Hoover, ``friction`` (per ASE time) for Langevin.
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

    Raises
    ------
    rigidmd.couplings.base.NotExportable
        A coupling LAMMPS has no equivalent for (Bussi, C-rescale, ``tri``).
    """
    from rigidmd.couplings.thermostats import LangevinThermostat, NoseHooverThermostat

    if tdamp is not None and friction is not None:
        raise ValueError("give tdamp (Nose-Hoover) or friction (Langevin), not both")
    if (tdamp is not None or friction is not None) != (temperature_K is not None):
        raise ValueError("a thermostat needs temperature_K and one of tdamp or friction")
    couplings = list(couplings)
    if tdamp is not None:
        couplings.append(NoseHooverThermostat(temperature_K, tdamp))
    elif friction is not None:
        couplings.append(LangevinThermostat(temperature_K, friction))
    body_ids = check_body_ids(atoms, body_ids)
    sizes = np.bincount(body_ids[body_ids >= 0])
    if np.any(sizes == 1):
        raise ValueError("LAMMPS fix rigid refuses bodies of one atom; give them body_id -1")
    time_unit = 1000.0 * units.fs
    style = coupling_fix(couplings, time_unit, seed, free_atoms=bool(np.any(body_ids < 0)))
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    data = write_data(atoms, body_ids, directory / "data.rigidmd", charges, ase_constants=False,
                      type_labels=type_labels)
    # A relative path, so the directory can be moved to another machine.
    data = replace(data, path=Path("data.rigidmd"))
    thermo = "step time temp pe ke etotal"
    if style.body_style in ("npt", "nph"):
        thermo += " vol press density"
    cmds = [
        "# LAMMPS input written by rigidmd: the same bodies, interactions and",
        "# integrator as the rigidmd run (metal units: eV, Å, ps).",
        *setup_commands(data, pair_commands),
        *integration_commands(data, body_ids, timestep, f"rigid/{style.body_style}/small",
                              couplings, seed),
        f"thermo_style custom {thermo}",
        "thermo_modify norm no",
        f"thermo {int(thermo_every)}",
        f"dump frames all custom {int(dump_every)} frames.dump id xu yu zu vx vy vz",
        "dump_modify frames sort id format float %.17g",
        f"run {int(nsteps)}",
    ]
    path = directory / "in.rigidmd"
    path.write_text("\n".join(cmds) + "\n")
    return {"data": directory / "data.rigidmd", "input": path, "dump": "frames.dump"}
