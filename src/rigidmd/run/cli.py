"""The ``rigidmd`` command: ``demo``, ``run``, ``relax``, ``bias``, ``plot`` and ``export-lammps``.

``rigidmd demo``                      a TIP3P water cluster, 2 ps, with plots
``rigidmd run CONFIG.yaml [flags]``   any system from a configuration file
``rigidmd relax CONFIG.yaml``         relax its rigid bodies (and cell) only
``rigidmd bias CONFIG.yaml``          the time step's bias of ⟨U⟩, from runs at dt and dt/2
``rigidmd plot LOG``                  energies and temperature of an MD log, to PNG
``rigidmd export-lammps CONFIG DIR``  the same run as a LAMMPS data file and deck
``rigidmd --version``                 the version (with ASE's, NumPy's and Python's)

See :mod:`rigidmd.config` for the configuration format and
:mod:`rigidmd.run.runner` for outputs, checkpoints and signals.  A mistake in the
configuration or the flags prints one line naming the field and exits with
status 2; a run stopped by the calculator (non-finite forces) or by a failed
write exits with 1; SIGINT, SIGTERM and SIGUSR1 stop after the current step
with a checkpoint (130, 143, 138), and ``--resume`` continues exactly.
"""

import argparse
import os
import signal
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from rigidmd.config import (
    DEMO_CONFIG,
    TIME_UNITS,
    ConfigError,
    check_config,
    load_config,
    parse_quantity,
)
from rigidmd.config.sections import PLOT_FORMATS
from rigidmd.config.trust import GivenOnCommandLine
from rigidmd.core.dynamics import NonFiniteForceError
from rigidmd.core.operators import ConvergenceError
from rigidmd.couplings.base import NotExportable
from rigidmd.lammps.library import LammpsError
from rigidmd.run.bias import add_bias_parser, bias_command
from rigidmd.run.fingerprint import resume_command
from rigidmd.run.logplot import LogError, plot_log
from rigidmd.run.outputs import OutputError, check_apart_from_inputs, describe_os_error
from rigidmd.run.relaxcommand import relax_only
from rigidmd.run.relaxstructure import RelaxationFailed, RelaxationNotConverged, RelaxationStopped
from rigidmd.run.runner import Run, RunStopped
from rigidmd.run.signals import StopSignals

__all__ = ["main"]

#: Outputs of ``rigidmd run --structure FILE`` without a configuration file.
FLAGS_ONLY_OUTPUTS = {"directory": "rigidmd-run", "trajectory": "md.traj", "log": "md.log",
                      "interval": 10}


def _apply_flags(config, args):
    """Command-line flags override the configuration file.

    Paths given on the command line are taken relative to the current
    directory (paths inside a configuration file, relative to the file).
    """
    for key in ("steps", "timestep", "integrator", "bodies"):
        value = getattr(args, key, None)
        if value is not None:
            config[key] = value
    integrator = getattr(args, "integrator", None)
    if integrator is not None and integrator.endswith((".yaml", ".yml")):  # a scheme file
        config["integrator"] = str(Path(integrator).resolve())
    for key in ("restart", "structure"):
        value = getattr(args, key, None)
        if value is not None:
            config[key] = str(Path(value).resolve())
    if getattr(args, "outdir", None):
        config.setdefault("outputs", {})
        # The user's own choice, not the configuration's: it may be anywhere.
        outdir = GivenOnCommandLine(Path(args.outdir).resolve())
        config["outputs"] = dict(config["outputs"], directory=outdir)
    return config


def _resume_hint(args):
    """The exact command that resumes ``rigidmd run`` with these flags (see :func:`resume_command`).

    The flags that define the run are repeated as given; ``--outdir`` is
    given with its absolute path, so the command cannot act on another run.
    """
    flags = []
    for key in ("structure", "restart", "steps", "timestep", "integrator", "bodies"):
        value = getattr(args, key, None)
        if value is not None:
            flags += [f"--{key}", str(value)]
    if args.trust:
        flags.append("--trust")
    return resume_command(args.config, args.outdir, flags)


