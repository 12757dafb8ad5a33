"""A run of the ``rigidmd`` command: outputs that never mix or break, checkpoints, signals.

* **One run per directory.**  A lock file refuses a second run into a
  directory in use (a lock left by a dead process is taken over).  A new run
  into a directory that already holds outputs is refused unless
  ``--overwrite`` (which removes them) or ``--resume`` is given.  Every input
  (structure, restart trajectory, checkpoint) is read and the dynamics is
  checked before any output is removed.
* **Checkpoints** every ``outputs.checkpoint_interval`` steps and at every
  clean stop: every output file is flushed to disk first and its length is
  recorded in the checkpoint (written atomically), with a digest of each
  configuration field that defines the trajectory (:func:`fingerprint`).
* **Resume** (``--resume``): the configuration is compared field by field
  (a changed field is named), temporary files of a killed checkpoint write
  are removed, every output is cut back to its length at the checkpoint
  (which also removes a truncated last frame after ``kill -9``), the
  dynamics is rebuilt from the checkpoint and the outputs are appended to;
  the finished files equal those of an uninterrupted run byte for byte.  A
  checkpoint at step 0 starts the run again from its configuration.
* **Signals**: SIGTERM (what batch schedulers send), SIGINT (Ctrl-C) and
  SIGUSR1 finish the current step and its outputs, write a checkpoint, close
  the files and exit with 143, 130 or 138, printing the exact command that
  resumes (:func:`resume_command`).  A second Ctrl-C during the steps stops at
  once without a checkpoint (the outputs may end mid-step); ``--resume``
  continues from the last one.  Once the steps have stopped, further signals
  are noted, not obeyed: the final checkpoint is always written whole.
* **Failures after the start** (a full disk, a step that fails) raise
  :class:`RunStopped`: one line naming the file or the reason, the step and
  the last checkpoint, which stays intact (status 1).
* **A run that never started** (its first force call fails: a LAMMPS input
  mistake, ...) removes the outputs it had opened, so the corrected
  configuration starts without ``--overwrite``.
"""

import os
import signal
import sys
import time

import numpy as np
from ase import units

from rigidmd.config import TIME_UNITS, ConfigError
from rigidmd.core.dof import temperature
from rigidmd.ipi import EngineError, add_wait_check, remove_wait_check
from rigidmd.run.fingerprint import (
    differing_fields,
    earlier_release_differences,
    fingerprint,
    resume_command,
)
from rigidmd.run.outputs import (
    OutputError,
    OutputLock,
    describe_os_error,
    output_lengths,
    trim_outputs,
)

__all__ = ["Run", "RunStopped", "Progress", "StopSignals", "StopRequest", "fingerprint",
           "resume_command"]

#: Exit status of a run stopped by each signal (128 + signal number).
EXIT_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGUSR1: 138}


