"""TIP4P/2005 water at 298 K and 1 bar: density and diffusion against the published values.

A periodic box of rigid four-site TIP4P/2005 waters (216 by default) with the
M site as an explicit massless atom in each rigid body, forces from LAMMPS
through :class:`rigidmd.lammps.LAMMPSCalculator` with the interactions of
Abascal & Vega (J. Chem. Phys. 123, 234505 (2005)): Lennard-Jones between
oxygens and real-space Coulomb cut at 8.5 Å, long-range Lennard-Jones
corrections to energy and pressure, long-range electrostatics (PPPM here,
Ewald there).  The lattice start is quenched with Langevin friction, then
:class:`rigidmd.RigidCRescale` (Bussi thermostat, stochastic cell rescaling)
equilibrates and samples at 298 K and 1 bar with a 2 fs step.

Printed and written to ``tip4p2005_results.json`` in ``--outdir`` (the centres
of mass every 0.1 ps and the densities in ``tip4p2005_com.npz``): the mean
density with its standard error (block averages), beside 0.9979 g/cm³
(Abascal & Vega 2005), and the self-diffusion coefficient of the molecular
centres of mass (Einstein relation, from the production run) beside 0.21 Å²/ps
for 216 molecules at 298 K (SklogWiki, citing the same authors).

Run (about 25 minutes, LAMMPS on one core; ``--quick`` about 15 s)::

    python examples/tip4p2005.py [--outdir DIR] [--quick]
        [--equilibration-ps 20] [--production-ps 200]

Each phase reports its progress.  Ctrl-C or SIGTERM finishes the step under way, writes a
checkpoint and the series so far (``tip4p2005_checkpoint.npz``, ``tip4p2005_state.json``)
and says how to continue: ``--resume`` with the same ``--outdir`` goes on from there, with
the run's own arguments, to the results an uninterrupted run gives (to roundoff: LAMMPS
sums its forces in the order of the lists a new instance builds).  (A stop during
the quench, seconds long, keeps nothing: run again.)
"""

import argparse
import json
import signal
import sys
import time
from pathlib import Path

import numpy as np
from ase import units

from rigidmd import RigidCRescale, RigidLangevin, load_checkpoint
from rigidmd.core.logger import RigidLogger
from rigidmd.lammps import LAMMPSCalculator
from rigidmd.systems import water_box
from rigidmd.water import water_model

MODEL = water_model("tip4p2005")
TEMPERATURE_K = 298.0
PRESSURE_BAR = 1.0
#: Abascal & Vega (2005), Table I: 298 K, 1 bar.
PUBLISHED_DENSITY = 0.9979
#: Å²/ps, 216 molecules at 298 K (SklogWiki "TIP4P/2005 model of water"); experiment 0.23.
PUBLISHED_DIFFUSION = 0.21
#: Isothermal compressibility of water, for the barostat's response (Å³/eV).
COMPRESSIBILITY = 4.5e-5 / units.bar
PS = 1000 * units.fs
#: What a stopped run keeps in --outdir to continue (removed when it ends).
STATE, CHECKPOINT = "tip4p2005_state.json", "tip4p2005_checkpoint.npz"


def calculator(cutoff, accuracy):
    """LAMMPS forces of TIP4P/2005 with explicit M sites (types O 1, H 2, M 3)."""
    return LAMMPSCalculator(MODEL.lammps_commands(cutoff, "pppm", accuracy, tail=True),
                            atom_types={"O": 1, "H": 2, "X": 3})


def block_average(values, blocks=10):
    """Mean and its standard error from ``blocks`` consecutive block means (the mean is
    the series' own: blocks of unequal length would weight their values unequally)."""
    values = np.asarray(values)
    means = np.array([b.mean() for b in np.array_split(values, blocks)])
    return float(values.mean()), float(means.std(ddof=1) / np.sqrt(blocks))


