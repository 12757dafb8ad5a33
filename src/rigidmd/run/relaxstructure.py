"""Relaxing the structure of a run: the ``relax:`` section (the command: relaxcommand).

:func:`relax_structure` relaxes the rigid bodies (and the cell) of a run's
start with :func:`rigidmd.relax.filter.relax`, writing the optimizer's trajectory
(every step, so the last frame is the structure reached) and log in the
output directory.  It is a product path as ``rigidmd run`` is:

* **Progress** on stderr: step, energy, largest generalized force and
  elapsed time, in place on a terminal, a line every 10 steps or 30 s otherwise.
* **Signals**: SIGTERM, SIGINT (Ctrl-C) and SIGUSR1 finish the current
  step and its trajectory frame, then stop with exit status 143, 130 or 138
  and one line saying how to continue (:class:`RelaxationStopped`); a second
  Ctrl-C stops at once, without a traceback.
* **Resume**: ``rigidmd relax CONFIG --resume`` continues from the last frame
  of the relaxation's trajectory, appending to it and to its log, with the
  optimizer's memory (:func:`state_path`, written when a relaxation stops
  before converging): the continued relaxation takes the steps the
  uninterrupted one would have taken.  Without that file (a relaxation
  killed outright) the optimizer's memory starts afresh, and it says so.
* **Nothing read is lost**: the structure is read before any output is
  touched; an earlier relaxation's outputs are replaced only with
  ``--overwrite``, and never when the structure *is* that trajectory.

A relaxation that does not converge within its steps raises
:class:`RelaxationNotConverged`, one whose optimizer or calculator fails in a
step :class:`~rigidmd.relax.filter.RelaxationFailed` (or the calculator's
:class:`~rigidmd.core.forces.NonFiniteForceError`), each with one line naming
the trajectory and how to continue.
"""

import sys
import time

import numpy as np

from rigidmd.core.forces import NonFiniteForceError
from rigidmd.relax.filter import Relaxation, RelaxationFailed, RigidFilter, relax

__all__ = ["relax_structure", "RelaxationNotConverged", "RelaxationStopped", "RelaxProgress",
           "RelaxationFailed", "continue_from", "relaxation_label", "state_path"]


def state_path(trajectory):
    """Where a relaxation writing ``trajectory`` keeps its state when it stops early:
    ``relax.traj`` -> ``relax.state.npz`` (:mod:`rigidmd.relax.optimizerstate`)."""
    return trajectory.with_suffix(".state.npz")


class RelaxationNotConverged(RuntimeError):
    """A relaxation reached its step limit above ``fmax``."""


class RelaxationStopped(RuntimeError):
    """A stop signal ended a relaxation after a whole step; ``status`` is the exit status."""

    def __init__(self, message, status):
        super().__init__(message)
        self.status = status


