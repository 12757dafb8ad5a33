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
* **A relaxation first** (``relax:``): stopped by a signal or short of its
  steps, it leaves a checkpoint at step 0 that says so; ``--resume``
  continues the relaxation from the last frame of its trajectory, then runs
  the MD.
* **Failures after the start** (a full disk, a step that fails) raise
  :class:`RunStopped`: one line naming the file or the reason, the step and
  the last checkpoint, which stays intact (status 1).
* **A run that never started** (its first force call fails: a LAMMPS input
  mistake, ...) removes the outputs it had opened, so the corrected
  configuration starts without ``--overwrite``.
"""

import os
import shlex
import signal
import sys
import time
from pathlib import Path

import numpy as np

from rigidmd.config import TIME_UNITS, ConfigError
from rigidmd.config.diagnostics import own_calculator
from rigidmd.ipi import EngineError
from rigidmd.run.checkpointing import RunCheckpoints
from rigidmd.run.directory import NamedOutput, RunFiles
from rigidmd.run.fingerprint import fingerprint, resume_command
from rigidmd.run.outputs import (
    OutputError,
    check_apart_from_inputs,
    describe_os_error,
    trim_outputs,
)
from rigidmd.run.report import Progress, describe, observables, summary
from rigidmd.run.signals import EXIT_STATUS, StopRequest, StopSignals

__all__ = ["Run", "RunStopped", "Progress", "StopSignals", "StopRequest", "fingerprint",
           "resume_command"]


class RunStopped(RuntimeError):
    """The run stopped after it started (a failed write, a failure in a step); one line."""


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
        self.outputs = config.outputs
        self.files = RunFiles(self.outputs, mode, self.stream, config.relax)
        self.checkpoints = RunCheckpoints(config, self.files, self.stream)
        self.diagnostics = []  # attached with the outputs (config.diagnostics)
        self._after_relax = None  # the stop signals between the relaxation and the MD

    @property
    def fingerprint(self):
        """:func:`fingerprint` of the configuration, taken once (files are read once)."""
        return self.checkpoints.fingerprint

    @property
    def checkpoint_step(self):
        """Step of the last checkpoint on disk, once known (else None)."""
        return self.checkpoints.step

    def _resume_hint(self):
        if self.resume_hint is not None:
            return self.resume_hint
        if self.mode == "demo":  # no configuration to continue: the demo starts again
            return (shlex.join(["rigidmd", "demo", "--outdir",
                                str(Path(self.outputs.directory).resolve())])
                    + " (a demo is not continued: it starts again)")
        return resume_command(self.config_path or "CONFIG", self.outputs.directory)

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
        source = config.structure.source
        if isinstance(source, dict) and config.relax is None and \
                config.structure.restart is None and self.mode != "demo":  # (the demo says so)
            # A lattice: 64 TIP3P waters went from 300 to 1,130 K in 20 fs under NPT, unsaid.
            print(f"structure: the built-in {source['builtin']} is a lattice, not relaxed: its "
                  "potential energy turns into heat in the first steps (hundreds of kelvin); "
                  "add relax: {fmax: 0.05, optimizer: FIRE} to start from the model's minimum",
                  file=self.stream)
        self._draw_velocities(atoms, bodies)
        return atoms, bodies

    def _draw_velocities(self, atoms, bodies):
        from rigidmd.core.velocities import rigid_maxwell_boltzmann

        velocities = self.config.run.velocities
        structure = self.config.structure
        if structure.restart is not None:
            file_options = isinstance(structure.source, Path) and bool(structure.read_options)
            unused = [name for name, given in (("structure:", structure.source is not None),
                                               ("read_options:", file_options),
                                               ("velocities:", velocities is not None)) if given]
            if unused:  # said, not silent: the restart's frame is the start
                listed = " and ".join([", ".join(unused[:-1]), unused[-1]] if len(unused) > 2
                                      else unused)
                print(f"restart: the run starts from the last frame of {structure.restart.name}, "
                      f"its positions and momenta; {listed} not used", file=self.stream)
            return
        if velocities is not None:
            rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                    rng=np.random.default_rng(velocities["seed"]),
                                    stationary=velocities.get("stationary", True))

    def _dynamics_arguments(self):
        return dict(integrator=self.config.run.integrator,
                    integrator_options=self.config.run.integrator_options)

    def _new_dynamics(self, replace=False, relaxation=False):
        """Read the inputs and check the dynamics on a copy; build it after the outputs' turn.

        ``replace``: remove the directory's outputs (a resume from step 0).  A
        ``relax:`` section relaxes the structure after that (relaxing is not
        reading an input: it writes its own trajectory and log), and the
        velocities are drawn again for the relaxed bodies.  ``relaxation``: a
        relaxation stopped earlier (its checkpoint says so) is continued from
        the last frame of its trajectory, which is kept, as its log is.
        """
        import warnings

        from rigidmd.core.dynamics import RigidDynamics

        atoms, bodies = self.start_atoms()
        self.config.coupling.check_structure(atoms)  # (before a calculator is started)
        atoms.calc = self.config.calculator.build(atoms, self.outputs.directory / "engine")
        self.config.coupling.check_calculator(atoms.calc, self.config.calculator.name)
        if self.config.relax is not None:  # what it cannot relax, before anything is written
            self.config.relax.check_structure(atoms)
        probe = atoms.copy()
        probe.calc = atoms.calc
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the real construction below warns, once
            start = RigidDynamics(probe, self.config.run.timestep, bodies=bodies,
                                  couplings=self.config.coupling.parts(),
                                  **self._dynamics_arguments())
        if self.outputs.mdanalysis is not None:  # (it was refused after the log was opened)
            from rigidmd.mdanalysis.topology import check_bodies_contiguous

            try:
                check_bodies_contiguous(start.bodies.body_ids, "outputs.mdanalysis",
                                        "give a structure whose bodies' atoms follow each "
                                        "other (molecule by molecule), or leave "
                                        "outputs.mdanalysis out")
            except ValueError as err:
                raise ConfigError(str(err)) from None
        keep = self.files.relaxation + [self.outputs.checkpoint] if relaxation else ()
        self.files.prepare(self.checkpoints.is_earlier_demo, replace, keep)
        # Nothing of this run's is in the directory now (but a relaxation it continues):
        # what appears is this run's.
        self.files.note_created()
        if self.config.relax is not None:  # (a restart with relax: is refused by the config)
            self._relax(atoms, bodies, start, relaxation)
        out = self.outputs
        return RigidDynamics(atoms, self.config.run.timestep, bodies=bodies,
                             couplings=self.config.coupling.parts(),
                             trajectory=str(out.trajectory) if out.trajectory else None,
                             logfile=str(out.log) if out.log else None,
                             loginterval=out.interval, **self._dynamics_arguments())

    def _relax(self, atoms, bodies, start, continuing):
        """The ``relax:`` section on ``atoms``, then velocities for the relaxed bodies.

        The checkpoint of the run's start (``start``, a dynamics of its
        unrelaxed atoms) at step 0 that records the relaxation is written before
        it begins, so a relaxation that stops (a signal), falls short of
        ``relax.steps``, fails or is killed outright (SIGKILL, a node lost) can
        be continued: ``--resume`` continues it from the last frame of its
        trajectory, and the MD after it.  The MD's own step-0 checkpoint
        replaces it.
        """
        from rigidmd.run.relaxstructure import continue_from, relax_structure, state_path

        section, directory = self.config.relax, self.outputs.directory
        done = 0
        if continuing:
            trajectory = directory / section.trajectory
            done = continue_from(atoms, trajectory, state_path(trajectory), self.stream)
        else:
            self.checkpoints.write(start, relaxation=str(section.trajectory))
        # Installed before the relaxation's own handlers and kept until the MD's: a signal
        # once the relaxation has ended is noted (the MD stops after its first step, with a
        # checkpoint), never a kill without a word.
        self._after_relax = StopSignals().__enter__()
        self._after_relax.shielded = True  # a second Ctrl-C then is only counted
        relax_structure(atoms, bodies, section, directory, self.stream, resume=continuing,
                        done=done, hint=self._resume_hint(), stop=StopSignals(),
                        label=f"calculator {self.fingerprint['calculator']}")
        self._draw_velocities(atoms, bodies)

    def _resumed_dynamics(self):
        from rigidmd.core.logger import RigidLogger
        from rigidmd.run.restart import load_checkpoint

        out = self.outputs
        checkpoint = self.checkpoints.read_for_resume()
        if checkpoint.nsteps == 0 and checkpoint.extra.get("relaxation") and \
                self.config.relax is not None:
            # Stopped while relaxing: the relaxation goes on, then the MD; killed before
            # its first frame, the run starts again.
            if not _holds_a_frame(out.directory / self.config.relax.trajectory):
                print(f"the relaxation had written no frame of {self.config.relax.trajectory}: "
                      "starting the run again", file=self.stream)
                return self._new_dynamics(replace=True)
            return self._new_dynamics(relaxation=True)
        if checkpoint.nsteps == 0:
            # Killed before its first interval checkpoint: the step-0 checkpoint holds the
            # configuration's start, so the run starts again (writing step 0 once).
            print(f"the checkpoint {out.checkpoint.name} is at step 0: starting the run again",
                  file=self.stream)
            return self._new_dynamics(replace=True)
        calc = self.config.calculator.build(checkpoint.atoms(), out.directory / "engine")
        self.files.prepare(self.checkpoints.is_earlier_demo)
        trimmed = trim_outputs(self.files.appended(), checkpoint.extra.get("outputs", {}),
                               self.files.fresh_start_advice())
        self.checkpoints.step = checkpoint.nsteps
        dyn = load_checkpoint(checkpoint, calc,
                              trajectory=str(out.trajectory) if out.trajectory else None,
                              append_trajectory=True, loginterval=out.interval)
        if out.log:
            dyn.attach(dyn.closelater(RigidLogger(dyn, str(out.log), pressure=dyn.evaluator.stress,
                                                  header=False)), out.interval)
        cut = f" (cut back: {', '.join(trimmed)})" if trimmed else ""
        print(f"resuming from step {dyn.nsteps} of {out.checkpoint}{cut}", file=self.stream)
        return dyn

    # ------------------------------------------------------------ the run
    def inputs(self):
        """The files the run reads, by field: ``{field: path or None}``."""
        structure, integrator = self.config.structure, self.config.run.integrator
        return {"configuration": self.config_path,
                "structure": structure.source if isinstance(structure.source, Path) else None,
                "restart": structure.restart,
                "integrator": integrator if isinstance(integrator, str) and
                integrator.endswith((".yaml", ".yml")) else None}

    def execute(self):
        """Run; returns the exit status (0, or 130/143/138 after a stop signal)."""
        # Before anything is touched.  A restart from this directory's own trajectory is
        # read before the outputs are removed (--overwrite), or refused (a new run).
        check_apart_from_inputs(self.files.named(), self.inputs(),
                                allowed={("outputs.trajectory", "restart")})
        lock = self.files.open()
        try:
            return self._execute()
        except BaseException:
            self.files.abandon(lock, started=self.checkpoint_step is not None)
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
        try:
            return self._execute_steps()
        finally:
            if self._after_relax is not None:
                self._after_relax.__exit__(None, None, None)  # the handlers before the run's

    def _execute_steps(self):
        dyn = self._set_up()
        stop = StopSignals()
        if self._after_relax is not None and self._after_relax.signum is not None:
            stop.signum = self._after_relax.signum  # arrived after the relaxation: obeyed now
        # The handlers stay until the calculator is closed: a signal after the steps is noted,
        # never a KeyboardInterrupt in the final checkpoint's write or the engine's shutdown.
        with stop:
            try:
                return self._drive(dyn, stop)
            finally:
                # A calculator with a process of its own (LAMMPSEngine) stops with the run.
                for calc in [dyn.atoms.calc] + [d.calculator for d in self.diagnostics]:
                    close = getattr(calc, "close", None)
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
        self.files.name_outputs(dyn)
        rows, steps = [], []
        dyn.attach(lambda: (rows.append(observables(dyn)), steps.append(dyn.nsteps)),
                   interval=out.interval)
        writer = None
        if out.mdanalysis is not None:
            from rigidmd.mdanalysis import MDAWriter

            writer = MDAWriter(dyn, out.mdanalysis, append=dyn.nsteps > 0)
            dyn.attach(NamedOutput(writer, out.mdanalysis), interval=out.interval)
        dyn.attach(Progress(dyn, remaining), interval=max(1, remaining // 1000))
        dyn.attach(lambda: self.checkpoints.write(dyn, writer), interval=out.checkpoint_interval)
        if config.diagnostics and config.diagnostics.configurational_temperature:  # summary's
            self.diagnostics = config.diagnostics.attach(
                dyn, own_calculator(config.calculator, dyn.atoms, out.directory / "engine"))
        dyn.attach(stop.check, interval=1)  # last: after every output of the step
        print(f"{dyn.bodies} with {dyn.scheme.name} integrator, {describe(dyn)}, "
              f"steps {dyn.nsteps + 1}-{total} of {config.run.timestep / TIME_UNITS['fs']:g} fs",
              file=self.stream)
        t0, resumed_at = time.perf_counter(), dyn.nsteps
        status, at_once = self._steps(dyn, remaining, writer)
        # The steps are over: a signal now is noted, not obeyed, until the run has written
        # everything (a KeyboardInterrupt inside the checkpoint's write would lose it).
        stop.shielded = True
        if at_once:
            return status  # a second Ctrl-C stopped the steps at once
        return self._finish(dyn, status, stop, (rows, steps, resumed_at), t0)

    def _finish(self, dyn, status, stop, statistics, t0):
        """The final checkpoint, the summary and the plot; the exit status."""
        out = self.outputs
        try:
            self.checkpoints.write(dyn, None)
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
        rows, steps, resumed_at = statistics
        summary(dyn, rows, time.perf_counter() - t0, self.stream, steps, resumed_at)
        for diagnostic in self.diagnostics:
            print(diagnostic.report(), file=self.stream)
        if out.plot is not None and out.log is not None and not status:
            from rigidmd.run.logplot import plot_log

            try:
                plot_log(out.log, out.plot)
            except OSError as err:
                raise self._stopped(dyn, describe_os_error(err)) from None
        for key, path in out.files.items():
            if key == "plot" and status:  # not drawn for a run that stopped: say so
                print(f"not drawn: {path} (the run stopped; rigidmd plot {out.log} draws "
                      "what it has)", file=self.stream)
            elif Path(path).exists():
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
                self.checkpoints.write_after_undone_step(dyn, writer)
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


def _holds_a_frame(trajectory):
    """False when the ASE trajectory file ``trajectory`` is missing, empty, or whole with no
    frame (killed before its first); else True: a damaged file is left to
    :func:`rigidmd.run.relaxstructure.continue_from`, which names it, and nothing is replaced."""
    from ase.io.trajectory import Trajectory

    if not trajectory.is_file() or trajectory.stat().st_size == 0:
        return False
    try:
        with Trajectory(trajectory) as frames:
            return len(frames) > 0
    except Exception:  # ASE raises many kinds on a damaged file  # noqa: BLE001
        return True
