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
``lmp``) on 1 and on ``--ranks`` MPI ranks, ``LAMMPSCalculator`` (one
process) and ``LAMMPSEngine`` on 1 and on ``--ranks`` ranks, interleaved;
each ratio is to native LAMMPS on as many ranks.

The machine's load (``os.getloadavg``) is printed with every table: on a
shared machine compare the CPU columns, and re-measure on a quiet one.

Run ``python benchmarks/lammps_engine.py`` (20 minutes on a 2-core machine
busy with other jobs) or ``--quick`` (216 and 1728 waters, half the steps,
2 rounds, no C-rescale rows: about 5 minutes); ``--sizes 2 4 8`` adds
13,824 waters to every table, ``--ranks 16`` scales further on a larger
machine.  The tables are stored in ``benchmarks/lammps_engine.txt`` (not with
``--quick``, unless ``--save``).
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from ase import units
from ase.io import read

from rigidmd import RigidBodies, RigidCRescale, RigidNPT, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.couplings.barostats import MTKBarostat
from rigidmd.couplings.thermostats import NoseHooverThermostat
from rigidmd.lammps import LAMMPSCalculator, export_lammps, run_rigid_reference, tip3p_charges
from rigidmd.lammps.engine import LAMMPSEngine, lammps_executable

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["pair_style lj/cut/coul/long 9.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956819 3.15061", "kspace_style pppm 1e-5"]  # O is type 1
EXCLUDE = ["neigh_modify exclude molecule/intra all"]
STEPS = {216: 200, 1728: 40, 13824: 10}
NPT_PARTS = [NoseHooverThermostat(298, 100 * units.fs),
             MTKBarostat(298, 1.01325 * units.bar, 1000 * units.fs)]
TICK = os.sysconf("SC_CLK_TCK")


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
    """(wall, CPU, floor wall) per step from a LAMMPS log: loop time, CPU use, Pair+Kspace+Neigh."""
    loop = re.search(r"^Loop time of (\S+) on (\d+) procs", text, re.MULTILINE)
    cpu = re.search(r"^(\S+)% CPU use with (\d+) MPI tasks x (\d+) OpenMP", text, re.MULTILINE)
    floor = sum(float(m.group(2)) for m in re.finditer(
        r"^(Pair|Kspace|Neigh)\s*\|\s*\S+\s*\|\s*(\S+)", text, re.MULTILINE))
    wall = float(loop.group(1))
    share = float(cpu.group(1)) / 100 * int(cpu.group(2))  # cores busy on average
    return wall / steps, wall * share / steps, floor / steps


def native(atoms, steps, fix="rigid/nve/small", couplings=()):
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    with tempfile.TemporaryDirectory() as tmp:
        run_rigid_reference(atoms, body_ids, COMMANDS + EXCLUDE, units.fs, steps, every=steps,
                            fix=fix, ase_constants=False, couplings=couplings, workdir=tmp)
        return log_timing((Path(tmp) / "log.lammps").read_text(), steps)


def proc_cpu(pids):
    """CPU seconds (user + system) used so far by the processes ``pids``."""
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])
        except OSError:
            pass
    return total / TICK


