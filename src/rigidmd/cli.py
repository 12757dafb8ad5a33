"""The ``rigidmd`` command: ``demo``, ``run``, ``plot`` and ``export-lammps``.

``rigidmd demo``                      a TIP3P water cluster, 2 ps, with plots
``rigidmd run CONFIG.yaml [flags]``   any system from a configuration file
``rigidmd plot LOG``                  energy and temperature of an MD log, to PNG
``rigidmd export-lammps CONFIG DIR``  the same run as a LAMMPS data file and deck

See :mod:`rigidmd.config` for the configuration format.  A mistake in the
configuration or the flags prints one line naming the field and exits with
status 2; an interrupted run (Ctrl-C) keeps every output readable up to the
last completed step and exits with status 130.
"""

import argparse
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
from ase import units

from rigidmd.config import (
    DEMO_CONFIG,
    TIME_UNITS,
    ConfigError,
    check_config,
    load_config,
    parse_quantity,
)
from rigidmd.coupling import NotExportable
from rigidmd.dynamics import NonFiniteForceError
from rigidmd.operators import ConvergenceError

__all__ = ["main"]


class Progress:
    """A progress bar on stderr (a line per 10 % when stderr is not a terminal)."""

    def __init__(self, dyn, total, stream=None, width=30):
        self.dyn, self.total, self.width = dyn, max(int(total), 1), width
        self.stream = sys.stderr if stream is None else stream
        self.start_step = dyn.nsteps
        self.t0 = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.next_report = 0.1

    def __call__(self):
        done = self.dyn.nsteps - self.start_step
        fraction = done / self.total
        elapsed = time.perf_counter() - self.t0
        rate = done / elapsed if elapsed > 0 else 0.0
        bar = "#" * int(self.width * fraction)
        line = (f"[{bar:<{self.width}}] {done:>{len(str(self.total))}}/{self.total} steps "
                f"{rate:8.1f} steps/s  T {self.dyn.atoms.get_temperature():7.1f} K")
        if self.tty:
            self.stream.write("\r" + line)
            if done >= self.total:
                self.stream.write("\n")
        elif fraction + 1e-12 >= self.next_report or done >= self.total:
            self.stream.write(line + "\n")
            self.next_report = np.floor(fraction * 10 + 1) / 10
        self.stream.flush()


class _DeferredInterrupt:
    """Ctrl-C stops the run after the current step's outputs are all written.

    A second Ctrl-C interrupts at once (the step in progress is rolled back,
    so the state stays consistent, but that step's outputs may be partial).
    """

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handler(self, signum, frame):
        self.requested = True
        signal.signal(signal.SIGINT, self._previous)

    def check(self):
        if self.requested:
            raise KeyboardInterrupt

    def __enter__(self):
        self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self._previous)
        return False


def read_log(path):
    """Columns of an ASE MD log: time (ps), Etot, Epot, Ekin (eV), T (K)."""
    rows = []
    with open(path) as fh:
        for line in fh:
            parts = line.split()
            try:
                rows.append([float(v) for v in parts[:5]])
            except ValueError:
                continue  # header lines
    if not rows:
        raise ConfigError(f"log: {path} holds no MD log lines")
    return np.array(rows)