class StopRequest(Exception):
    """A stop signal arrived; raised after the current step's outputs were written."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class StopSignals:
    """Turn SIGTERM, SIGINT and SIGUSR1 into a :class:`StopRequest` between steps.

    :meth:`check` is attached as the last observer, so a stop comes after
    every output of the step.  A second SIGINT raises ``KeyboardInterrupt``
    at once, unless :attr:`shielded` (set while the final checkpoint is
    written): then it is only counted in :attr:`ignored`.
    """

    modifies_atoms = False

    def __init__(self):
        self.signum = None
        self.shielded = False
        self.ignored = 0
        self._previous = {}

    def _handler(self, signum, frame):
        if self.signum is None:
            self.signum = signum
        elif self.shielded:
            self.ignored += 1
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt

    def check(self):
        if self.signum is not None:
            self.shielded = True  # from here on the run only writes what it has
            raise StopRequest(self.signum)

    def __enter__(self):
        for signum in EXIT_STATUS:
            self._previous[signum] = signal.signal(signum, self._handler)
        add_wait_check(self.check)  # a stop also ends a wait for an i-PI engine (<= 0.1 s)
        return self

    def __exit__(self, *exc):
        remove_wait_check(self.check)
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False


def time_left(steps, rate):
    """``"  12m05s left"`` for ``steps`` more at ``rate`` steps per second; empty when unknown."""
    if steps <= 0 or not rate > 0:
        return ""
    seconds = int(round(steps / rate))
    hours, rest = divmod(seconds, 3600)
    text = f"{hours}h{rest // 60:02d}m" if hours else f"{rest // 60}m{rest % 60:02d}s"
    return f"  {text} left"


class Progress:
    """A progress line on stderr: in place on a terminal, else every 1 % or 30 s."""

    modifies_atoms = False

    def __init__(self, dyn, total, stream=None, width=30):
        self.dyn, self.total, self.width = dyn, max(int(total), 1), width
        self.stream = sys.stderr if stream is None else stream
        self.start_step = dyn.nsteps
        self.t0 = self.last = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.next_report = 0.01

    def __call__(self):
        done = self.dyn.nsteps - self.start_step
        fraction = done / self.total
        now = time.perf_counter()
        rate = done / (now - self.t0) if now > self.t0 else 0.0
        bar = "#" * int(self.width * fraction)
        line = (f"[{bar:<{self.width}}] {done:>{len(str(self.total))}}/{self.total} steps "
                f"{rate:8.1f} steps/s  T {temperature(self.dyn.atoms):7.1f} K"
                f"{time_left(self.total - done, rate)}")
        if self.tty:
            self.stream.write("\r" + line + ("\n" if done >= self.total else ""))
        elif fraction + 1e-12 >= self.next_report or done >= self.total or now - self.last > 30:
            self.stream.write(line + "\n")
            self.next_report = np.floor(fraction * 100 + 1) / 100
            self.last = now
        self.stream.flush()


class RunStopped(RuntimeError):
    """The run stopped after it started (a failed write, a failure in a step); one line."""


def _observables(dyn):
    """Time, conserved energy and, under a barostat, pressure (bar), volume, density."""
    row = (dyn.get_time(), dyn.get_conserved_energy())
    if dyn.evaluator.cell_moves:
        # A Monte Carlo barostat runs with calculators that have no stress: no pressure then.
        stress = "stress" in getattr(dyn.atoms.calc, "implemented_properties", ("stress",))
        pressure = dyn.get_pressure() / units.bar if stress else np.nan
        row += (pressure, dyn.get_volume(), dyn.get_density())
    return row


class _NamedOutput:
    """An output observer whose write errors name its file (ASE's carry no file name)."""

    modifies_atoms = False

    def __init__(self, function, path):
        self.function, self.path = function, path

    def __call__(self, *args, **kwargs):
        try:
            return self.function(*args, **kwargs)
        except OSError as err:
            if err.filename is None:
                raise type(err)(err.errno, err.strerror or str(err), str(self.path)) from None
            raise


class Run:
    """One ``rigidmd run`` (or ``demo``) of a checked configuration.

    Everything the run reads (the structure or restart file, the checkpoint)
    is read, and the calculator and the dynamics are checked, before any
    output is removed or written.

    Parameters
    ----------
    config : rigidmd.config.RunConfig
    mode : {"new", "resume", "overwrite", "demo"}
        ``"demo"`` replaces an earlier demo's outputs in the directory, saying
        so, and refuses to touch any other run's.
    config_path : str, optional
        The configuration file, for the resume hint.
    stream : file, optional
        Where messages go (default: standard output at construction).
    resume_hint : str, optional
        The command that resumes this run (the command line builds it with
        :func:`resume_command` from its flags); default: the configuration
        file with ``--outdir`` and ``--resume``.
    """

    def __init__(self, config, mode="new", config_path=None, stream=None, resume_hint=None):
        self.config, self.mode = config, mode
        self.stream = sys.stdout if stream is None else stream
        self.config_path = config_path
        self.resume_hint = resume_hint
        self.created = []  # output files this run created before its first checkpoint
        self.outputs = config.outputs
        self.checkpoint_step = None  # step of the last checkpoint on disk, once known
        self._fingerprint = None

    @property
    def fingerprint(self):
        """:func:`fingerprint` of the configuration, taken once (files are read once)."""
        if self._fingerprint is None:
            self._fingerprint = fingerprint(self.config)
        return self._fingerprint

    # ------------------------------------------------------------ outputs
    def _appended_files(self):
        """The files a run appends to (trimmed on resume)."""
        out = self.outputs
        return {name: path for name, path in (("trajectory", out.trajectory), ("log", out.log),
                                              ("mdanalysis", out.mdanalysis)) if path}

    def _all_files(self):
        files = list(self._appended_files().values())
        if self.outputs.mdanalysis is not None:
            files.append(self.outputs.mdanalysis.with_suffix(".psf"))
        files += [p for p in (self.outputs.plot, self.outputs.checkpoint) if p]
        return files

    def _resume_hint(self):
        if self.resume_hint is not None:
            return self.resume_hint
        return resume_command(self.config_path or "CONFIG", self.outputs.directory)

    def _fresh_start_advice(self):
        """How to go on without the checkpoint: keeping the outputs first, then removing them."""
        trajectory = self.outputs.trajectory
        keep = ""
        if trajectory is not None and trajectory.exists():
            keep = (f"start a new run from its last frame with --restart {trajectory} "
                    "--outdir NEW_DIRECTORY (which keeps these outputs), or ")
        return f"{keep}start it again with --overwrite (which removes them)"

    def _remove_unstarted_outputs(self):
        """Remove the outputs of a new run that failed before its first checkpoint.

        Such a run never started: what it opened (a log header, an empty
        trajectory) would only block the corrected configuration.  Returns the
        names removed.
        """
        if self.checkpoint_step is not None or not self.created:
            return []
        removed = []
        for path in self.created:
            if path.exists():
                path.unlink()
                removed.append(path.name)
        return removed

    def _is_earlier_demo(self):
        """The checkpoint in the directory is a demo's (same fingerprint, any steps)."""
        from rigidmd.run.checkpoint import CheckpointError, read_checkpoint

        try:
            checkpoint = read_checkpoint(self.outputs.checkpoint)
        except CheckpointError:
            return False
        return checkpoint.extra.get("fingerprint") == self.fingerprint

    def _prepare_directory(self, replace=False):
        from rigidmd.run.checkpoint import remove_stale_temporaries

        existing = [p for p in self._all_files() if p.exists()]
        names = ", ".join(p.name for p in existing)
        if self.mode == "new" and existing:
            raise ConfigError(
                f"outputs: {self.outputs.directory} already holds {names} from an earlier run; "
                "continue it with --resume, or replace it with --overwrite")
        if self.mode == "demo" and existing and not self._is_earlier_demo():
            raise ConfigError(
                f"outputs: {self.outputs.directory} holds {names}, which are not an earlier "
                "demo's; give the demo another --outdir")
        # No other run writes here (the lock is ours): a temporary file is a killed write's.
        stale = remove_stale_temporaries(self.outputs.checkpoint)
        if stale:
            print(f"removed {', '.join(stale)}, left by a checkpoint write that was killed",
                  file=self.stream)
        if (self.mode == "resume" and not replace) or not existing:
            return
        verb = "replacing the earlier demo's" if self.mode == "demo" else "removing"
        print(f"{verb} {names} in {self.outputs.directory}", file=self.stream)
        for path in existing:
            path.unlink()

    # ------------------------------------------------------------ set-up
    def start_atoms(self):
        """The configuration's structure, its bodies, and its velocities if it draws any.

        Returns
        -------
        atoms : ase.Atoms
        bodies : rigidmd.RigidBodies
        """
        config = self.config
        atoms = config.structure.build_atoms()
        bodies = config.structure.resolve_bodies(atoms)
        self._draw_velocities(atoms, bodies)
        return atoms, bodies

    def _draw_velocities(self, atoms, bodies):
        from rigidmd import rigid_maxwell_boltzmann

        velocities = self.config.run.velocities
        if velocities is not None and self.config.structure.restart is None:
            rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                    rng=np.random.default_rng(velocities["seed"]))

    def _dynamics_arguments(self):
        return dict(integrator=self.config.run.integrator,
                    integrator_options=self.config.run.integrator_options)

    def _new_dynamics(self, replace=False):
        """Read the inputs and check the dynamics on a copy; build it after the outputs' turn.

        ``replace``: remove the directory's outputs (a resume from step 0).  A
        ``relax:`` section relaxes the structure after that (relaxing is not
        reading an input: it writes its own trajectory and log), and the
        velocities are drawn again for the relaxed bodies.
        """
        import warnings

        from rigidmd.core.dynamics import RigidDynamics

        atoms, bodies = self.start_atoms()
        atoms.calc = self.config.calculator.build(atoms, self.outputs.directory / "engine")
        probe = atoms.copy()
        probe.calc = atoms.calc
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the real construction below warns, once
            RigidDynamics(probe, self.config.run.timestep, bodies=bodies,
                          couplings=self.config.coupling.parts(), **self._dynamics_arguments())
        self._prepare_directory(replace)
        if self.config.relax is not None:  # (a restart with relax: is refused by the config)
            from rigidmd.relax.structure import relax_structure

            relax_structure(atoms, bodies, self.config.relax, self.outputs.directory,
                            self.stream, hint=f"rigidmd run {self.config_path or 'CONFIG'} "
                            "--overwrite (it relaxes again from the structure)",
                            stop=StopSignals())
            self._draw_velocities(atoms, bodies)
        out = self.outputs
        # Nothing of this run's is in the directory now: what appears is this run's.
        self.created = [p for p in self._all_files() if not p.exists()]
        return RigidDynamics(atoms, self.config.run.timestep, bodies=bodies,
                             couplings=self.config.coupling.parts(),
                             trajectory=str(out.trajectory) if out.trajectory else None,
                             logfile=str(out.log) if out.log else None,
                             loginterval=out.interval, **self._dynamics_arguments())

    def _read_checkpoint(self):
        from rigidmd.run.checkpoint import CheckpointError, read_checkpoint

        out = self.outputs
        if not out.checkpoint.exists():
            others = [p.name for p in self._all_files() if p.exists()]
            if others:
                raise ConfigError(
                    f"--resume: there is no checkpoint {out.checkpoint} beside "
                    f"{', '.join(others)}, so that run cannot be continued; start it again "
                    "with --overwrite")
            raise ConfigError(f"--resume: there is no run to continue in {out.directory} (no "
                              f"{out.checkpoint.name}); start one without --resume")
        try:
            checkpoint = read_checkpoint(out.checkpoint)
        except CheckpointError as err:
            raise ConfigError(f"--resume: {err}; the run cannot be continued from it: "
                              f"{self._fresh_start_advice()}") from None
        differing = differing_fields(checkpoint.extra.get("fingerprint"), self.fingerprint)
        if differing is None:
            differing = earlier_release_differences(self.config, checkpoint)
            if not differing:
                print("the checkpoint was written by an earlier rigidmd, which recorded the "
                      "configuration as one digest: its atoms, timestep, integrator and "
                      "thermostat/barostat were compared with the configuration and agree; "
                      "the calculator and outputs.interval cannot be compared (keep them as "
                      "they were)", file=self.stream)
        if differing:
            raise ConfigError(
                f"--resume: {', '.join(differing)} differ{'s' if len(differing) == 1 else ''} "
                "from the checkpoint's run (only steps may change between a run and its "
                "continuation); restore it, or start anew with --overwrite")
        return checkpoint

    def _resumed_dynamics(self):
        from rigidmd.run.logger import RigidLogger
        from rigidmd.run.restart import load_checkpoint

        out = self.outputs
        checkpoint = self._read_checkpoint()
        if checkpoint.nsteps == 0:
            # Killed before its first interval checkpoint: the step-0 checkpoint holds the
            # configuration's start, so the run starts again (writing step 0 once).
            print(f"the checkpoint {out.checkpoint.name} is at step 0: starting the run again",
                  file=self.stream)
            return self._new_dynamics(replace=True)
        calc = self.config.calculator.build(checkpoint.atoms(), out.directory / "engine")
        self._prepare_directory()
        trimmed = trim_outputs(self._appended_files(), checkpoint.extra.get("outputs", {}))
        self.checkpoint_step = checkpoint.nsteps
        dyn = load_checkpoint(checkpoint, calc,
                              trajectory=str(out.trajectory) if out.trajectory else None,
                              append_trajectory=True, loginterval=out.interval)
        if out.log:
            dyn.attach(dyn.closelater(RigidLogger(dyn, str(out.log), pressure=dyn.evaluator.stress,
                                                  header=False)), out.interval)
        cut = f" (cut back: {', '.join(trimmed)})" if trimmed else ""
        print(f"resuming from step {dyn.nsteps} of {out.checkpoint}{cut}", file=self.stream)
        return dyn

    # ------------------------------------------------------------ checkpoints
    def _checkpoint(self, dyn, writer):
        if writer is not None:
            writer.flush()
        extra = {"outputs": output_lengths(self._appended_files()),
                 "fingerprint": self.fingerprint, "steps": self.config.run.steps}
        dyn.save_checkpoint(self.outputs.checkpoint, extra=extra)
        self.checkpoint_step = dyn.nsteps

    def _checkpoint_undone_step(self, dyn, writer):
        """Checkpoint after a step an engine failed in: the stepper undid that step, and
        the steps before it, outputs included, are whole (``--resume`` starts there)."""
        try:
            self._checkpoint(dyn, writer)
        except OSError:
            pass  # the last checkpoint stays, and the message names it

    def _name_outputs(self, dyn):
        """Wrap the trajectory and log observers so that their write errors name the file.

        Called before the run attaches its own observers: the dynamics has only
        these two (ASE's trajectory writer, an ``MDLogger``) then.
        """
        from ase.md.logger import MDLogger

        named = []
        for function, interval, args, kwargs in dyn.observers:
            owner = getattr(function, "__self__", function)
            path = self.outputs.log if isinstance(owner, MDLogger) else self.outputs.trajectory
            named.append((_NamedOutput(function, path), interval, args, kwargs))
        dyn.observers[:] = named

    # ------------------------------------------------------------ the run
    def execute(self):
        """Run; returns the exit status (0, or 130/143/138 after a stop signal)."""
        out = self.outputs
        created = not out.directory.exists()
        try:
            out.directory.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"outputs.directory: cannot create {out.directory} "
                              f"({describe_os_error(err).split(': ', 1)[-1]})") from None
        lock = OutputLock(out.directory)
        try:
            lock.acquire()
        except OSError as err:
            reason = describe_os_error(err).rsplit(": ", 1)[-1]
            raise OutputError(f"outputs.directory: cannot write in {out.directory} "
                              f"({reason})") from None
        if lock.stale:
            print(f"taking over the lock left by process {lock.stale.get('pid')}, which is gone",
                  file=self.stream)
        try:
            return self._execute()
        except BaseException:
            removed = self._remove_unstarted_outputs()
            if removed:
                print(f"the run did not start: removed {', '.join(removed)}, which it had "
                      "opened", file=self.stream)
            lock.release()
            if created:  # a run that could not start leaves no empty directory behind
                try:
                    out.directory.rmdir()
                except OSError:
                    pass  # it holds outputs: the run had started
            raise
        finally:
            lock.release()

    def _set_up(self):
        """The dynamics, ready to run; nothing has run yet (errors are the set-up's)."""
        try:
            return self._resumed_dynamics() if self.mode == "resume" else self._new_dynamics()
        except OSError as err:
            raise OutputError(describe_os_error(err)) from None

    def _stopped(self, dyn, reason):
        if self.checkpoint_step is None:
            where = "no checkpoint was written"
        else:
            where = (f"the last checkpoint is intact (step {self.checkpoint_step}): continue "
                     f"with {self._resume_hint()}")
        return RunStopped(f"{reason} (at step {dyn.nsteps}); {where}")

    def _execute(self):
        dyn = self._set_up()
        stop = StopSignals()
        # The handlers stay until the calculator is closed: a signal after the steps is noted,
        # never a KeyboardInterrupt in the final checkpoint's write or the engine's shutdown.
        with stop:
            try:
                return self._drive(dyn, stop)
            finally:
                # A calculator with a process of its own (LAMMPSEngine) stops with the run.
                close = getattr(dyn.atoms.calc, "close", None)
                if callable(close):
                    close()

    def _drive(self, dyn, stop):
        out, config = self.outputs, self.config
        total = config.run.steps
        remaining = total - dyn.nsteps
        if remaining <= 0:
            print(f"the run is complete ({dyn.nsteps} of {total} steps); raise steps to go on",
                  file=self.stream)
            return 0
        self._name_outputs(dyn)
        rows = []
        dyn.attach(lambda: rows.append(_observables(dyn)), interval=out.interval)
        writer = None
        if out.mdanalysis is not None:
            from rigidmd.mdanalysis import MDAWriter

            writer = MDAWriter(dyn, out.mdanalysis, append=dyn.nsteps > 0)
            dyn.attach(_NamedOutput(writer, out.mdanalysis), interval=out.interval)
        dyn.attach(Progress(dyn, remaining), interval=max(1, remaining // 1000))
        dyn.attach(lambda: self._checkpoint(dyn, writer), interval=out.checkpoint_interval)
        dyn.attach(stop.check, interval=1)  # last: after every output of the step
        print(f"{dyn.bodies} with {dyn.scheme.name} integrator, {describe(dyn)}, "
              f"steps {dyn.nsteps + 1}-{total} of {config.run.timestep / TIME_UNITS['fs']:g} fs",
              file=self.stream)
        t0 = time.perf_counter()
        status, at_once = self._steps(dyn, remaining, writer)
        # The steps are over: a signal now is noted, not obeyed, until the run has written
        # everything (a KeyboardInterrupt inside the checkpoint's write would lose it).
        stop.shielded = True
        if at_once:
            return status  # a second Ctrl-C stopped the steps at once
        return self._finish(dyn, status, stop, rows, t0)

    def _finish(self, dyn, status, stop, rows, t0):
        """The final checkpoint, the summary and the plot; the exit status."""
        out = self.outputs
        try:
            self._checkpoint(dyn, None)
        except OSError as err:
            raise self._stopped(dyn, describe_os_error(err)) from None
        if stop.signum is not None and not status:  # a signal during the final checkpoint
            status = EXIT_STATUS[stop.signum]
        if stop.ignored:
            print(f"\n(a further {signal.Signals(stop.signum).name} arrived while the final "
                  "checkpoint was written; it was finished first)", file=self.stream)
        if status:
            print(f"checkpoint {out.checkpoint} written; continue with: {self._resume_hint()}",
                  file=self.stream)
        summary(dyn, rows, time.perf_counter() - t0, self.stream)
        if out.plot is not None and out.log is not None and not status:
            from rigidmd.run.logplot import plot_log

            try:
                plot_log(out.log, out.plot)
            except OSError as err:
                raise self._stopped(dyn, describe_os_error(err)) from None
        for path in out.files.values():
            print(f"wrote {path}", file=self.stream)
        return status

    def _steps(self, dyn, remaining, writer):
        """Run the steps: (exit status, whether a second Ctrl-C stopped them at once)."""
        status = 0
        interrupted = False
        try:
            dyn.run(remaining)
        except StopRequest as request:
            status = EXIT_STATUS[request.signum]
            print(f"\nstopped by {request} after step {dyn.nsteps}", file=self.stream)
        except KeyboardInterrupt:
            # A second Ctrl-C: anywhere in a step or between one output and the next.  The
            # outputs may end mid-step, so no checkpoint records them; --resume cuts them
            # back to the last checkpoint.
            status, interrupted = 130, True
        except (OSError, ValueError, ArithmeticError, RuntimeError) as err:
            if os.environ.get("RIGIDMD_DEBUG") or getattr(err, "setup", False):
                raise  # a LammpsError of the set-up (the input's fault) is the command's
            reason = describe_os_error(err) if isinstance(err, OSError) else \
                " ".join(str(err).split()) or type(err).__name__
            if isinstance(err, EngineError) and dyn.nsteps > self.config.run.steps - remaining:
                self._checkpoint_undone_step(dyn, writer)
            raise self._stopped(dyn, reason) from None
        finally:
            if writer is not None:
                writer.close()
        if interrupted:
            if self.checkpoint_step is None:
                print("\ninterrupted at once (second Ctrl-C) before any checkpoint; start "
                      "again with --overwrite", file=self.stream)
            else:
                print(f"\ninterrupted at once (second Ctrl-C) near step {dyn.nsteps}; the "
                      f"checkpoint of step {self.checkpoint_step} is kept: {self._resume_hint()} "
                      "continues from it (cutting back the outputs written after it)",
                      file=self.stream)
        return status, interrupted


def describe(dyn):
    """What the run is, in words: NVE, or its coupling parts."""
    parts = []
    for part in dyn.couplings:
        text = f"{part.kind} {part.section}"
        if hasattr(part, "pressure_au"):
            text += f" at {part.pressure_au / units.bar:g} bar ({part.couple})"
        elif hasattr(part, "temperature_K"):
            text += f" at {part.temperature_K:g} K"
        parts.append(text)
    return ", ".join(parts) or "NVE"


def summary(dyn, rows, elapsed, stream):
    """Steps, speed, temperature, energy drift and (NPT) mean pressure, volume, density."""
    label = "conserved energy" if dyn.couplings else "total energy"
    print(f"{dyn.nsteps} steps ({elapsed:.1f} s for this run); "
          f"T = {temperature(dyn.atoms):.1f} K ({dyn.degrees_of_freedom} degrees of "
          "freedom)", file=stream)
    for part in dyn.couplings:  # a part that reports on itself (the Monte Carlo barostat)
        report = getattr(part, "report", None)
        if callable(report):
            print(report(), file=stream)
    if len(rows) >= 3:
        data = np.array(rows)
        t_ps, e = data[:, 0] / TIME_UNITS["ps"], data[:, 1]
        drift = np.polyfit(t_ps, e, 1)[0]
        print(f"{label}: drift {drift:+.2e} eV/ps, max |E - E0| {np.abs(e - e[0]).max():.2e} eV",
              file=stream)
        if data.shape[1] > 2:
            pressure, volume, density = data[:, 2:].T
            mean_p = "" if np.isnan(pressure).all() else f"mean P = {pressure.mean():.1f} bar, "
            print(f"{mean_p}V = {volume.mean():.1f} Å³, "
                  f"density = {density.mean():.4f} g/cm³ (final {density[-1]:.4f})",
                  file=stream)

