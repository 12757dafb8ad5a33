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

__all__ = ["setup_commands", "integration_commands", "coupling_fix", "export_lammps", "number",
           "pressure_commands"]

#: LAMMPS's ``metal`` constants (``force->nktv2p``: eV/Å³ to bar; ``force->mvv2e``:
#: amu Å²/ps² to eV), as LAMMPS's own ``press`` uses them.
METAL_NKTV2P = 1.6021765e6
METAL_MVV2E = 1.0364269e-4


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


def pressure_commands(pair_commands: Iterable[str] = ()) -> list[str]:
    """The deck's ``v_press_mol`` (rigidmd's pressure, bar) and what ``press`` includes.

    rigidmd's pressure is the molecular one: (2 K_com + tr W_mol) / 3V, the centres of
    mass' kinetic energy and the molecular virial (the atomic virial less the sum of
    d_i . f_i over each body's atoms about its centre of mass; a
    free atom is a body of its own).  LAMMPS's thermo ``press`` is the atomic pressure with
    ``fix rigid``'s constraint virial, which ``fix rigid`` computes from the velocity change
    over a step: at step 0 it is incomplete (27 waters: +10.5 bar against rigidmd's -2096.3
    bar), later it differs from rigidmd's step by step by tens of bar.  ``v_press_mol``
    computes the molecular pressure in LAMMPS, at every thermo step (step 0 included):
    equal to rigidmd's to 3e-8 relative (LAMMPS's ``metal`` constants against ASE's).

    Parameters
    ----------
    pair_commands : iterable of str
        The deck's interaction commands (for the note on LAMMPS's warning about
        excluded pairs with a k-space solver).

    Returns
    -------
    list of str
        Comment lines, computes and the ``press_mol`` variable (thermo: ``v_press_mol``).
    """
    commands = flatten(pair_commands)
    notes = [
        "# Pressure (bar).  LAMMPS's thermo `press` is the atomic pressure: 2 KE of every",
        "# atom (translation and rotation) + the atomic virial (pair and k-space) + fix",
        "# rigid's constraint virial, over 3V.  fix rigid computes its constraint virial from",
        "# the velocity change over a step, so `press` at step 0 is incomplete; later it",
        "# differs from rigidmd's step by step (by tens of bar on liquid water).",
        "# v_press_mol is rigidmd's pressure at every step, step 0 included: the molecular",
        "# pressure, 2 KE of the centres of mass + the molecular virial (the atomic one less",
        "# sum d_i.f_i over each molecule's atoms about its centre of mass), over 3V.",
    ]
    words = {c.split()[0] for c in commands if c.split()}
    if "kspace_style" in words and any("exclude" in c.split() for c in commands):
        notes += [
            "# LAMMPS warns \"Neighbor exclusions used with KSpace solver may give inconsistent",
            "# Coulombic energies\": the excluded intramolecular pairs keep their k-space part,",
            "# a constant of a rigid molecule, as in rigidmd's LAMMPS calculator (expected).",
        ]
    spread = "c_rmd_spread"
    dvir = "+".join(f"(c_rmd_xu[{k}]-{spread}[{k}])*f{a}" for k, a in zip((1, 2, 3), "xyz",
                                                                           strict=True))
    return notes + [
        "compute rmd_chunk all chunk/atom molecule",
        "compute rmd_com all com/chunk rmd_chunk",
        "compute rmd_vcm all vcm/chunk rmd_chunk",
        "compute rmd_spread all chunk/spread/atom rmd_chunk c_rmd_com[*] c_rmd_vcm[*]",
        "compute rmd_xu all property/atom xu yu zu",
        f"variable rmd_dvir atom {dvir}",
        f"variable rmd_kcom atom mass*({spread}[4]^2+{spread}[5]^2+{spread}[6]^2)",
        "compute rmd_sums all reduce sum v_rmd_dvir v_rmd_kcom",
        "compute rmd_pvir all pressure NULL pair kspace",
        f"variable press_mol equal c_rmd_pvir+(c_rmd_sums[2]*{METAL_MVV2E!r}"
        f"-c_rmd_sums[1])/(3*vol)*{METAL_NKTV2P!r}",
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
        raise NotExportable("barostat: without a thermostat rigidmd's barostat still holds "
                            "its temperature (its chain's and the cell's), which LAMMPS's "
                            "fix rigid/nph/small has no keyword for; export works with a "
                            "nose_hoover thermostat (fix rigid/npt/small)")
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
    periodic = data.boundary == "p p p"
    if style.body_style in ("npt", "nph"):
        thermo += " vol press v_press_mol density"
    elif periodic:
        thermo += " press v_press_mol"
    cmds = [
        "# LAMMPS input written by rigidmd: the same bodies, interactions and",
        "# integrator as the rigidmd run (metal units: eV, Å, ps).",
        *setup_commands(data, pair_commands),
        *integration_commands(data, body_ids, timestep, f"rigid/{style.body_style}/small",
                              couplings, seed),
        *(pressure_commands(pair_commands) if periodic else []),
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