def diffusion(com, masses, frame_ps, fit_ps):
    """D (Å²/ps) from the mean-squared displacement of unwrapped centres of mass.

    The stochastic thermostat leaves the box's total momentum to wander (and no
    thermostat may fix it under a barostat), so each frame's centres of mass are
    taken relative to the system's.  Every frame is a time origin; MSD(t) = 6 D t
    is fitted (least squares, through its own intercept) over lags
    ``fit_ps = (t0, t1)``.  Returns D and the three per-axis estimates (2 D t
    each), whose spread is a rough error.
    """
    com = np.asarray(com)
    com = com - np.einsum("b,fbi->fi", masses, com)[:, None, :] / masses.sum()
    lags = np.arange(1, len(com))
    per_axis = np.array([np.mean((com[k:] - com[:-k]) ** 2, axis=(0, 1)) for k in lags])
    t = lags * frame_ps
    window = (t >= fit_ps[0]) & (t <= fit_ps[1])
    slopes = np.polyfit(t[window], per_axis[window], 1)[0] / 2.0  # (3,) per axis
    return float(slopes.mean()), slopes.tolist()


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--outdir", type=Path, default=Path("."), help="output directory")
    p.add_argument("--n-side", type=int, default=6, help="waters per box edge (6: 216)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--cutoff", type=float, default=8.5, help="real-space cut-off (Å)")
    p.add_argument("--accuracy", type=float, default=1e-5, help="PPPM relative accuracy")
    p.add_argument("--timestep-fs", type=float, default=2.0)
    p.add_argument("--quench-ps", type=float, help="default 0.2 (--quick: 0.05)")
    p.add_argument("--equilibration-ps", type=float, help="default 20 (--quick: 0.4)")
    p.add_argument("--production-ps", type=float,
                   help="default 200 (--quick: 1); at least 1 (the diffusion fit)")
    p.add_argument("--quick", action="store_true",
                   help="a short smoke run: 0.05 ps quench, 0.4 ps equilibration, 1 ps "
                        "production (a time given explicitly is kept)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run stopped in --outdir, with its own arguments")
    args = p.parse_args(argv)
    if args.resume:
        given = [a for a in (argv if argv is not None else sys.argv[1:])
                 if a.startswith("--") and a.split("=")[0] not in ("--outdir", "--resume")]
        if given:
            p.error(f"argument --resume: the run continues with its own arguments; leave "
                    f"out {' '.join(given)}")
        state = args.outdir / STATE
        if not state.is_file():
            p.error(f"argument --resume: no stopped run in {args.outdir} (no {STATE})")
        return argparse.Namespace(**json.loads(state.read_text())["arguments"],
                                  outdir=args.outdir, resume=True)
    times = {"quench_ps": (0.2, 0.05), "equilibration_ps": (20.0, 0.4),
             "production_ps": (200.0, 1.0)}
    for key, (full, quick) in times.items():
        if getattr(args, key) is None:
            setattr(args, key, quick if args.quick else full)
    for key in ("timestep_fs", *times):
        if not 0 < getattr(args, key) < float("inf"):
            p.error(f"argument --{key.replace('_', '-')}: must be positive, got "
                    f"{getattr(args, key)}")
    if args.production_ps < 1.0:  # lags of 0.2-0.4 of it, 0.1 ps apart: 3 at least
        p.error(f"argument --production-ps: the diffusion fit needs at least 1 ps, got "
                f"{args.production_ps:g}")
    if args.n_side < 1:
        p.error(f"argument --n-side: must be at least 1, got {args.n_side}")
    return args


class Stop:
    """SIGINT and SIGTERM ask the run to stop after the step under way."""

    def __init__(self):
        self.signal = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self.ask)

    def ask(self, signum, frame):
        self.signal = signal.Signals(signum).name
        print(f"{self.signal}: stopping after the step under way", flush=True)