#: The files export-lammps writes in its directory (LAMMPS writes frames.dump when run).
DECK_FILES = ("in.rigidmd", "data.rigidmd")


def _check_deck_directory(directory, config_path, overwrite):
    """Refuse, in one line and before anything is read or written, a directory that is a
    file, one holding a deck (without ``overwrite``), or a deck file that is the
    configuration itself."""
    if directory.exists() and not directory.is_dir():
        raise ConfigError(f"directory: {directory} is a file; give a directory for the deck")
    check_apart_from_inputs({name: directory / name for name in DECK_FILES},
                            {"configuration": config_path})
    held = [name for name in DECK_FILES if (directory / name).exists()]
    if held and not overwrite:
        raise ConfigError(f"directory: {directory} already holds {' and '.join(held)}; give "
                          "another directory, or --overwrite to replace them")


def _export(config, directory, stream=sys.stdout):
    if config.calculator.name == "multiple_time_step":  # before any file is read or written
        raise ConfigError("calculator: export-lammps cannot write a split (fast, slow, substeps): "
                          "under LAMMPS's run_style respa its rigid fixes kick each inner step "
                          "with the outer level's forces (not r-RESPA; 8.7e-3 Å off its own "
                          "Verlet after one step at k = 1), and its levels split one LAMMPS "
                          "model, not two calculators; export the full model on its own")
    atoms, bodies = Run(config).start_atoms()
    _check_exportable(config, atoms, bodies)  # before a relaxation spends its time and writes
    # Installed before the relaxation's own handlers and kept until the deck is written: a
    # signal once the relaxation has ended is noted and the deck finished (a second
    # Ctrl-C only counted), never a kill without a word halfway through the files.
    after = StopSignals()
    after.shielded = True
    with after:
        status = _write_deck(config, atoms, bodies, directory, stream)
    if after.signum is not None:
        print(f"export-lammps: {signal.Signals(after.signum).name} arrived after the "
              "relaxation had ended; the deck is complete", file=stream)
    return status


def _check_exportable(config, atoms, bodies):
    """Refuse, in one line, a calculator, integrator or coupling LAMMPS has no equivalent
    for, and ASE's TIP3P on a periodic box or a cluster too wide for its ``rc`` (checked on
    the start; :func:`_write_deck` checks the relaxed cluster again)."""
    from rigidmd.couplings.base import NotExportable
    from rigidmd.lammps.deck import coupling_fix

    if config.calculator.name not in ("tip3p", "lammps"):
        raise ConfigError(f"calculator.name: {config.calculator.name!r} has no LAMMPS "
                          "equivalent; export-lammps supports tip3p and lammps")
    if config.run.integrator != "no_squish":
        raise ConfigError(f"integrator: export-lammps writes fix rigid/nve/small (no_squish), "
                          f"not {config.run.integrator!r}")
    try:
        coupling_fix(config.coupling.parts(),
                     free_atoms=bool(np.any(np.asarray(bodies.body_ids) < 0)))
    except NotExportable as err:
        raise ConfigError(str(err)) from None
    if config.calculator.name == "tip3p":
        _check_tip3p_exportable(config.calculator, bodies.whole_positions(atoms), atoms)


def _check_tip3p_exportable(calc, positions, atoms):
    """Refuse (one line) ASE's TIP3P where the deck's pair style would not reproduce it.

    The deck's pair style cuts each atom pair at ``rc``, where ASE's TIP3P takes every
    atom pair of two molecules whose oxygens are within its switch: every atom pair must
    lie within ``rc`` too, and a periodic box (images across the faces) cannot be written.

    Parameters
    ----------
    calc : rigidmd.config.CalculatorSection
        ``name: tip3p``.
    positions : numpy.ndarray
        The atoms' positions, each body whole.
    atoms : ase.Atoms
        Their numbers and periodicity.
    """
    rc = calc.options.get("rc", 5.0)
    width = calc.options.get("width", 1.0)
    oxygens = positions[atoms.numbers == 8]
    span = np.linalg.norm(oxygens[:, None] - oxygens[None], axis=-1).max()
    atom_span = np.linalg.norm(positions[:, None] - positions[None], axis=-1).max()
    if atoms.pbc.any() or span >= rc - width or atom_span >= rc:
        raise ConfigError(
            "calculator: ASE's TIP3P switches off each molecule pair smoothly near rc, "
            "which no LAMMPS pair style reproduces; export works for a cluster whose "
            f"oxygens lie within rc - width and atoms within rc (here {span:.1f} Å "
            f"against {rc - width:g} Å, {atom_span:.1f} Å against {rc:g} Å) or with the "
            "lammps calculator")


