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

Run ``python benchmarks/lammps_engine.py`` (20 minutes on a 2-core machine
busy with other jobs); the tables are stored in ``benchmarks/lammps_engine.txt``.
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
STEPS = {216: 200, 1728: 40}
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


def one_core(atoms, steps, rounds):
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
    args = parser.parse_args()
    lines = [f"lj/cut/coul/long 9.0 + pppm 1e-5, 1 fs, 298 K thermal rigid start; best of "
             f"{args.rounds} interleaved rounds; 2-core machine shared with other jobs; "
             "CPU: all processes of the run"]
    npt = {name: "native NPT (fix rigid/npt/small iso)" for name in (
        "RigidNPT (MTK iso) LAMMPSCalculator", "RigidNPT (MTK iso) LAMMPSEngine",
        "RigidCRescale every 1, LAMMPSCalculator", "RigidCRescale every 1, LAMMPSEngine",
        "RigidCRescale every 10, LAMMPSCalculator", "RigidCRescale every 10, LAMMPSEngine")}
    for replicas in args.sizes:
        atoms = water_box(replicas)
        n = len(atoms) // 3
        results = one_core(atoms, STEPS[n], args.rounds)
        lines += [""] + table(f"{n} waters, one core ({STEPS[n]} steps)", results,
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
        lines += [""] + table("1728 waters, two cores (ratios to native on the same 2 ranks, "
                              "or threads)", results, "native NVE, 2 MPI ranks",
                              "LAMMPS force time, 2 ranks", ratios)
        print("\n".join(lines[-len(results) - 2:]), flush=True)
    (Path(__file__).with_suffix(".txt")).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