def run_phase(dyn, name, first, last, stop, log):
    """Steps ``first`` to ``last`` of the run (``dyn.nsteps`` counts from the start of the
    equilibration), ten at a time (a cell move's interval), with a progress line at each
    quarter; False when asked to stop."""
    reports = [first + (last - first) * q // 4 for q in (1, 2, 3)]
    dt_ps = dyn.dt / PS
    while dyn.nsteps < last:
        if stop.signal:
            return False
        due = min([r for r in reports if r > dyn.nsteps] + [last])
        dyn.run(min(10, due - dyn.nsteps))
        if dyn.nsteps in reports:
            log(f"{name} {(dyn.nsteps - first) * dt_ps:g} / {(last - first) * dt_ps:g} ps")
    return True


def keep(dyn, outdir, args, densities, com):
    """The checkpoint, the series so far and the arguments: what --resume continues."""
    dyn.save_checkpoint(outdir / CHECKPOINT)
    np.savez(outdir / "tip4p2005_series.npz", densities=np.array(densities),
             com=np.array(com).reshape(-1, len(dyn.model.mass), 3))
    arguments = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                 if k not in ("outdir", "resume")}
    (outdir / STATE).write_text(json.dumps({"arguments": arguments, "nsteps": dyn.nsteps},
                                           indent=1) + "\n")