def _write_deck(config, atoms, bodies, directory, stream):
    """Relax (with a ``relax:`` section) and write the deck: :func:`_export`'s work."""
    from rigidmd.lammps import export_lammps, tip3p_charges, tip3p_pair_commands

    if config.relax is not None:  # the deck starts where `rigidmd run` would start its MD
        from rigidmd.run.relaxcommand import relax_for_export

        relax_for_export(config, atoms, bodies, directory, stream)
    atoms.positions = bodies.whole_positions(atoms)
    calc = config.calculator
    if calc.name == "tip3p":  # (checked on the start; the relaxation may have spread it)
        _check_tip3p_exportable(calc, atoms.positions, atoms)
        rc = calc.options.get("rc", 5.0)
        pair, charges = tip3p_pair_commands(rc), tip3p_charges(atoms)
    else:  # "lammps" (_check_exportable refused the others)
        pair = list(calc.commands)
        if calc.options.get("exclude_intramolecular", True):
            pair.append("neigh_modify exclude molecule/intra all")  # as the calculator does
        if calc.water is not None:
            calc.build(atoms)  # checks the molecules against the model, sets its charges
        charges = (np.array([calc.charges.get(s, 0.0) for s in atoms.get_chemical_symbols()])
                   if calc.charges else atoms.get_initial_charges())
    couplings = config.coupling.parts()
    seeds = [spec.seed for spec in config.coupling.specs if spec.seed is not None]
    seed = seeds[0] if seeds else 12345
    interval = config.outputs.interval
    try:
        files = export_lammps(atoms, bodies.body_ids, directory, pair, config.run.timestep,
                              config.run.steps, couplings=couplings, seed=seed, charges=charges,
                              dump_every=interval, thermo_every=interval)
    except NotExportable as err:
        raise ConfigError(str(err)) from None
    print(f"wrote {files['data']} and {files['input']}; run with "
          f"'cd {directory} && lmp -in in.rigidmd' (or mpirun -np N lmp -in in.rigidmd)",
          file=stream)
    return 0


#: What the demo's user sees, and why (printed before it runs).
DEMO_NOTE = ("rigidmd demo: 32 rigid TIP3P waters, built on a lattice and not relaxed, "
             "velocities drawn at 250 K, no thermostat (NVE). As the cluster settles, its "
             "potential energy becomes kinetic: the temperature climbs from about 230 K to "
             "300-420 K within 0.4 ps while the total energy stays constant. For a steady "
             "temperature, relax first and add a thermostat (relax: and thermostat: in a "
             "configuration for rigidmd run).")


def _version():
    """``rigidmd 0.1.0 (ASE 3.29.0, NumPy 2.4.6, Python 3.11.9)``: what a bug report needs."""
    import platform
    from importlib.metadata import version

    import ase

    return (f"rigidmd {version('rigidmd')} (ASE {ase.__version__}, NumPy {np.__version__}, "
            f"Python {platform.python_version()})")