class RelaxProgress:
    """Progress of a relaxation on ``stream``: in place on a terminal, else a line every 10
    steps or 30 s (step, energy, largest generalized force, elapsed time)."""

    def __init__(self, total, done=0, fmax=0.05, stream=None, width=20):
        self.total, self.done, self.fmax, self.width = int(total), int(done), fmax, width
        self.stream = sys.stderr if stream is None else stream
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = self.last = time.perf_counter()

    def __call__(self, step, energy, fmax):
        now = time.perf_counter()
        step = self.done + step
        # Progress toward fmax on a log scale: a bar that fills as the force falls.
        start = getattr(self, "first", None)
        if start is None:
            start = self.first = max(fmax, self.fmax * 1.0001)
        fraction = np.clip(np.log(start / max(fmax, 1e-300)) / np.log(start / self.fmax), 0, 1)
        line = (f"relax step {step:>{len(str(self.total))}}/{self.total}  energy "
                f"{energy:.6f} eV  fmax {fmax:.4f} eV/Å (target {self.fmax:g})  "
                f"{now - self.t0:.1f} s")
        if self.tty:
            bar = "#" * int(self.width * fraction)
            self.stream.write(f"\r[{bar:<{self.width}}] {line}")
        elif step % 10 == 0 or now - self.last > 30 or fmax < self.fmax:
            self.stream.write(line + "\n")
            self.last = now
        self.stream.flush()

    def finish(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def continue_from(atoms, trajectory, state_file=None, stream=None):
    """Put the last frame of a relaxation's ``trajectory`` into ``atoms``; steps it holds.

    A trajectory that cannot be read is continued from the positions of the
    relaxation's ``state_file`` when that is whole: the damaged file is kept
    beside it (``relax.damaged.traj``) and the continuation writes a new one.

    Parameters
    ----------
    atoms : ase.Atoms
        The configuration's structure (its atoms, bodies and calculator are kept).
    trajectory : pathlib.Path
    state_file : pathlib.Path, optional
        The relaxation's state (:func:`state_path`).
    stream : file, optional
        Told when the state's positions replace a damaged trajectory.

    Returns
    -------
    int
        Optimizer steps the trajectory records (frames less one).

    Raises
    ------
    rigidmd.config.quantities.ConfigError
        No trajectory, an unreadable or empty one, or one of other atoms.
    """
    from ase.io import read

    from rigidmd.config.quantities import ConfigError

    if not trajectory.is_file():
        raise ConfigError(f"--resume: no relaxation to continue ({trajectory} does not "
                          "exist); start one without --resume")
    try:
        frames = read(trajectory, index=":")
    except Exception as err:  # ASE raises many kinds on a damaged file  # noqa: BLE001
        reason = f"{type(err).__name__}: {' '.join(str(err).split())}"
        done = _from_state(atoms, trajectory, state_file, reason, stream)
        if done is None:
            raise ConfigError(f"--resume: cannot read {trajectory} ({reason})") from None
        return done
    if not frames:
        raise ConfigError(f"--resume: {trajectory} holds no frame; start again with "
                          "--overwrite")
    last = frames[-1]
    if len(last) != len(atoms) or np.any(last.numbers != atoms.numbers):
        raise ConfigError(f"--resume: {trajectory} holds {len(last)} atoms "
                          f"({last.get_chemical_formula()}), the configuration's structure "
                          f"{len(atoms)} ({atoms.get_chemical_formula()}); not its relaxation")
    atoms.set_cell(last.cell, scale_atoms=False)
    atoms.positions = last.positions
    return len(frames) - 1


def _from_state(atoms, trajectory, state_file, reason, stream):
    """Continue from the positions of a whole ``state_file`` of these atoms instead of a
    damaged ``trajectory``, which is kept under another name; steps taken, or None."""
    from rigidmd.relax.optimizerstate import read_state
    from rigidmd.run.outputs import OutputError, ulm_header

    if state_file is None:
        return None
    try:
        state = read_state(state_file)
    except ValueError:
        return None
    if state is None or state["positions"].shape != atoms.positions.shape:
        return None
    try:
        done = max(ulm_header(trajectory)[0] - 1, 0)  # the frames its header counts
    except (OSError, OutputError):
        done = 0
    aside, n = trajectory.with_name(f"{trajectory.stem}.damaged{trajectory.suffix}"), 1
    while aside.exists():
        n += 1
        aside = trajectory.with_name(f"{trajectory.stem}.damaged{n}{trajectory.suffix}")
    trajectory.rename(aside)
    atoms.set_cell(state["cell"], scale_atoms=False)
    atoms.positions = state["positions"]
    if stream is not None:
        print(f"relax: {trajectory} cannot be read ({reason}); it is kept as {aside.name}, and "
              f"the relaxation continues from the positions in {state_file} in a new "
              f"{trajectory.name}, whose steps count from 0 again", file=stream)
    return done


def relax_structure(atoms, bodies, section, directory, stream=sys.stdout, *, resume=False,
                    done=0, hint=None, progress=None, stop=None, label=None):
    """Relax ``atoms`` in place as ``section`` says; files go to ``directory``.

    Parameters
    ----------
    atoms : ase.Atoms
        With its calculator.
    bodies : rigidmd.RigidBodies
    section : rigidmd.config.relaxsection.RelaxSection
    directory : pathlib.Path
    stream : file
        Where the summary and the stop message go.
    resume : bool
        Append to the trajectory and log (a continued relaxation).
    done : int
        Steps already taken (a continued relaxation): ``section.steps`` counts them.
    hint : str, optional
        The command that continues this relaxation, for the messages.
    progress : file, optional
        Where progress goes (default stderr).
    stop : rigidmd.run.runner.StopSignals, optional
        Signal handling for the relaxation (installed around it; checked after
        every step).  Without it a signal does what it does outside rigidmd.
    label : str, optional
        What a continuation must share with the relaxation it continues (the
        calculator's digest, ``"calculator <digest>"``): recorded in the state
        file; a continuation with another is refused.

    Returns
    -------
    rigidmd.relax.filter.Relaxation

    Raises
    ------
    RelaxationNotConverged
        Not converged within ``section.steps`` (the trajectory holds the
        structure reached).
    RelaxationStopped
        A stop signal (after the step's frame; the message was printed).
    """
    from contextlib import nullcontext

    from rigidmd.core.bodies import store_bodies_in_tags

    directory.mkdir(parents=True, exist_ok=True)
    store_bodies_in_tags(atoms, bodies.body_ids)  # every frame carries the bodies
    trajectory = directory / section.trajectory
    log = directory / section.log
    left = max(section.steps - done, 0)
    state_file = state_path(trajectory)
    exact = False
    if resume:
        _check_label(state_file, label)
        exact, why = _can_continue_exactly(state_file, atoms, section.optimizer, label)
        if not exact and not state_file.exists():
            # No state: killed outright, or converged (its state removed).  The forces of
            # the last frame say which (one call, which the relaxation's first reuses).
            view = RigidFilter(atoms, bodies, cell=section.cell,
                               scalar_pressure=section.pressure)
            force = float(view.force_norms().max()) if len(view) else 0.0
            if force < section.fmax:  # the relaxation's own test (RigidFilter.converged)
                print(f"relax: the relaxation in {trajectory} is complete: it converged at "
                      f"step {done} (largest generalized force {force:.3g} eV/Å, below fmax "
                      f"{section.fmax:g}); nothing is left to do", file=stream)
                return Relaxation(True, 0, float(atoms.get_potential_energy()), force)
        print(f"continuing the relaxation of {trajectory} after step {done}", file=stream)
        said = (f"continuing with the optimizer's memory ({state_file})" if exact
                else f"the optimizer's memory starts afresh: {why}")
        print(f"relax: {said}", file=stream)
    elif state_file.exists():
        state_file.unlink()
    report = RelaxProgress(section.steps, done, section.fmax, progress)
    observers = (report,) if stop is None else (report, lambda *_: stop.check())
    continuing = hint or "rigidmd relax CONFIG --resume"
    status = 0
    # A trajectory rebuilt from the state file (the old one unreadable) starts anew with its
    # start frame, so its steps count from 0 again (a later --resume counts its frames).  A
    # continuation gives first_step even when it is 0 (a relaxation stopped at step 0: its log
    # has the header and step 0 already); None starts the log anew.
    first_step = done if resume and trajectory.exists() else None
    try:
        # Line-buffered: a relaxation killed outright keeps the log of every step its
        # trajectory has (block-buffered, the log of 103 steps was empty).
        with stop or nullcontext(), open(log, "a" if resume else "w", buffering=1,
                                         encoding="utf-8") as logfile:
            result = relax(atoms, bodies, fmax=section.fmax, steps=left,
                           optimizer=section.optimizer, cell=section.cell,
                           scalar_pressure=section.pressure, trajectory=str(trajectory),
                           logfile=logfile, append_trajectory=resume, observers=observers,
                           state_file=state_file, resume=exact, state_label=label,
                           first_step=first_step)
    except (RelaxationFailed, NonFiniteForceError) as err:  # the atoms are at a whole step
        raise type(err)(f"{err}, the last frame of {trajectory}; continue with: "
                        f"{continuing}") from None
    except OSError as err:  # a failed write: ASE's errors name no file
        from rigidmd.run.outputs import describe_os_error

        where = err.filename or _written_file(err, trajectory, log, state_file)
        raise RelaxationFailed(f"relax: {describe_os_error(err, where)}; continue with: "
                               f"{continuing} once it can be written") from None
    except Exception as err:
        signum = getattr(err, "signum", None)  # the stop's StopRequest, after a whole step
        if stop is None or signum is None:
            raise
        status, message = 128 + int(signum), f"stopped by {err}"
    except KeyboardInterrupt:
        status, message = 130, "interrupted at once (second Ctrl-C)"
    finally:
        report.finish()
    if status:
        text = (f"relax: {message}; the structure reached is the last frame of {trajectory}; "
                f"continue with: {continuing}")
        print(text, file=stream)
        raise RelaxationStopped(text, status)
    cell = f", cell {section.cell}" if section.cell else ""
    if not result.converged:
        raise RelaxationNotConverged(
            f"relax: {section.optimizer} did not reach fmax {section.fmax:g} eV/Å in "
            f"{section.steps} steps (largest generalized force {result.fmax:.3g} eV/Å); the "
            f"structure reached is the last frame of {trajectory}; raise relax.steps and "
            f"continue with: {continuing}")
    print(f"relaxed {bodies} ({section.optimizer}{cell}) in {done + result.steps} steps to "
          f"fmax {result.fmax:.3g} eV/Å, energy {result.energy:.6f} eV; wrote {trajectory} and "
          f"{log}", file=stream)
    return result


def _written_file(err, trajectory, log, state_file):
    """The file a write error without a file name came from, by where it was raised: ASE's
    trajectory writer, the state file's writer, else the optimizer's log."""
    frames = []
    tb = err.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame.f_code.co_filename.replace("\\", "/"))
        tb = tb.tb_next
    if any("/ase/io/" in name for name in frames):
        return trajectory
    if any(name.endswith(("/rigidmd/relax/optimizerstate.py", "/rigidmd/core/checkpoint.py"))
           for name in frames):
        return state_file
    return log