def main(argv=None):
    args = parse(argv)
    outdir = args.outdir
    outdir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    def log(text):
        print(f"[{time.perf_counter() - start:7.1f} s] {text}", flush=True)

    stop = Stop()
    dt = args.timestep_fs * units.fs
    n_eq = int(args.equilibration_ps * PS / dt)
    every = 10  # cell moves every 10 steps: LAMMPS's PPPM set-up paid once per 10 steps
    n_eq = -(-n_eq // every) * every  # (whole cell-move intervals)
    n_prod = int(args.production_ps * PS / dt)
    densities, com = [], []
    logfile = str(outdir / "tip4p2005.log")
    if args.resume:
        dyn = load_checkpoint(outdir / CHECKPOINT, calculator(args.cutoff, args.accuracy))
        # the log goes on where it stopped, without a second header
        dyn.attach(dyn.closelater(RigidLogger(dyn, logfile, pressure=True, header=False)),
                   max(int(PS / dt), 1))
        with np.load(outdir / "tip4p2005_series.npz") as series:
            densities, com = list(series["densities"]), list(series["com"])
        atoms = dyn.atoms
        n = len(atoms) // 4
        log(f"resuming at {dyn.nsteps * args.timestep_fs / 1000:g} ps of "
            f"{(n_eq + n_prod) * args.timestep_fs / 1000:g}")
    else:
        earlier = [outdir / name for name in ("tip4p2005.log", "tip4p2005_results.json",
                                              "tip4p2005_com.npz", STATE)
                   if (outdir / name).exists()]
        if earlier:  # (the log was appended to, mixing two runs)
            print(f"replacing an earlier run's {', '.join(p.name for p in earlier)} in "
                  f"{outdir}", flush=True)
            for name in ("tip4p2005.log", STATE, CHECKPOINT, "tip4p2005_series.npz"):
                (outdir / name).unlink(missing_ok=True)
        atoms = water_box(args.n_side, seed=args.seed, model="tip4p2005")
        n = len(atoms) // 4
        atoms.set_initial_charges(MODEL.charges(n))
        box = float(atoms.cell.lengths()[0])
        if args.cutoff > box / 2:
            raise SystemExit(f"--cutoff {args.cutoff} Å is more than half the box "
                             f"({box:.2f} Å)")
        atoms.calc = calculator(args.cutoff, args.accuracy)
        log(f"{n} TIP4P/2005 waters (M explicit, massless) in a {box:.2f} Å box; "
            f"lj/cut/coul/long {args.cutoff:g} Å, tail corrections, pppm {args.accuracy:g}")
        rng = np.random.default_rng(args.seed)

        # Quench the random lattice: strong friction, short step.
        quench = RigidLangevin(atoms, 0.5 * units.fs, temperature_K=TEMPERATURE_K,
                               friction=0.05 / units.fs, rng=rng, fixcm=False)
        quench.run(max(int(args.quench_ps * PS / (0.5 * units.fs)), 1))
        if stop.signal:
            raise SystemExit(f"stopped ({stop.signal}) during the quench; nothing kept: run "
                             "again")
        dyn = RigidCRescale(atoms, dt, TEMPERATURE_K, PRESSURE_BAR * units.bar,
                            taut=0.5 * PS, taup=2.0 * PS, compressibility_au=COMPRESSIBILITY,
                            rng=rng, every=every, logfile=logfile,
                            loginterval=max(int(PS / dt), 1))

    frame_steps = max(int(0.1 * PS / dt), 1)  # centres of mass every 0.1 ps
    if dyn.nsteps < n_eq:
        if not run_phase(dyn, "equilibration", 0, n_eq, stop, log):
            return stopped(dyn, outdir, args, densities, com, stop)
        log(f"equilibrated {args.equilibration_ps:g} ps at {TEMPERATURE_K:g} K, "
            f"{PRESSURE_BAR:g} bar: {dyn.get_density():.4f} g/cm³")
    dyn.attach(lambda: densities.append(dyn.get_density()), interval=every)
    dyn.attach(lambda: com.append(dyn.com_positions.copy()), interval=frame_steps)
    t0, at = time.perf_counter(), dyn.nsteps
    if not run_phase(dyn, "production", n_eq, n_eq + n_prod, stop, log):
        return stopped(dyn, outdir, args, densities, com, stop)
    ms_per_step = 1e3 * (time.perf_counter() - t0) / max(dyn.nsteps - at, 1)
    density, density_err = block_average(densities)
    frame_ps = frame_steps * args.timestep_fs * 1e-3
    fit = (0.2 * args.production_ps, 0.4 * args.production_ps)
    np.savez_compressed(outdir / "tip4p2005_com.npz", com=np.array(com), masses=dyn.model.mass,
                        frame_ps=frame_ps, densities=np.array(densities))
    d, d_axes = diffusion(com, dyn.model.mass, frame_ps, fit)
    results = {
        "molecules": n, "production_ps": args.production_ps, "ms_per_step": ms_per_step,
        "density_g_cm3": density, "density_stderr": density_err,
        "published_density_g_cm3": PUBLISHED_DENSITY,
        "density_deviation_percent": 100 * (density / PUBLISHED_DENSITY - 1),
        "diffusion_A2_ps": d, "diffusion_per_axis_A2_ps": d_axes,
        "published_diffusion_A2_ps": PUBLISHED_DIFFUSION, "fit_ps": fit,
    }
    (outdir / "tip4p2005_results.json").write_text(json.dumps(results, indent=1) + "\n")
    for name in (STATE, CHECKPOINT, "tip4p2005_series.npz"):
        (outdir / name).unlink(missing_ok=True)
    log(f"production {args.production_ps:g} ps, {ms_per_step:.1f} ms/step")
    print(f"density   {density:.4f} ± {density_err:.4f} g/cm³  (Abascal & Vega 2005: "
          f"{PUBLISHED_DENSITY}; {results['density_deviation_percent']:+.2f} %)")
    print(f"diffusion {d:.3f} Å²/ps (x, y, z: {', '.join(f'{v:.3f}' for v in d_axes)}; "
          f"published for 216 molecules: {PUBLISHED_DIFFUSION}, experiment 0.23)")
    return results


def stopped(dyn, outdir, args, densities, com, stop):
    """Keep what --resume needs, say how to continue, and exit (130 for SIGINT, 143)."""
    keep(dyn, outdir, args, densities, com)
    dyn.close()
    total = args.equilibration_ps + args.production_ps
    print(f"stopped ({stop.signal}) at {dyn.nsteps * args.timestep_fs / 1000:g} ps of "
          f"{total:g}; continue with: python {sys.argv[0]} --outdir {outdir} --resume",
          flush=True)
    raise SystemExit(130 if stop.signal == "SIGINT" else 143)


if __name__ == "__main__":
    main()