def _parser():
    description = __doc__.splitlines()[0].replace("``", "")  # no reStructuredText in --help
    parser = argparse.ArgumentParser(prog="rigidmd", description=description)
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the built-in TIP3P water cluster demo")
    demo.add_argument("--steps", type=int, help="number of steps (default 2000)")
    demo.add_argument("--outdir", help="output directory (default ./rigidmd-demo); an "
                                       "earlier demo's outputs there are replaced")
    run = sub.add_parser("run", help="run a configuration file")
    run.add_argument("config", nargs="?", help="YAML configuration (see rigidmd.config)")
    run.add_argument("--structure", help="structure file (any ASE-readable format)")
    run.add_argument("--steps", type=int, help="total number of steps of the run")
    run.add_argument("--timestep", help="time step with unit, e.g. '2 fs'")
    from rigidmd.core.schemes import BUILTIN_SCHEMES

    run.add_argument("--integrator", help=f"{', '.join(BUILTIN_SCHEMES)} (default no_squish) "
                                          "or a scheme .yaml")
    run.add_argument("--bodies", help="connectivity, mol-id or tags")
    run.add_argument("--restart", help="start a new run from the last frame of this "
                                       "trajectory (to continue a run exactly, use --resume)")
    run.add_argument("--outdir", help="output directory")
    trust_help = ("run what the configuration asks beyond the allow-list (rigidmd.config."
                  "trust): any calculator class and option, any LAMMPS command (shell, python, "
                  "...), output paths outside the run's directory")
    run.add_argument("--trust", action="store_true", help=trust_help)
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue the run from the checkpoint in the output directory")
    mode.add_argument("--overwrite", action="store_true",
                      help="replace the outputs of an earlier run in the output directory")
    _relax_parser(sub, trust_help)
    add_bias_parser(sub, trust_help)
    plot = sub.add_parser("plot", help="plot energies and temperature of an MD log")
    plot.add_argument("log", help="an MD log written by rigidmd (or by ASE's MDLogger)")
    plot.add_argument("-o", "--output", help="image file: .png, .pdf, .svg, ... (default: the "
                                             "log's name with .png)")
    export = sub.add_parser("export-lammps", help="write an equivalent LAMMPS data file and deck")
    export.add_argument("config", help="YAML configuration of the run to export")
    export.add_argument("directory", help="directory for data.rigidmd and in.rigidmd")
    export.add_argument("--steps", type=int, help="number of steps in the deck")
    export.add_argument("--overwrite", action="store_true",
                        help="replace a deck (in.rigidmd, data.rigidmd) already in the directory")
    export.add_argument("--trust", action="store_true", help=trust_help)
    return parser


def _relax_parser(sub, trust_help):
    relax = sub.add_parser("relax", help="relax the rigid bodies (and the cell) of a "
                                         "configuration's structure")
    relax.add_argument("config", help="YAML configuration; its relax: section (default "
                                      "RigidLBFGS to fmax 0.05 eV/Å) says how")
    relax.add_argument("--outdir", help="output directory")
    relax.add_argument("--trust", action="store_true", help=trust_help)
    mode = relax.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue the relaxation from the last frame of its trajectory")
    mode.add_argument("--overwrite", action="store_true",
                      help="replace an earlier relaxation's outputs in the output directory")


