"""Shows: the Monte Carlo barostat, on a calculator without stress, gives TIP4P/2005's density.

The Monte Carlo barostat on TIP4P/2005 water with a calculator that hides its stress.

216 rigid TIP4P/2005 waters (M explicit, massless), LAMMPS forces through
:class:`rigidmd.lammps.LAMMPSCalculator` (lj/cut/coul/long 8.5 Å, tail
corrections, PPPM 1e-5; as ``examples/tip4p2005.py``), 298 K and 1 bar,
2 fs steps, from one quenched lattice start:

1. :class:`rigidmd.RigidMCBarostat` (Bussi thermostat, taut 0.5 ps; a volume
   move every 25 steps) with the calculator wrapped in :class:`HiddenStress`,
   which offers energy and forces only (what ASE's TIP4P or an ML wrapper
   offers): mean density against 0.9979 g/cm³ (Abascal & Vega 2005);
2. :class:`rigidmd.RigidCRescale` (every 10 steps, the example's settings)
   with the plain calculator, the same lengths: the same density?
3. cost: calculator calls per step, and ms per step of RigidMCBarostat
   (every 25, move sizes frozen) against ``RigidBussi`` (NVT) on the same
   wrapped calculator, interleaved, best of ``--rounds``; with ``--engine``,
   the same with :class:`rigidmd.lammps.LAMMPSEngine` (LAMMPS in its own
   process, one rank), CPU time then of this process and its children.

Run ``python validation/mc_barostat.py`` (``--equilibration-ps``,
``--production-ps``; about 20 minutes with the defaults on a shared
machine); the results are written to ``validation/mc_barostat.txt`` (``--output``) when the
run is complete, the lines so far to ``mc_barostat.txt.partial`` until then.
"""

import argparse
import contextlib
import os
import sys
import time
from pathlib import Path

import numpy as np
from ase import units
from ase.calculators.calculator import Calculator, all_changes

from rigidmd import RigidBussi, RigidCRescale, RigidLangevin, RigidMCBarostat
from rigidmd.ipi import processes
from rigidmd.lammps import LAMMPSCalculator, LAMMPSEngine
from rigidmd.systems import water_box
from rigidmd.water import water_model

sys.path.insert(0, str(Path(__file__).resolve().parent))  # arguments.py, beside this script
from arguments import at_least_zero, positive, whole  # noqa: E402

MODEL = water_model("tip4p2005")
T, P_BAR, PUBLISHED = 298.0, 1.0, 0.9979
PS = 1000 * units.fs
DT = 2 * units.fs
BLOCKS = 10  # of the density's block average


def lammps(engine=False):
    kind = LAMMPSEngine if engine else LAMMPSCalculator
    return kind(MODEL.lammps_commands(8.5, "pppm", 1e-5, tail=True),
                atom_types={"O": 1, "H": 2, "X": 3})


def cpu_seconds():
    """CPU time (s) of this process and all its descendants (an engine's ``lmp``), from /proc."""
    return time.process_time() + processes.cpu_seconds(processes.descendants(os.getpid()))


class HiddenStress(Calculator):
    """Energy and forces of another calculator, without its stress; counts the calls."""

    implemented_properties = ["energy", "free_energy", "forces"]

    def __init__(self, inner):
        super().__init__()
        self.inner = inner
        self.calls = 0

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.calls += 1
        wanted = [p for p in properties if p in self.implemented_properties]
        self.inner.calculate(self.atoms, wanted or ["energy"], system_changes)
        self.results = {k: v for k, v in self.inner.results.items() if k != "stress"}


def block_average(values, blocks=BLOCKS):
    means = np.array([b.mean() for b in np.array_split(np.asarray(values), blocks)])
    return float(means.mean()), float(means.std(ddof=1) / np.sqrt(blocks))