def plot_log(log, png):
    """Energy and temperature against time, two panels, to ``png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = read_log(log)
    t, etot, epot, ekin, temp = data.T
    fig, (ax0, ax1, ax2) = plt.subplots(3, 1, sharex=True, figsize=(7, 8))
    ax0.plot(t, 1000 * (etot - etot[0]), color="C0")
    ax0.set_ylabel("total energy − initial (meV)")
    ax0.set_title(Path(log).name)
    ax1.plot(t, epot - epot[0], label="potential", color="C1")
    ax1.plot(t, ekin - ekin[0], label="kinetic", color="C2")
    ax1.set_ylabel("energy − initial (eV)")
    ax1.legend(loc="best")
    ax2.plot(t, temp, color="C3")
    ax2.set_ylabel("temperature (K)")
    ax2.set_xlabel("time (ps)")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def _setup(config):
    """Atoms and dynamics from a checked configuration."""
    from rigidmd.dynamics import RigidDynamics

    atoms, bodies = _start(config)
    atoms.calc = config.calculator.build(atoms)
    outputs, restart = config.outputs, config.structure.restart
    outputs.directory.mkdir(parents=True, exist_ok=True)
    trajectory = outputs.trajectory
    append = restart is not None and trajectory is not None and trajectory.exists() and (
        trajectory.resolve() == restart.resolve())
    dyn = RigidDynamics(atoms, config.run.timestep, bodies=bodies,
                        integrator=config.run.integrator,
                        integrator_options=config.run.integrator_options,
                        couplings=config.coupling.parts(),
                        trajectory=str(trajectory) if trajectory else None,
                        logfile=str(outputs.log) if outputs.log else None,
                        loginterval=outputs.interval, append_trajectory=append)
    return atoms, dyn


def _start(config):
    """Starting atoms, their bodies, and (unless restarting) drawn rigid velocities."""
    from rigidmd import rigid_maxwell_boltzmann

    atoms = config.structure.build_atoms()
    bodies = config.structure.resolve_bodies(atoms)
    velocities = config.run.velocities
    if velocities is not None and config.structure.restart is None:
        rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                rng=np.random.default_rng(velocities["seed"]))
    return atoms, bodies


def _kind(dyn):
    """What the run is, in words: NVE, or its coupling parts."""
    parts = [f"{part.kind} {part.section}" + (
        f" at {part.temperature_K:g} K" if hasattr(part, "temperature_K") else "")
        for part in dyn.couplings]
    return ", ".join(parts) or "NVE"


def _run(config, stream=sys.stdout):
    """Run a checked configuration; returns the exit status."""
    atoms, dyn = _setup(config)
    outputs = config.outputs
    energies = []
    dyn.attach(lambda: energies.append(_observables(dyn)), interval=outputs.interval)
    writer = None
    if outputs.mdanalysis is not None:
        from rigidmd.mdanalysis import MDAWriter

        writer = MDAWriter(dyn, outputs.mdanalysis)
        dyn.attach(writer, interval=outputs.interval)
    steps = config.run.steps
    dyn.attach(Progress(dyn, steps), interval=max(1, steps // 200))
    interrupt = _DeferredInterrupt()
    dyn.attach(interrupt.check, interval=1)  # last: after every output of the step
    print(f"{dyn.bodies} with {dyn.scheme.name} integrator, {_kind(dyn)}, {steps} steps of "
          f"{config.run.timestep / TIME_UNITS['fs']:g} fs", file=stream)
    status = 0
    t0 = time.perf_counter()
    try:
        with interrupt:
            dyn.run(steps)
    except KeyboardInterrupt:
        print(f"\ninterrupted after step {dyn.nsteps}: the outputs hold every step up to it",
              file=stream)
        status = 130
    finally:
        if writer is not None:
            writer.close()
    elapsed = time.perf_counter() - t0
    _summary(dyn, energies, elapsed, stream)
    if outputs.plot is not None and outputs.log is not None:
        plot_log(outputs.log, outputs.plot)
    for path in outputs.files.values():
        print(f"wrote {path}", file=stream)
    return status


def _observables(dyn):
    """Time, conserved energy and, under a barostat, pressure (bar), volume, density."""
    row = (dyn.get_time(), dyn.get_conserved_energy())
    if dyn._cell_moves:
        row += (dyn.get_pressure() / units.bar, dyn.get_volume(), dyn.get_density())
    return row


def _summary(dyn, rows, elapsed, stream):
    label = "conserved energy" if dyn.couplings else "total energy"
    print(f"{dyn.nsteps} steps in {elapsed:.1f} s; T = {dyn.atoms.get_temperature():.1f} K "
          f"({dyn.degrees_of_freedom} degrees of freedom)", file=stream)
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


def _apply_flags(config, args):
    """Command-line flags override the configuration file."""
    for key in ("steps", "timestep", "integrator", "bodies", "restart", "structure"):
        value = getattr(args, key, None)
        if value is not None:
            config[key] = value
    if getattr(args, "outdir", None):
        config.setdefault("outputs", {})
        config["outputs"] = dict(config["outputs"], directory=str(Path(args.outdir).resolve()))
    return config


def _export(config, directory, stream=sys.stdout):
    from rigidmd.lammps import export_lammps, tip3p_charges, tip3p_pair_commands

    atoms, bodies = _start(config)
    atoms.positions = bodies.whole_positions(atoms)
    calc = config.calculator
    if calc.name == "tip3p":
        rc = calc.options.get("rc", 5.0)
        width = calc.options.get("width", 1.0)
        oxygens = atoms.positions[atoms.numbers == 8]
        span = np.linalg.norm(oxygens[:, None] - oxygens[None], axis=-1).max()
        if atoms.pbc.any() or span >= rc - width:
            raise ConfigError(
                "calculator: ASE's TIP3P switches off each molecule pair smoothly near rc, "
                "which no LAMMPS pair style reproduces; export works for a cluster within "
                f"rc - width (here {span:.1f} Å >= {rc - width:g} Å) or with the lammps "
                "calculator")
        pair, charges = tip3p_pair_commands(rc), tip3p_charges(atoms)
    elif calc.name == "lammps":
        pair = list(calc.pair)
        charges = np.array([calc.charges.get(s, 0.0) for s in atoms.get_chemical_symbols()])
    else:
        raise ConfigError(f"calculator.name: {calc.name!r} has no LAMMPS equivalent; "
                          "export-lammps supports tip3p and lammps")
    integrator = config.run.integrator
    if integrator != "no_squish":
        raise ConfigError(f"integrator: export-lammps writes fix rigid/nve/small (no_squish), "
                          f"not {integrator!r}")
    kwargs = {}
    for spec in config.coupling.specs:
        part = spec.part()
        try:
            part.lammps_fix(time_unit=1000 * units.fs, seed=spec.seed or 12345)
        except NotExportable as err:
            raise ConfigError(str(err)) from None
        kwargs["temperature_K"] = part.temperature_K
        if spec.kind == "langevin":
            kwargs.update(friction=part.friction, seed=spec.seed or 12345)
        else:
            kwargs["tdamp"] = part.tdamp
    interval = config.outputs.interval
    files = export_lammps(atoms, bodies.body_ids, directory, pair, config.run.timestep,
                          config.run.steps, charges=charges, dump_every=interval,
                          thermo_every=interval, **kwargs)
    print(f"wrote {files['data']} and {files['input']}; run with "
          f"'cd {directory} && lmp -in in.rigidmd' (or mpirun -np N lmp -in in.rigidmd)",
          file=stream)
    return 0


def _parser():
    parser = argparse.ArgumentParser(prog="rigidmd", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the built-in TIP3P water cluster demo")
    demo.add_argument("--steps", type=int, help="number of steps (default 2000)")
    demo.add_argument("--outdir", help="output directory (default ./rigidmd-demo)")
    run = sub.add_parser("run", help="run a configuration file")
    run.add_argument("config", nargs="?", help="YAML configuration (see rigidmd.config)")
    run.add_argument("--structure", help="structure file (any ASE-readable format)")
    run.add_argument("--steps", type=int)
    run.add_argument("--timestep", help="time step with unit, e.g. '2 fs'")
    run.add_argument("--integrator")
    run.add_argument("--bodies", help="connectivity, mol-id or tags")
    run.add_argument("--restart", help="continue from the last frame of this trajectory")
    run.add_argument("--outdir", help="output directory")
    plot = sub.add_parser("plot", help="plot energy and temperature of an MD log")
    plot.add_argument("log")
    plot.add_argument("-o", "--output", help="PNG file (default: the log's name with .png)")
    export = sub.add_parser("export-lammps", help="write an equivalent LAMMPS data file and deck")
    export.add_argument("config")
    export.add_argument("directory")
    export.add_argument("--steps", type=int)
    return parser


def main(argv=None):
    """Entry point of the ``rigidmd`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "plot":
            log = Path(args.log)
            if not log.is_file():
                raise ConfigError(f"log: no such file {str(log)!r}")
            png = Path(args.output) if args.output else log.with_suffix(".png")
            plot_log(log, png)
            print(f"wrote {png}")
            return 0
        if args.command == "demo":
            config = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEMO_CONFIG.items()}
            config = _apply_flags(config, args)
            return _run(check_config(config))
        if args.command == "run":
            if args.config:
                config = load_config(args.config)
            elif args.structure:
                config = {"_base": str(Path.cwd())}
            else:
                raise ConfigError("config: give a configuration file or --structure")
            config = _apply_flags(config, args)
            if args.timestep is not None:
                parse_quantity("--timestep", args.timestep, TIME_UNITS)
            return _run(check_config(config))
        if args.command == "export-lammps":
            config = _apply_flags(load_config(args.config), args)
            return _export(check_config(config), Path(args.directory))
    except ConfigError as err:
        print(f"rigidmd: error: {err}", file=sys.stderr)
        return 2
    except (NonFiniteForceError, ConvergenceError) as err:
        # The run stopped; its outputs hold every step before the failure.
        print(f"rigidmd: run stopped: {err}", file=sys.stderr)
        return 1
    except (ValueError, TypeError) as err:
        # Raised by rigidmd before anything runs: a bad body definition, mass, ...
        if os.environ.get("RIGIDMD_DEBUG"):
            raise
        print(f"rigidmd: error: {err}", file=sys.stderr)
        return 2
    return 1  # pragma: no cover - argparse requires a command


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