@contextmanager
def _further_ctrl_c_ignored():
    """SIGINT ignored inside (in the main thread; elsewhere signals are the main thread's)."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _stopped(command, err):
    """The line for a command that started and stopped: ``rigidmd: run stopped: ...``, or
    ``rigidmd: relax stopped: ...`` for ``rigidmd relax`` (whose messages say ``relax:``)."""
    if command != "relax":
        return f"rigidmd: run stopped: {err}"
    text = str(err)
    return f"rigidmd: relax stopped: {text.removeprefix('relax: ')}"


def main(argv=None):
    """Entry point of the ``rigidmd`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "plot":
            log = Path(args.log)
            if not log.is_file():
                raise ConfigError(f"log: no such file {str(log)!r}")
            png = Path(args.output) if args.output else log.with_suffix(".png")
            if png.suffix.lower().lstrip(".") not in PLOT_FORMATS:
                raise ConfigError(f"-o: {png.name} is not an image file the plot can write; "
                                  "end its name in .png, .pdf or .svg (or "
                                  f"{', '.join('.' + f for f in PLOT_FORMATS[3:])})")
            plot_log(log, png)
            print(f"wrote {png}")
            return 0
        if args.command == "demo":
            config = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEMO_CONFIG.items()}
            config = _apply_flags(config, args)
            print(DEMO_NOTE, file=sys.stderr)
            return Run(check_config(config), mode="demo").execute()
        if args.command == "run":
            if args.config:
                config = load_config(args.config)
            elif args.structure:
                # No configuration: say what is used, and write the usual outputs.
                config = {"_base": str(Path.cwd()), "outputs": dict(FLAGS_ONLY_OUTPUTS)}
                where = args.outdir or FLAGS_ONLY_OUTPUTS["directory"]
                print("rigidmd: no configuration file, so: calculator tip3p (ASE's TIP3P, "
                      "waters only), no thermostat, the structure's velocities (0 K if it "
                      f"has none), md.traj and md.log every 10 steps in {where}/",
                      file=sys.stderr)
            else:
                raise ConfigError("config: give a configuration file or --structure")
            config = _apply_flags(config, args)
            if args.timestep is not None:
                parse_quantity("--timestep", args.timestep, TIME_UNITS)
            mode = "resume" if args.resume else "overwrite" if args.overwrite else "new"
            return Run(check_config(config, trust=args.trust), mode=mode,
                       config_path=args.config, resume_hint=_resume_hint(args)).execute()
        if args.command == "relax":
            mode = "resume" if args.resume else "overwrite" if args.overwrite else "new"
            return relax_only(_apply_flags(load_config(args.config), args), trust=args.trust,
                              mode=mode, config_path=args.config)
        if args.command == "bias":
            return bias_command(args)
        if args.command == "export-lammps":
            config = _apply_flags(load_config(args.config), args)
            directory = Path(args.directory)
            _check_deck_directory(directory, Path(args.config), args.overwrite)
            return _export(check_config(config, trust=args.trust), directory)
    except (ConfigError, OutputError, LogError) as err:
        print(f"rigidmd: error: {err}", file=sys.stderr)
        return 2
    except ImportError as err:  # an optional extra (lammps, MDAnalysis) is missing
        if os.environ.get("RIGIDMD_DEBUG"):
            raise
        print(f"rigidmd: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2
    except RelaxationStopped as err:  # a stop signal in a run's relaxation: said already
        return err.status
    except RunStopped as err:
        # The run started and stopped: a failed write, a failure in a step.  The message
        # names the step and the checkpoint to continue from.
        print(_stopped(args.command, err), file=sys.stderr)
        return 1
    except LammpsError as err:
        if os.environ.get("RIGIDMD_DEBUG"):
            raise
        message = " ".join(str(err).split())  # LAMMPS's message spans lines
        if err.setup:  # the commands, the cut-off for the box, ...: the input
            print(f"rigidmd: error: {message}", file=sys.stderr)
            return 2
        print(f"rigidmd: run stopped: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        # Ctrl-C before the steps began (reading, building the calculator, relaxing): no run
        # started, so there is nothing to continue.  A further Ctrl-C (a second press while
        # slow imports ran) has nothing left to stop: ignored while the line is written.
        with _further_ctrl_c_ignored():
            print(f"rigidmd: interrupted before the {args.command} started", file=sys.stderr)
        return 130
    except (NonFiniteForceError, ConvergenceError, RelaxationNotConverged,
            RelaxationFailed) as err:
        # The run stopped; its outputs and checkpoint hold every step before the failure.
        print(_stopped(args.command, err), file=sys.stderr)
        return 1
    except OSError as err:
        if os.environ.get("RIGIDMD_DEBUG"):
            raise
        print(f"rigidmd: error: {describe_os_error(err)}", file=sys.stderr)
        return 1
    except (ValueError, TypeError) as err:
        # Raised by rigidmd before anything runs: a bad body definition, mass, ...
        if os.environ.get("RIGIDMD_DEBUG"):
            raise
        print(f"rigidmd: error: {err}", file=sys.stderr)
        return 2
    return 1  # pragma: no cover - argparse requires a command


if __name__ == "__main__":  # pragma: no cover
    from rigidmd.run.signals import run_command

    sys.exit(run_command(main))
