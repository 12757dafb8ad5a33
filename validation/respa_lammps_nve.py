r"""NVE energy conservation of a two-level LAMMPS split against the outer step, 216 waters.

The split of ``respa_lammps_cost.py`` (fast level ``lammps_short_range_commands(r_split)``,
slow level the 9 Å PPPM model less it, two LAMMPS instances in one process) under
:class:`rigidmd.RigidVerlet`, from the same equilibrated start
(``water_openmm_long.start_tip4p2005.npz``, 298 K), for outer steps of 1-8 fs and k = 1
(the full model alone, single-step), 2, 4 and 8.  Per point over ``--ps``: the standard
deviation of the total energy and its drift (a straight line), both per water, and the force
calls per ps.  A fluctuation that grows faster than the outer step squared marks a
resonance.  The model is the production one (Lennard-Jones cut at 9 Å with the tail
correction, unshifted: each pair crossing the cut-off makes the energy jump, a floor under
the fluctuation at every step).

A short look, not the accuracy study (sampling against the time-step table's tolerances,
which needs CPU hours).  Writes ``respa_lammps_nve.json`` and ``.txt`` beside this script::

    python validation/respa_lammps_nve.py           # about 2 minutes on one idle core
    python validation/respa_lammps_nve.py --r-split 4 --lj-cut --out validation/respa_lammps_nve_4lj
    python validation/respa_lammps_nve.py --quick   # seconds
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402
from respa_lammps_cost import calculators, start_atoms  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
from arguments import positive  # noqa: E402

DT_FS = (1.0, 2.0, 4.0, 6.0, 8.0)
KS = (1, 2, 4, 8)


def run_point(dt_fs, k, calcs, ps):
    """One NVE run; the fluctuation and drift of its total energy (meV per water)."""
    from ase import units

    from rigidmd import RigidVerlet

    full, splits, counters = calcs
    split = next(iter(splits.values()))
    atoms = start_atoms()
    if k == 1:
        atoms.calc = full
    else:
        split.substeps = k
        atoms.calc = split
    dyn = RigidVerlet(atoms, dt_fs * units.fs)
    steps = max(int(round(ps * 1000 / dt_fs)), 2)
    every = max(int(round(4.0 / dt_fs)), 1)  # a sample every 4 fs or every step
    times, energies = [], []

    def sample():
        times.append(dyn.nsteps * dt_fs / 1000)
        energies.append(dyn.get_conserved_energy())

    dyn.attach(sample, interval=every)
    for c in counters.values():
        c.reset()
    cpu = time.process_time()
    dyn.run(steps)
    cpu = time.process_time() - cpu
    n = len(atoms) // 4
    e = np.array(energies) / n * 1000
    drift = np.polyfit(times, e, 1)[0] if len(e) > 2 else float("nan")
    sim_ps = steps * dt_fs / 1000
    fast = next(c for key, c in counters.items() if key != "full")
    return {"dt_fs": dt_fs, "k": k, "steps": steps, "std_meV_per_water": float(np.std(e)),
            "drift_meV_per_ps_per_water": float(drift),
            "fast_calls_per_ps": fast.calls / sim_ps,
            "full_calls_per_ps": counters["full"].calls / sim_ps,
            "cpu_ms_per_ps": 1000 * cpu / sim_ps}


def report(result) -> str:
    rows = {(r["dt_fs"], r["k"]): r for r in result["points"]}
    dts = sorted({r["dt_fs"] for r in result["points"]})
    ks = sorted({r["k"] for r in result["points"]})
    lines = [__doc__.splitlines()[0], "",
             f"fast level {result['fast']}; {result['ps']} ps per point; std of the total "
             "energy (drift of a straight line), meV per water; k = 1 is the full model "
             "alone.", "",
             "| outer step (fs) | " + " | ".join(f"k = {k}" for k in ks) + " |",
             "|---|" + "---|" * len(ks)]
    for dt in dts:
        cells = []
        for k in ks:
            r = rows.get((dt, k))
            cells.append("–" if r is None else f"{r['std_meV_per_water']:.3f} "
                         f"({r['drift_meV_per_ps_per_water']:+.2f})")
        lines.append(f"| {dt:g} | " + " | ".join(cells) + " |")
    lines += ["", "Exponent of the std against the outer step, between neighbouring steps "
              "(2: the r-RESPA error; far above 2: a resonance):", "",
              "| k | " + " | ".join(f"{a:g}→{b:g} fs" for a, b in zip(dts, dts[1:],
                                                                        strict=False)) + " |",
              "|---|" + "---|" * (len(dts) - 1)]
    for k in ks:
        cells = []
        for a, b in zip(dts, dts[1:], strict=False):
            ra, rb = rows.get((a, k)), rows.get((b, k))
            if ra is None or rb is None:
                cells.append("–")
                continue
            ratio = rb["std_meV_per_water"] / ra["std_meV_per_water"]
            cells.append(f"{np.log(ratio) / np.log(b / a):.2f}")
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ps", type=positive, default=0.5, help="simulated ps per point")
    ap.add_argument("--r-split", type=float, default=5.0)
    ap.add_argument("--lj-cut", action="store_true",
                    help="the fast level's Lennard-Jones cut, not smooth (lj/cut/coul/dsf)")
    ap.add_argument("--quick", action="store_true", help="two steps and k = 1, 4; 24 fs")
    ap.add_argument("--out", type=Path, default=HERE / "respa_lammps_nve")
    args = ap.parse_args(argv)
    dts, ks = DT_FS, KS
    if args.quick:
        dts, ks, args.ps = (2.0, 4.0), (1, 4), 0.024
    calcs = calculators([(args.r_split, not args.lj_cut)], 0.2)
    points = []
    for k in ks:
        for dt in dts:
            r = run_point(dt, k, calcs, args.ps)
            points.append(r)
            print(f"k={k} dt={dt:g} fs: std {r['std_meV_per_water']:.3f} meV/water, drift "
                  f"{r['drift_meV_per_ps_per_water']:+.3f} meV/ps/water", flush=True)
    result = {"fast": f"{args.r_split:g} Å {'lj/cut' if args.lj_cut else 'smooth'}",
              "ps": args.ps, "points": points,
              "load_average": os.getloadavg()[0]}
    text = report(result)
    print(text)
    if not args.quick:
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
        args.out.with_suffix(".txt").write_text(text)
    return result


if __name__ == "__main__":
    main()
