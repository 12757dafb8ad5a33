"""``rigidmd relax CONFIG`` and the relaxation before ``rigidmd export-lammps``.

The command's side of :mod:`rigidmd.run.relaxstructure`: the configuration's
sections, the output directory's lock, the outputs of an earlier
relaxation (refused, replaced with ``--overwrite`` or continued with
``--resume``, never the structure being read), and signals.
"""

import signal
import sys
from pathlib import Path

import numpy as np

from rigidmd.run.fingerprint import calculator_digest, resume_command
from rigidmd.run.relaxstructure import (
    RelaxationStopped,
    continue_from,
    relax_structure,
    relaxation_label,
    state_path,
)
from rigidmd.run.runner import StopSignals

__all__ = ["relax_only", "relax_for_export"]


def relax_only(raw, stream=sys.stdout, trust=False, mode="new", config_path=None):
    """``rigidmd relax CONFIG``: build the structure and calculator, relax, write.

    Parameters
    ----------
    raw : dict
        A configuration as :func:`rigidmd.config.load_config` returns; the MD
        keys may be present and are ignored, a missing ``relax:`` section is
        the defaults of :class:`~rigidmd.config.relaxsection.RelaxSection`.
    trust : bool
        ``--trust``: let the calculator section run what could run code
        (:mod:`rigidmd.config.trust`), as for ``rigidmd run``.
    mode : str
        ``"new"`` (refuses a directory holding a relaxation's outputs),
        ``"overwrite"`` (replaces them, after every input was read) or
        ``"resume"`` (continues from the last frame of the trajectory).
    config_path : str, optional
        The configuration's file, for the message that says how to continue.

    Returns
    -------
    int
        Exit status: 0, or 130/143/138 after a stop signal.
    """
    from rigidmd.config import known_keys
    from rigidmd.config.quantities import ConfigError
    from rigidmd.config.relaxsection import RelaxSection
    from rigidmd.config.sections import OutputsSection, StructureSection
    from rigidmd.config.splitsection import calculator_section
    from rigidmd.config.trust import check_output_paths
    from rigidmd.run.outputs import LOCK_NAME, OutputError, OutputLock, check_apart_from_inputs

    raw = dict(raw)
    base = Path(raw.pop("_base", "."))
    unknown = sorted(set(raw) - known_keys(), key=str)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown key; allowed: "
                          f"{', '.join(sorted(known_keys()))}")
    check_output_paths(raw, trust, base)
    structure = StructureSection.from_config(raw, base)
    calculator = calculator_section(raw, base)
    calculator.check_trust(trust)
    outputs = OutputsSection.from_config(raw, base)
    section = RelaxSection.from_config(raw, base) or RelaxSection()
    atoms = structure.build_atoms()  # every input is read before any output is touched
    bodies = structure.resolve_bodies(atoms)
    directory = outputs.directory
    section.check_paths(directory)
    # The calculator before any output is touched: the checks that need it (a cell
    # relaxation's stress, the constraints on the bodies) refuse here, never after an
    # earlier relaxation was replaced.  (An engine starts at the first force call.)
    atoms.calc = calculator.build(atoms, directory / "engine")
    section.check_structure(atoms)
    _check_relaxable(atoms, bodies, section)
    trajectory, log = directory / section.trajectory, directory / section.log
    state = state_path(trajectory)
    source = structure.source if isinstance(structure.source, Path) else None
    own = source is not None and source.resolve() == trajectory.resolve()
    if own and mode != "resume":
        raise ConfigError(f"structure: {source} is this relaxation's own trajectory; "
                          "continue it with --resume (or copy it elsewhere first)")
    check_apart_from_inputs({"relax.log": log, "relax state": state,
                             "the lock file": directory / LOCK_NAME},
                            {"configuration": config_path, "structure": source})
    directory.mkdir(parents=True, exist_ok=True)
    lock = OutputLock(directory)
    lock.acquire()
    try:
        done = 0
        if mode == "resume":
            done = continue_from(atoms, trajectory, state, stream)
        else:
            existing = [p for p in (trajectory, log, state) if p.exists()]
            if existing and mode != "overwrite":
                raise OutputError(f"relax: {existing[0]} holds an earlier relaxation; "
                                  "continue it with --resume or replace it with --overwrite")
            for path in existing:
                path.unlink()
        # Installed before the relaxation's own handlers and kept after them: a signal once
        # the relaxation has ended is noted, never a kill without a word (exit -15).
        after = StopSignals()
        after.shielded = True  # a second Ctrl-C then is only counted
        calc = atoms.calc
        try:
            with after:
                relax_structure(atoms, bodies, section, directory, stream,
                                resume=mode == "resume", done=done, stop=StopSignals(),
                                label=relaxation_label(calculator_digest(calculator),
                                                       section),
                                hint=resume_command(config_path or "CONFIG", directory,
                                                    ["--trust"] if trust else [],
                                                    command="relax"))
                calc = _close(calc)
                lock.release()
        except RelaxationStopped as stopped:
            return stopped.status
        finally:
            _close(calc)
        if after.signum is not None:
            print(f"relax: {signal.Signals(after.signum).name} arrived after the relaxation "
                  "had ended; it is complete and its outputs are whole", file=stream)
    finally:
        lock.release()
    return 0


def _check_relaxable(atoms, bodies, section):
    """What the relaxation's filter refuses (a constraint holding part of a body, a cell
    relaxation without stress), refused now, on a copy, before any output is touched."""
    from rigidmd.config.quantities import ConfigError
    from rigidmd.relax.filter import RigidFilter

    probe = atoms.copy()
    probe.calc = atoms.calc
    try:
        RigidFilter(probe, bodies, cell=section.cell, scalar_pressure=section.pressure)
    except ValueError as err:
        raise ConfigError(f"relax: {err}") from None


def _close(calc):
    """Close a calculator with a process of its own (``None``: closed already); None."""
    close = getattr(calc, "close", None)
    if callable(close):
        close()



def relax_for_export(config, atoms, bodies, directory, stream=sys.stdout):
    """Relax a run's start as ``rigidmd run`` would, for ``rigidmd export-lammps``.

    The configuration's ``relax:`` section relaxes ``atoms`` in place with its
    calculator (trajectory and log in ``directory``, beside the deck), and the
    velocities are drawn again for the relaxed bodies, as the run does, so
    that the deck starts from the structure the run's MD starts from.

    Parameters
    ----------
    config : rigidmd.config.RunConfig
        With a ``relax`` section.
    atoms : ase.Atoms
        The start (:meth:`rigidmd.run.runner.Run.start_atoms`); no calculator is left on it.
    bodies : rigidmd.RigidBodies
    directory : pathlib.Path
        The export directory.
    stream : file
    """
    from rigidmd.core.velocities import rigid_maxwell_boltzmann

    config.relax.check_paths(directory)
    atoms.calc = config.calculator.build(atoms, directory / "engine")
    try:
        config.relax.check_structure(atoms)  # before the directory is made
        _check_relaxable(atoms, bodies, config.relax)
        directory.mkdir(parents=True, exist_ok=True)
        relax_structure(atoms, bodies, config.relax, directory, stream,
                        hint="rigidmd export-lammps CONFIG DIRECTORY (it relaxes again)",
                        stop=StopSignals())
    finally:
        close = getattr(atoms.calc, "close", None)
        if callable(close):
            close()
        atoms.calc = None
    velocities = config.run.velocities
    if velocities is not None and config.structure.restart is None:
        rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                rng=np.random.default_rng(velocities["seed"]),
                                stationary=velocities.get("stationary", True))