def descendants(pid):
    parents = {}
    for p in os.listdir("/proc"):
        if p.isdigit():
            try:
                with open(f"/proc/{p}/stat") as f:
                    parents[int(p)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                pass
    found, frontier = [], [pid]
    while frontier:
        frontier = [p for p, parent in parents.items() if parent in frontier]
        found += frontier
    return found


def timed(dyn, steps, engine=None):
    """(wall, CPU) per step of ``dyn.run(steps)``, after 3 steps of set-up."""
    dyn.run(3)  # set-up and the first neighbour list out of the timing
    others = [] if engine is None else descendants(engine.pid)
    wall, cpu, other = time.perf_counter(), time.process_time(), proc_cpu(others)
    dyn.run(steps)
    wall = time.perf_counter() - wall
    cpu = time.process_time() - cpu + proc_cpu(others) - other
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
    """rigidmd with LAMMPSEngine (LAMMPS in its own process)."""
    a = atoms.copy()
    with LAMMPSEngine(COMMANDS, **options) as calc:
        a.calc = calc
        return timed(dynamics(a, kind), steps, engine=calc)


def calc_run(atoms, kind, steps, **options):
    a = atoms.copy()
    a.calc = LAMMPSCalculator(COMMANDS, **options)
    return timed(dynamics(a, kind), steps)


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
            cmd = [str(Path(sys.executable).parent / "mpirun"), "-np", str(processes)] + cmd
        subprocess.run(cmd, cwd=tmp, env=env, check=True)
        return log_timing((Path(tmp) / "log.lammps").read_text(), steps)


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


def scaling(atoms, steps, rounds, ranks):
    """NVE: native, in-process and engine on 1 and on ``ranks`` MPI ranks (wall, CPU)."""
    runs = {
        "native, 1 rank": lambda: native_parallel(atoms, steps)[:2],
        f"native, {ranks} ranks": lambda: native_parallel(atoms, steps, processes=ranks)[:2],
        "LAMMPSCalculator": lambda: calc_run(atoms, "nve", steps),
        "LAMMPSEngine, 1 rank": lambda: engine_run(atoms, "nve", steps),
        f"LAMMPSEngine, {ranks} ranks": lambda: engine_run(atoms, "nve", steps,
                                                           processes=ranks),
    }
    return interleaved(runs, rounds)


def scaling_table(rows, ranks):
    """One line per size: ms per step of native and ratios to native on as many ranks."""
    head = (f"{'waters':>7} {'native 1':>9} {'calc/nat':>9} {'eng/nat':>8} "
            f"{f'native {ranks}':>9} {f'eng{ranks}/nat{ranks}':>11}")
    lines = []
    for column, label in ((0, "wall"), (1, "CPU")):
        lines += [f"NVE, {label} time per step (ms) and ratios", head]
        for n, r in rows:
            one, many = r["native, 1 rank"][column], r[f"native, {ranks} ranks"][column]
            lines.append(
                f"{n:>7} {1e3 * one:9.2f} {r['LAMMPSCalculator'][column] / one:9.3f} "
                f"{r['LAMMPSEngine, 1 rank'][column] / one:8.3f} {1e3 * many:9.2f} "
                f"{r[f'LAMMPSEngine, {ranks} ranks'][column] / many:11.3f}")
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="*", default=[2, 4],
                        help="replicas of the 27-water box per direction")
    parser.add_argument("--no-two-cores", action="store_true")
    parser.add_argument("--no-scaling", action="store_true")
    parser.add_argument("--ranks", type=int, default=2, help="MPI ranks of the scaling table")
    parser.add_argument("--quick", action="store_true",
                        help="216 and 1728 waters, half the steps, 2 rounds, no C-rescale")
    parser.add_argument("--save", action="store_true", help="store the tables with --quick")
    args = parser.parse_args()
    if args.quick:
        args.rounds = min(args.rounds, 2)
        for n in STEPS:
            STEPS[n] //= 2
    lines = [f"lj/cut/coul/long 9.0 + pppm 1e-5, 1 fs, 298 K thermal rigid start; best of "
             f"{args.rounds} interleaved rounds; {os.cpu_count()} cores; CPU: all processes "
             f"of the run; at the start: {load()}"]
    npt = {name: "native NPT (fix rigid/npt/small iso)" for name in (
        "RigidNPT (MTK iso) LAMMPSCalculator", "RigidNPT (MTK iso) LAMMPSEngine",
        "RigidCRescale every 1, LAMMPSCalculator", "RigidCRescale every 1, LAMMPSEngine",
        "RigidCRescale every 10, LAMMPSCalculator", "RigidCRescale every 10, LAMMPSEngine")}
    for replicas in args.sizes:
        atoms = water_box(replicas)
        n = len(atoms) // 3
        results = one_core(atoms, STEPS[n], args.rounds, quick=args.quick)
        lines += [""] + table(f"{n} waters, one core ({STEPS[n]} steps; {load()})", results,
                              "native NVE (fix rigid/nve/small)",
                              "LAMMPS force time (Pair+Kspace+Neigh)", npt)
        print("\n".join(lines[-len(results) - 2:]), flush=True)
    if not args.no_two_cores:
        atoms = water_box(4)
        results = two_cores(atoms, STEPS[1728], args.rounds)
        ratios = {"native NVE, 1 rank": "native NVE, 1 rank",
                  "native NVE, 2 OpenMP threads": "native NVE, 2 OpenMP threads",
                  "NVE LAMMPSCalculator(threads=2)": "native NVE, 2 OpenMP threads",
                  "NVE LAMMPSEngine(threads=2)": "native NVE, 2 OpenMP threads"}
        lines += [""] + table(f"1728 waters, two cores (ratios to native on the same 2 ranks, "
                              f"or threads; {load()})", results, "native NVE, 2 MPI ranks",
                              "LAMMPS force time, 2 ranks", ratios)
        print("\n".join(lines[-len(results) - 2:]), flush=True)
    if not args.no_scaling:
        rows = []
        for replicas in args.sizes:
            atoms = water_box(replicas)
            n = len(atoms) // 3
            rows.append((n, scaling(atoms, STEPS[n], args.rounds, args.ranks)))
        block = scaling_table(rows, args.ranks)
        lines += ["", f"Scaling, NVE, best of {args.rounds} interleaved rounds ({load()})"] + block
        print("\n".join(lines[-len(block) - 1:]), flush=True)
    if args.save or not args.quick:
        (Path(__file__).with_suffix(".txt")).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
