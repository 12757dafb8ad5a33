"""rigidmd driven by LAMMPS forces, against LAMMPS running alone (one core).

Liquid TIP3P from ``tests/data/water_box_27.traj`` replicated to 216, 1728
and 5832 waters; ``lj/cut/coul/long 9.0`` and PPPM at 1e-5; 1 fs steps.
Per water count, side by side in one run, each measured ``--rounds`` times
in turn (the median is reported):

* native LAMMPS ``fix rigid/nve/small`` (the whole step: LAMMPS's loop time),
  with its Pair, Kspace and Neigh times (the floor: LAMMPS's own force work);
* rigidmd ``RigidVerlet`` with :class:`rigidmd.lammps.LAMMPSCalculator`,
  and the share of its step spent inside LAMMPS (the rest is Python);
* rigidmd ``RigidVerlet`` with ASE's ``LAMMPSlib`` (not at 5832 waters
  unless ``--lammpslib-all``: it takes minutes).

Then NPT at 1728 waters and 1 atm: native ``fix rigid/npt/small`` against
``RigidNPT`` (MTK, the cell moves every step) and ``RigidCRescale`` moving
the cell every step and every 10 steps.

Run ``python benchmarks/lammps_engine.py`` (about 5 minutes); the table
printed is stored in ``benchmarks/lammps_engine.txt``.
"""

import argparse
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
from rigidmd.coupling.barostats import MTKBarostat
from rigidmd.coupling.thermostats import NoseHooverThermostat
from rigidmd.lammps import LAMMPSCalculator, export_lammps, run_rigid_reference, tip3p_charges
from rigidmd.lammps.engine import LAMMPSEngine, lammps_executable

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["pair_style lj/cut/coul/long 9.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956819 3.15061", "kspace_style pppm 1e-5"]  # O is type 1
EXCLUDE = ["neigh_modify exclude molecule/intra all"]
STEPS = {216: 200, 1728: 40}
NPT_PARTS = [NoseHooverThermostat(298, 100 * units.fs),
             MTKBarostat(298, 1.01325 * units.bar, 1000 * units.fs)]


def water_box(replicas):
    base = read(ROOT / "tests" / "data" / "water_box_27.traj")
    base.positions = RigidBodies.resolve(base, "tags").whole_positions(base)
    atoms = base.repeat(replicas)
    n = len(atoms) // 3
    atoms.set_tags(np.repeat(np.arange(1, n + 1), 3))
    atoms.set_initial_charges(tip3p_charges(atoms))
    rigid_maxwell_boltzmann(atoms, 298, bodies="tags", rng=np.random.default_rng(0))
    return atoms


def native(atoms, steps, fix="rigid/nve/small", couplings=()):
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    ref = run_rigid_reference(atoms, body_ids, COMMANDS + EXCLUDE, units.fs, steps, every=steps,
                              fix=fix, ase_constants=False, couplings=couplings)
    sections = {k: v / steps for k, v in ref.timing["sections"].items()}
    return ref.timing["loop_time"] / steps, sections


def timed(dyn, steps):
    dyn.run(3)  # set-up and the first neighbour list out of the timing
    start = time.perf_counter()
    dyn.run(steps)
    return (time.perf_counter() - start) / steps


def engine_run(atoms, kind, steps, **options):
    """rigidmd with LAMMPSEngine (LAMMPS in its own process): NVE, MTK or C-rescale."""
    a = atoms.copy()
    with LAMMPSEngine(COMMANDS, **options) as calc:
        a.calc = calc
        return timed(dynamics(a, kind), steps)


def dynamics(a, kind):
    if kind == "nve":
        return RigidVerlet(a, units.fs, bodies="tags")
    if kind == "mtk":
        return RigidNPT(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                        1000 * units.fs, bodies="tags")
    return RigidCRescale(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                         1000 * units.fs, 4.5e-5 / units.bar, bodies="tags",
                         rng=np.random.default_rng(1), every=int(kind[len("crescale"):]))


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
        text = (Path(tmp) / "log.lammps").read_text()
    loop = float(re.search(r"^Loop time of (\S+)", text, re.MULTILINE).group(1))
    sections = {m.group(1): float(m.group(2)) for m in re.finditer(
        r"^(Pair|Kspace|Neigh)\s*\|\s*\S+\s*\|\s*(\S+)", text, re.MULTILINE)}
    return loop / steps, sum(sections.values()) / steps


