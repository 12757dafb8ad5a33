"""A run of the ``rigidmd`` command: outputs that never mix or break, checkpoints, signals.

* **One run per directory.**  A lock file refuses a second run into a
  directory in use (a lock left by a dead process is taken over).  A new run
  into a directory that already holds outputs is refused unless
  ``--overwrite`` (which removes them first) or ``--resume`` is given.
* **Checkpoints** every ``outputs.checkpoint_interval`` steps and at every
  clean stop: every output file is flushed to disk first and its length is
  recorded in the checkpoint (written atomically).
* **Resume** (``--resume``): every output is cut back to its length at the
  checkpoint (which also removes a truncated last frame after ``kill -9``), the
  dynamics is rebuilt from the checkpoint and the outputs are appended to; the
  finished files equal those of an uninterrupted run.
* **Signals**: SIGTERM (what batch schedulers send), SIGINT (Ctrl-C) and
  SIGUSR1 finish the current step and its outputs, write a checkpoint, close
  the files and exit with 143, 130 or 138, saying how to resume.  A second
  Ctrl-C stops at once (the step in progress is undone).
* **Write failures** (a full disk, no permission) end the run with one line
  naming the file and status 1; the last checkpoint stays intact.
"""

import hashlib
import json
import signal
import sys
import time
from dataclasses import asdict

import numpy as np
from ase import units

from rigidmd.config import TIME_UNITS, ConfigError
from rigidmd.dof import temperature
from rigidmd.outputs import OutputError, OutputLock, output_lengths, trim_outputs