def relaxation_label(digest, section):
    """What a continued ``rigidmd relax`` must share with the relaxation it continues: the
    calculator (its digest) and the surface it descends (``relax.cell``, and
    ``relax.pressure`` when the cell moves), as ``"calculator D; relax.cell C; ..."``.
    ``relax.fmax``, ``relax.steps`` and ``relax.optimizer`` may change (a tighter fmax
    continues; another optimizer starts its memory afresh, and says so)."""
    parts = [f"calculator {digest}", f"relax.cell {section.cell}"]
    if section.cell:
        parts.append(f"relax.pressure {section.pressure!r}")
    return "; ".join(parts)


def _label_fields(label):
    """``{"calculator": D, "relax.cell": C, ...}`` from :func:`relaxation_label`'s text (a
    state of an earlier release records the calculator only)."""
    return dict(part.partition(" ")[::2] for part in str(label).split("; "))


def _check_label(state_file, label):
    """Refuse to continue a relaxation whose state file records another ``label`` (another
    calculator, cell or pressure): its frames and the new ones would be of two surfaces."""
    from rigidmd.config.quantities import ConfigError
    from rigidmd.relax.optimizerstate import read_state

    if label is None:
        return
    try:
        state = read_state(state_file)
    except ValueError:
        return  # a damaged state: the memory starts afresh, and says why
    recorded = None if state is None else state.get("label")
    if recorded is None:
        return
    before, now = _label_fields(recorded), _label_fields(label)
    for field, value in now.items():
        if field in before and before[field] != value:
            raise ConfigError(f"--resume: the {field} differs from the relaxation's "
                              f"({state_file} records {field} {before[field]}, the "
                              f"configuration gives {field} {value}); restore it, or start "
                              "anew with --overwrite")


def _can_continue_exactly(state_file, atoms, optimizer, label=None):
    """``(True, "")`` when ``state_file`` holds the state of the last frame, else (False, why)."""
    from rigidmd.relax.filter import optimizer_class
    from rigidmd.relax.optimizerstate import keeps_memory, read_state, state_matches

    if not keeps_memory(optimizer_class(optimizer)):
        return False, f"{optimizer} keeps no memory that can be saved"
    try:
        state = read_state(state_file)
    except ValueError as err:
        return False, str(err)
    if state is None:
        return False, f"no {state_file} (the relaxation was not stopped by a signal or its steps)"
    differs = state_matches(state, atoms, optimizer, label)
    return (False, f"{state_file}: {differs}") if differs else (True, "")