def best(function, rounds, *args, **kwargs):
    return min(function(*args, **kwargs) for _ in range(rounds))


def one_core(atoms, steps, rounds):
    """Best of ``rounds`` (interleaved) ms per step of each run on one core."""
    runs = {
        "native NVE (fix rigid/nve/small)": lambda: native(atoms, steps)[0],
        "LAMMPS force time (Pair+Kspace+Neigh)": lambda: sum(
            v for k, v in native(atoms, steps)[1].items() if k in ("Pair", "Kspace", "Neigh")),
        "NVE LAMMPSCalculator": lambda: calc_run(atoms, "nve", steps),
        "NVE LAMMPSEngine": lambda: engine_run(atoms, "nve", steps),
        "native NPT (fix rigid/npt/small iso)": lambda: native(
            atoms, steps, "rigid/npt/small", NPT_PARTS)[0],
        "RigidNPT (MTK iso) LAMMPSCalculator": lambda: calc_run(atoms, "mtk", steps // 2),
        "RigidNPT (MTK iso) LAMMPSEngine": lambda: engine_run(atoms, "mtk", steps),
        "RigidCRescale every 1, LAMMPSEngine": lambda: engine_run(atoms, "crescale1", steps),
        "RigidCRescale every 10, LAMMPSEngine": lambda: engine_run(atoms, "crescale10", steps),
        "RigidCRescale every 10, LAMMPSCalculator": lambda: calc_run(atoms, "crescale10",
                                                                     steps),
    }
    times = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            times[name].append(run())
    return {name: min(v) for name, v in times.items()}


def two_cores(atoms, steps, rounds):
    runs = {
        "native NVE, 1 rank": lambda: native_parallel(atoms, steps)[0],
        "native NVE, 2 MPI ranks": lambda: native_parallel(atoms, steps, processes=2)[0],
        "LAMMPS force time, 2 ranks": lambda: native_parallel(atoms, steps, processes=2)[1],
        "NVE LAMMPSEngine(processes=2)": lambda: engine_run(atoms, "nve", steps, processes=2),
        "native NVE, 2 OpenMP threads": lambda: native_parallel(atoms, steps, threads=2)[0],
        "NVE LAMMPSCalculator(threads=2)": lambda: calc_run(atoms, "nve", steps, threads=2),
        "NVE LAMMPSEngine(threads=2)": lambda: engine_run(atoms, "nve", steps, threads=2),
    }
    times = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            times[name].append(run())
    return {name: min(v) for name, v in times.items()}


def table(title, results, native_key, floor_key, ratios):
    lines = [title, f"{'run':>42} {'ms/step':>8} {'/native':>8} {'/floor':>7}"]
    for name, t in results.items():
        ref = results[ratios.get(name, native_key)]
        lines.append(f"{name:>42} {1e3 * t:8.2f} {t / ref:8.3f} {t / results[floor_key]:7.3f}")
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="*", default=[2, 4],
                        help="replicas of the 27-water box per direction")
    parser.add_argument("--no-two-cores", action="store_true")
    args = parser.parse_args()
    lines = [f"lj/cut/coul/long 9.0 + pppm 1e-5, 1 fs, 298 K thermal rigid start; best of "
             f"{args.rounds} interleaved rounds; the 2-core machine shared with other jobs"]
    npt = {name: "native NPT (fix rigid/npt/small iso)" for name in (
        "RigidNPT (MTK iso) LAMMPSCalculator", "RigidNPT (MTK iso) LAMMPSEngine",
        "RigidCRescale every 1, LAMMPSEngine", "RigidCRescale every 10, LAMMPSEngine",
        "RigidCRescale every 10, LAMMPSCalculator", "native NPT (fix rigid/npt/small iso)")}
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
        lines += [""] + table("1728 waters, two cores (ratios: to native on the same 2 ranks or "
                              "threads)", results, "native NVE, 2 MPI ranks",
                              "LAMMPS force time, 2 ranks", ratios)
        print("\n".join(lines[-len(results) - 2:]), flush=True)
    (Path(__file__).with_suffix(".txt")).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