__all__ = ["Run", "Progress", "StopSignals", "StopRequest"]

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
    at once.
    """

    modifies_atoms = False

    def __init__(self):
        self.signum = None
        self._previous = {}

    def _handler(self, signum, frame):
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signum = signum

    def check(self):
        if self.signum is not None:
            raise StopRequest(self.signum)

    def __enter__(self):
        for signum in EXIT_STATUS:
            self._previous[signum] = signal.signal(signum, self._handler)
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False


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
                f"{rate:8.1f} steps/s  T {temperature(self.dyn.atoms):7.1f} K")
        if self.tty:
            self.stream.write("\r" + line + ("\n" if done >= self.total else ""))
        elif fraction + 1e-12 >= self.next_report or done >= self.total or now - self.last > 30:
            self.stream.write(line + "\n")
            self.next_report = np.floor(fraction * 100 + 1) / 100
            self.last = now
        self.stream.flush()


def fingerprint(config):
    """A digest of what defines the trajectory (all but ``steps`` and output names)."""
    run = asdict(config.run)
    run.pop("steps")
    data = {
        "structure": str(config.structure.source), "bodies": config.structure.bodies,
        "calculator": asdict(config.calculator), "run": run,
        "coupling": [[spec.kind, spec.kwargs, spec.seed] for spec in config.coupling.specs],
        "interval": config.outputs.interval,
    }
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _observables(dyn):
    """Time, conserved energy and, under a barostat, pressure (bar), volume, density."""
    row = (dyn.get_time(), dyn.get_conserved_energy())
    if dyn.evaluator.cell_moves:
        row += (dyn.get_pressure() / units.bar, dyn.get_volume(), dyn.get_density())
    return row


class Run:
    """One ``rigidmd run`` (or ``demo``) of a checked configuration.

    Parameters
    ----------
    config : rigidmd.config.RunConfig
    mode : {"new", "resume", "overwrite", "demo"}
        ``"demo"`` replaces the directory's earlier outputs, saying so.
    config_path : str, optional
        The configuration file, for the resume hint.
    stream : file
    """

    def __init__(self, config, mode="new", config_path=None, stream=sys.stdout):
        self.config, self.mode, self.stream = config, mode, stream
        self.config_path = config_path
        self.outputs = config.outputs

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

    def _prepare_directory(self):
        existing = [p for p in self._all_files() if p.exists()]
        if self.mode == "resume" or not existing:
            return
        names = ", ".join(p.name for p in existing)
        if self.mode == "new":
            raise ConfigError(
                f"outputs: {self.outputs.directory} already holds {names} from an earlier run; "
                "continue it with --resume, or replace it with --overwrite")
        verb = "replacing the earlier demo's" if self.mode == "demo" else "removing"
        print(f"{verb} {names} in {self.outputs.directory}", file=self.stream)
        for path in existing:
            path.unlink()

    # ------------------------------------------------------------ set-up
    def start_atoms(self):
        from rigidmd import rigid_maxwell_boltzmann

        config = self.config
        atoms = config.structure.build_atoms()
        bodies = config.structure.resolve_bodies(atoms)
        velocities = config.run.velocities
        if velocities is not None and config.structure.restart is None:
            rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                    rng=np.random.default_rng(velocities["seed"]))
        return atoms, bodies

    def _new_dynamics(self):
        from rigidmd.dynamics import RigidDynamics

        atoms, bodies = self.start_atoms()
        atoms.calc = self.config.calculator.build(atoms)
        out = self.outputs
        return RigidDynamics(atoms, self.config.run.timestep, bodies=bodies,
                             integrator=self.config.run.integrator,
                             integrator_options=self.config.run.integrator_options,
                             couplings=self.config.coupling.parts(),
                             trajectory=str(out.trajectory) if out.trajectory else None,
                             logfile=str(out.log) if out.log else None,
                             loginterval=out.interval)

    def _resumed_dynamics(self):
        from rigidmd.checkpoint import CheckpointError, read_checkpoint
        from rigidmd.logger import RigidLogger
        from rigidmd.restart import load_checkpoint

        out = self.outputs
        try:
            checkpoint = read_checkpoint(out.checkpoint)
        except CheckpointError as err:
            raise ConfigError(f"--resume: {err}; start the run without --resume") from None
        recorded = checkpoint.extra.get("fingerprint")
        if recorded != fingerprint(self.config):
            raise ConfigError(
                "--resume: the configuration differs from the checkpoint's (only steps may "
                "change between a run and its continuation); restore it, or start anew "
                "with --overwrite")
        trimmed = trim_outputs(self._appended_files(), checkpoint.extra.get("outputs", {}))
        atoms = checkpoint.atoms()
        calc = self.config.calculator.build(atoms)
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
                 "fingerprint": fingerprint(self.config), "steps": self.config.run.steps}
        dyn.save_checkpoint(self.outputs.checkpoint, extra=extra)

    # ------------------------------------------------------------ the run
    def execute(self):
        """Run; returns the exit status (0, or 130/143/138 after a stop signal)."""
        out = self.outputs
        try:
            out.directory.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"outputs.directory: cannot create {out.directory} "
                              f"({err.strerror})") from None
        lock = OutputLock(out.directory)
        try:
            lock.acquire()
        except PermissionError:
            raise OutputError(f"outputs.directory: cannot write in {out.directory} "
                              "(permission denied)") from None
        if lock.stale:
            print(f"taking over the lock left by process {lock.stale.get('pid')}, which is gone",
                  file=self.stream)
        try:
            return self._execute()
        finally:
            lock.release()

    def _execute(self):
        out, config = self.outputs, self.config
        self._prepare_directory()
        dyn = self._resumed_dynamics() if self.mode == "resume" else self._new_dynamics()
        total = config.run.steps
        remaining = total - dyn.nsteps
        if remaining <= 0:
            print(f"the run is complete ({dyn.nsteps} of {total} steps); raise steps to go on",
                  file=self.stream)
            return 0
        rows = []
        dyn.attach(lambda: rows.append(_observables(dyn)), interval=out.interval)
        writer = None
        if out.mdanalysis is not None:
            from rigidmd.mdanalysis import MDAWriter

            writer = MDAWriter(dyn, out.mdanalysis, append=self.mode == "resume")
            dyn.attach(writer, interval=out.interval)
        dyn.attach(Progress(dyn, remaining), interval=max(1, remaining // 1000))
        dyn.attach(lambda: self._checkpoint(dyn, writer), interval=out.checkpoint_interval)
        stop = StopSignals()
        dyn.attach(stop.check, interval=1)  # last: after every output of the step
        print(f"{dyn.bodies} with {dyn.scheme.name} integrator, {describe(dyn)}, "
              f"steps {dyn.nsteps + 1}-{total} of {config.run.timestep / TIME_UNITS['fs']:g} fs",
              file=self.stream)
        status = 0
        t0 = time.perf_counter()
        try:
            with stop:
                dyn.run(remaining)
        except StopRequest as request:
            status = EXIT_STATUS[request.signum]
            print(f"\nstopped by {request} after step {dyn.nsteps}", file=self.stream)
        except KeyboardInterrupt:
            status = 130
            print(f"\ninterrupted during step {dyn.nsteps + 1}; it was undone", file=self.stream)
        finally:
            if writer is not None:
                writer.close()
        self._checkpoint(dyn, None)
        if status:
            again = f"rigidmd run {self.config_path or 'CONFIG'} --resume"
            print(f"checkpoint {out.checkpoint} written; continue with: {again}",
                  file=self.stream)
        summary(dyn, rows, time.perf_counter() - t0, self.stream)
        if out.plot is not None and out.log is not None:
            from rigidmd.logplot import plot_log

            plot_log(out.log, out.plot)
        for path in out.files.values():
            print(f"wrote {path}", file=self.stream)
        return status


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
    if len(rows) >= 3:
        data = np.array(rows)
        t_ps, e = data[:, 0] / TIME_UNITS["ps"], data[:, 1]
        drift = np.polyfit(t_ps, e, 1)[0]
        print(f"{label}: drift {drift:+.2e} eV/ps, max |E - E0| {np.abs(e - e[0]).max():.2e} eV",
              file=stream)
        if data.shape[1] > 2:
            pressure, volume, density = data[:, 2:].T
            print(f"mean P = {pressure.mean():.1f} bar, V = {volume.mean():.1f} Å³, "
                  f"density = {density.mean():.4f} g/cm³ (final {density[-1]:.4f})",
                  file=stream)