def start(seed=1):
    atoms = water_box(6, seed=seed, model="tip4p2005")
    atoms.set_initial_charges(MODEL.charges(len(atoms) // 4))
    atoms.calc = lammps()
    RigidLangevin(atoms, 0.5 * units.fs, temperature_K=T, friction=0.05 / units.fs,
                  rng=np.random.default_rng(seed), fixcm=False).run(400)
    atoms.calc = None
    return atoms


def density_run(atoms, kind, eq_ps, prod_ps, out):
    rng = np.random.default_rng(2)
    if kind == "mc":
        atoms.calc = HiddenStress(lammps())
        dyn = RigidMCBarostat(atoms, DT, T, P_BAR * units.bar, 0.5 * PS, every=25, rng=rng,
                              adapt_moves=200)
        every = 25
    else:
        atoms.calc = lammps()
        dyn = RigidCRescale(atoms, DT, T, P_BAR * units.bar, taut=0.5 * PS, taup=2.0 * PS,
                            compressibility_au=4.5e-5 / units.bar, rng=rng, every=10)
        every = 10
    t0 = time.perf_counter()
    dyn.run(int(eq_ps * PS / DT))
    densities = []
    dyn.attach(lambda: densities.append(dyn.get_density()), interval=every)
    n = int(prod_ps * PS / DT)
    dyn.run(n)
    elapsed = time.perf_counter() - t0
    mean, err = block_average(densities)
    deviation = 100 * (mean / PUBLISHED - 1)
    line = (f"{kind:>9}: density {mean:.4f} ± {err:.4f} g/cm³ ({deviation:+.2f} % "
            f"from {PUBLISHED}), {eq_ps:g} ps equilibration + {prod_ps:g} ps, "
            f"{1e3 * elapsed / (n + eq_ps * PS / DT):.1f} ms/step")
    if kind == "mc":
        b = dyn.barostat
        line += (f"; acceptance {100 * b.acceptance:.1f} % over {b.attempted.sum()} moves, "
                 f"move size ln V ± {b.steps[0]:.4f} (frozen after {b.adapt_moves} moves)")
    out(line)
    return mean, err


def cost(atoms, rounds, steps, out, engine=False):
    """ms per step (wall and CPU) and calculator calls per step: NVT Bussi against the MC barostat.

    CPU time of this process (LAMMPS runs in it, or in a child with ``engine``)
    is less disturbed by other jobs on a shared machine than wall time.
    """
    wall = {"bussi": [], "mc": []}
    cpu = {"bussi": [], "mc": []}
    calls, acceptance = {}, []
    for _ in range(rounds):
        for kind in ("bussi", "mc"):
            copy = atoms.copy()
            inner = lammps(engine)
            calc = HiddenStress(inner)
            copy.calc = calc
            # With the engine, the with block stops it: no lmp outlives the round.
            with inner if engine else contextlib.nullcontext():
                if kind == "bussi":
                    dyn = RigidBussi(copy, DT, T, 0.5 * PS, rng=np.random.default_rng(3))
                else:
                    # The move size the density run froze at (about 45 % accepted).
                    dyn = RigidMCBarostat(copy, DT, T, P_BAR * units.bar, 0.5 * PS, every=25,
                                          rng=np.random.default_rng(3), adapt_moves=0,
                                          step=0.0236)
                dyn.run(25)  # LAMMPS set-up (the engine's start), compilation
                calls0, t0, c0 = calc.calls, time.perf_counter(), cpu_seconds()
                dyn.run(steps)
                wall[kind].append(1e3 * (time.perf_counter() - t0) / steps)
                cpu[kind].append(1e3 * (cpu_seconds() - c0) / steps)
            calls[kind] = (calc.calls - calls0) / steps
            if kind == "mc":
                acceptance.append(dyn.barostat.acceptance)
    where = "LAMMPSEngine (own process, 1 rank)" if engine else "LAMMPSCalculator (in-process)"
    out(f"cost with {where}, {steps} steps, {rounds} interleaved rounds, best of each "
        "(ms per step; calculator calls per step):")
    for kind, label in (("bussi", "RigidBussi (NVT)        "), ("mc", "RigidMCBarostat every 25")):
        line = (f"  {label} wall {min(wall[kind]):7.2f} ms  CPU {min(cpu[kind]):7.2f} ms  "
                f"{calls[kind]:.3f} calls")
        if kind == "mc":
            line += (f"  overhead wall {100 * (min(wall['mc']) / min(wall['bussi']) - 1):+.1f} %, "
                     f"CPU {100 * (min(cpu['mc']) / min(cpu['bussi']) - 1):+.1f} %; "
                     f"acceptance {100 * np.mean(acceptance):.0f} %")
        out(line)
    out(f"  all rounds CPU: bussi {', '.join(f'{v:.2f}' for v in cpu['bussi'])}; "
        f"mc {', '.join(f'{v:.2f}' for v in cpu['mc'])}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--equilibration-ps", type=at_least_zero, default=20.0)
    p.add_argument("--production-ps", type=positive, default=60.0,
                   help=f"at least {BLOCKS} density samples (one every 25 steps of 2 fs)")
    p.add_argument("--rounds", type=whole(1), default=3)
    p.add_argument("--cost-steps", type=whole(1), default=500)
    p.add_argument("--engine", action="store_true",
                   help="cost with LAMMPSEngine (LAMMPS in its own process)")
    p.add_argument("--only", choices=("mc", "crescale", "cost"), action="append")
    p.add_argument("--output", type=Path,
                   default=Path(__file__).with_name("mc_barostat.txt"),
                   help="replaced at the end of a complete run (until then the lines are in "
                        "OUTPUT.partial)")
    args = p.parse_args(argv)
    only = args.only or ["cost", "mc", "crescale"]
    # The density runs' block averages need BLOCKS samples (MC: one every 25 steps).
    samples = int(args.production_ps * PS / DT) // 25
    if {"mc", "crescale"} & set(only) and samples < BLOCKS:
        p.error(f"argument --production-ps: {args.production_ps:g} ps gives {samples} density "
                f"samples, fewer than the {BLOCKS} blocks (at least "
                f"{BLOCKS * 25 * DT / PS:g} ps)")
    if not args.output.parent.is_dir():
        p.error(f"argument --output: no folder {args.output.parent}")
    # The lines go to OUTPUT.partial as they come; it replaces OUTPUT only when the run is
    # complete, so a failed or interrupted run leaves the results file as it was.
    partial = args.output.with_name(args.output.name + ".partial")
    lines = []

    def out(text):
        print(text, flush=True)
        lines.append(text)
        partial.write_text("\n".join(lines) + "\n")

    try:
        out(f"216 TIP4P/2005 waters, LAMMPS lj/cut/coul/long 8.5 + tail + pppm 1e-5, {T:g} K, "
            f"{P_BAR:g} bar, 2 fs; one core, other jobs on the machine (absolute times "
            "pessimistic)")
        out(f"command: python {' '.join(sys.argv)}")
        atoms = start()
        if "cost" in only:
            cost(atoms, args.rounds, args.cost_steps, out, args.engine)
        for kind in ("mc", "crescale"):
            if kind in only:
                mean, err = density_run(atoms.copy(), kind, args.equilibration_ps,
                                        args.production_ps, out)
                if not np.isfinite([mean, err]).all():
                    raise SystemExit(f"mc_barostat.py: the {kind} run's density is not finite")
    except BaseException:
        print(f"mc_barostat.py: stopped before the end: {args.output} is left as it was; "
              f"the lines so far are in {partial}", file=sys.stderr, flush=True)
        raise
    os.replace(partial, args.output)


if __name__ == "__main__":
    main()
