r"""LAMMPS's own r-RESPA split of TIP4P/2005, timed natively: what two force levels inside one
LAMMPS model can gain at most.

A split of one LAMMPS model into a fast and a slow level inside LAMMPS (the pairs within a
split distance once per inner step, those beyond it and PPPM once per outer step, each pair
computed once and one neighbour list for both) is what a two-level engine protocol
(``fix rigidmd/ipi`` sending two force sets) would ask LAMMPS for.  LAMMPS's own
``run_style respa 2 k inner 1 r_in r_out outer 2 kspace 2`` does exactly that force work, in
its own process, with no round trip to rigidmd and no Python: its ns/day against LAMMPS's
single step is therefore an upper bound for any such engine (which adds a round trip per
inner step and rigidmd's own step).  LAMMPS's rigid fixes are not a correct r-RESPA for rigid
bodies (see ``docs/guide/multiple-time-steps.md``); only the cost is measured here.

The model is the time-step table's TIP4P/2005 with explicit M sites (``lj/cut/coul/long``
9 Å with the tail correction, which has LAMMPS's ``inner``/``outer`` r-RESPA levels; PPPM
1e-5, its parameters chosen by LAMMPS, the same for every case), ``fix rigid/nve/small
molecule`` for every case, from the equilibrated 216-water start (its velocities; 1728: the
box repeated 2×2×2, as ``respa_kspace_share.py`` does).  Cases (:data:`CASES`): the single
step at 2 and 3 fs (3 fs: BAOAB's largest step meeting the time-step table's goals), the
distance split at outer steps of 6 and 8 fs with k = 2-4 and switching ranges 4.5-5 and
5.5-6 Å, and k-space alone on the outer level.  Times are CPU times of the loop (each
section's wall time times its ``%CPU``, as ``respa_kspace_share.py``), best of
``--repeats`` interleaved repeats, per simulated time.

Written to ``respa_lammps_native.json`` (every run) and ``.txt`` (the tables) beside this
script, or ``--out``.  A stop (Ctrl-C, SIGTERM) finishes the LAMMPS run under way, writes the
runs measured so far (marked incomplete) and says how to continue (``--resume``)::

    python validation/respa_lammps_native.py                  # about 6 minutes, 2 idle cores
    python validation/respa_lammps_native.py --skin 3 --out validation/respa_lammps_native_skin3
    python validation/respa_lammps_native.py --quick          # a few steps: seconds
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, children.py, respa_kspace_share.py beside it)
from arguments import positive, read_json, read_results, whole  # noqa: E402
from children import ends_with_parent  # noqa: E402
from respa_kspace_share import START, parse_log  # noqa: E402

CUTOFF = 9.0
#: name -> (run_style arguments after "respa 2 k" or None for verlet, outer step fs, k)
CASES = {
    "single 2 fs": (None, 2.0, 1),
    "single 3 fs": (None, 3.0, 1),
    "k-space 6 fs, k = 2": ("pair 1 kspace 2", 6.0, 2),
    "split 4.5-5 Å 6 fs, k = 2": ("inner 1 4.5 5.0 outer 2 kspace 2", 6.0, 2),
    "split 5.5-6 Å 6 fs, k = 2": ("inner 1 5.5 6.0 outer 2 kspace 2", 6.0, 2),
    "split 4.5-5 Å 6 fs, k = 3": ("inner 1 4.5 5.0 outer 2 kspace 2", 6.0, 3),
    "split 4.5-5 Å 8 fs, k = 2": ("inner 1 4.5 5.0 outer 2 kspace 2", 8.0, 2),
    "split 4.5-5 Å 8 fs, k = 4": ("inner 1 4.5 5.0 outer 2 kspace 2", 8.0, 4),
}
REFERENCE = "single 3 fs"
PS = {216: 0.6, 1728: 0.3}  # simulated ps measured per run (after a warm-up of 30 steps)
ARGUMENT_KEYS = ("sizes", "ranks", "skin", "repeats", "ps")


def write_data(path: Path, n_waters: int) -> None:
    """A LAMMPS data file of ``n_waters`` TIP4P/2005 waters with explicit M sites (types O 1,
    H 2, M 3; molecule IDs; the start's velocities, M's that of its O)."""
    from ase import units

    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    with np.load(START) as d:
        x, p, cell = d["positions"], d["momenta"], np.diag(d["cell"]).astype(float)
    n = len(x) // 4
    masses = model.masses()
    v = p.reshape(n, 4, 3) / np.maximum(masses, 1.0)[None, :, None] * (1000 * units.fs)
    v[:, 3] = v[:, 0]
    x = x.reshape(n, 4, 3)
    reps = round((n_waters / n) ** (1 / 3))
    if reps ** 3 * n != n_waters:
        raise SystemExit(f"--sizes: {n_waters} waters is not a cube number of {n}-water boxes")
    shifts = np.array([[i, j, k] for i in range(reps) for j in range(reps)
                       for k in range(reps)], dtype=float) * cell
    x = (x[None] + shifts[:, None, None]).reshape(-1, 4, 3)
    v = np.tile(v, (reps ** 3, 1, 1))
    charges = [float(q) for q in model.charges(1)]
    edges = [f"0 {float(b) * reps!r} {a}lo {a}hi" for a, b in zip("xyz", cell, strict=True)]
    mass_lines = [f"{t + 1} {max(float(masses[t]), 1e-20)!r}" for t in range(3)]
    lines = ["TIP4P/2005 water, explicit M sites", "", f"{4 * n_waters} atoms", "3 atom types",
             "", *edges, "", "Masses", "", *mass_lines, "", "Atoms # full", ""]
    kinds = (1, 2, 2, 3)
    for i in range(n_waters):
        for s in range(4):
            lines.append(f"{4 * i + s + 1} {i + 1} {kinds[s]} {charges[s]!r} "
                         + " ".join(map(repr, x[i, s].tolist())))
    lines += ["", "Velocities", ""]
    for i in range(n_waters):
        for s in range(4):
            lines.append(f"{4 * i + s + 1} " + " ".join(map(repr, v[i, s].tolist())))
    path.write_text("\n".join(lines) + "\n")


def deck(data: Path, case: str, skin: float, ps: float, warmup: int = 30) -> str:
    """The input of one case (see the module docstring)."""
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    levels, dt_fs, k = CASES[case]
    style = "run_style verlet" if levels is None else f"run_style respa 2 {k} {levels}"
    return "\n".join([
        "units metal", "atom_style full", "boundary p p p", f"read_data {data}",
        f"pair_style lj/cut/coul/long {CUTOFF}", "pair_coeff * * 0.0 1.0",
        f"pair_coeff 1 1 {model.epsilon!r} {model.sigma!r}", "pair_modify tail yes",
        "kspace_style pppm 1e-5", f"neighbor {skin!r} bin",
        "neigh_modify exclude molecule/intra all every 1 delay 0 check yes", style,
        "fix 1 all rigid/nve/small molecule", "timer full", f"timestep {dt_fs / 1000!r}",
        "thermo 100000", f"run {warmup}", f"run {max(round(ps * 1000 / dt_fs), 1)}", ""])


def run_case(work: Path, n: int, ranks: int, case: str, skin: float, ps: float,
             warmup: int) -> dict:
    """One native LAMMPS run (``ranks`` MPI processes of one thread) and its parsed log.

    Started in a session of its own (a Ctrl-C at the terminal reaches this script only,
    which lets the run finish) and ended with this script (``ends_with_parent``).
    """
    slug = case.replace(" ", "_").replace(",", "").replace("=", "").replace("Å", "A")
    inp, log = work / f"in.{n}.{ranks}.{slug}", work / f"log.{n}.{ranks}.{slug}"
    inp.write_text(deck(work / f"water{n}.data", case, skin, ps, warmup))
    lmp = Path(sys.executable).with_name("lmp")
    command = [str(lmp), "-in", str(inp), "-log", str(log), "-screen", "none"]
    if ranks > 1:
        command = [str(Path(sys.executable).with_name("mpirun")), "-np", str(ranks), *command]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    done = subprocess.run(command, env=env, cwd=work, preexec_fn=ends_with_parent,
                          start_new_session=True, capture_output=True, text=True)
    text = log.read_text() if log.exists() else ""
    if done.returncode != 0:
        errors = [line for line in text.splitlines() if line.startswith("ERROR")]
        raise SystemExit(f"{case}, {n} waters, {ranks} ranks: LAMMPS failed: "
                         + (errors[-1] if errors else done.stderr.strip()[-300:]))
    out = parse_log(text)
    builds = [line for line in text.splitlines() if line.startswith("Neighbor list builds")]
    out["neighbor_builds"] = int(builds[-1].split("=")[1]) if builds else None
    # LAMMPS's own account of what each r-RESPA level computes ("1 = ... pair-inner")
    levels = re.search(r"^Respa levels:\n((?:  \d+ = .*\n)+)", text, re.M)
    out["respa_levels"] = None if levels is None else [
        line.split("=", 1)[1].split() for line in levels.group(1).splitlines()]
    return out


def analyse(runs: list) -> list:
    """Per size, ranks and case: the best run, its ns/day and its ratio to the reference."""
    best = {}
    for r in runs:
        key = (r["waters"], r["ranks"], r["case"])
        if key not in best or r["loop_cpu_s"] < best[key]["loop_cpu_s"]:
            best[key] = r
    rows = []
    for (n, ranks, case), r in sorted(best.items(), key=lambda kv: (
            kv[0][0], kv[0][1], list(CASES).index(kv[0][2]))):
        levels, dt_fs, k = CASES[case]
        ps = r["steps"] * dt_fs / 1000
        ns_day = ps * 1e-3 / r["loop_cpu_s"] * 86400
        rows.append({"waters": n, "ranks": ranks, "case": case, "dt_fs": dt_fs, "k": k,
                     "inner_fs": dt_fs / k, "ms_per_outer_step": 1000 * r["loop_cpu_s"]
                     / r["steps"], "ns_per_day": ns_day, "cpu_use": r["cpu_use"],
                     "shares": {s: r["cpu"][s] / r["loop_cpu_s"] for s in r["cpu"]},
                     "builds_per_ps": None if r["neighbor_builds"] is None
                     else r["neighbor_builds"] / ps})
    for row in rows:
        ref = next((o for o in rows if (o["waters"], o["ranks"], o["case"])
                    == (row["waters"], row["ranks"], REFERENCE)), None)
        row["vs_single_3fs"] = None if ref is None else row["ns_per_day"] / ref["ns_per_day"]
    return rows


def report(result: dict) -> str:
    a = result["arguments"]
    lines = [__doc__.splitlines()[0] + " " + __doc__.splitlines()[1], "",
             f"LAMMPS {result['lammps']}; neighbour skin {a['skin']:g} Å; best of "
             f"{a['repeats']} interleaved repeats; load average {result['load_before']:.1f} "
             f"before, {result['load_after']:.1f} after, on {result['cpus']} cores."
             + ("" if result["complete"] else " INCOMPLETE: stopped before every run was "
                "measured (--resume continues)."), "",
             "CPU ms per outer step, ns/day (CPU time), its ratio to the single step at 3 fs "
             "(same size and ranks), the step's sections (% of the loop) and neighbour-list "
             "builds per simulated ps:", "",
             "| waters | ranks | case | outer (fs) | k | inner (fs) | ms/outer step | ns/day "
             "| vs single 3 fs | Pair | Kspace | Neigh | Modify | builds/ps |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        s = r["shares"]
        ratio = "–" if r["vs_single_3fs"] is None else f"{r['vs_single_3fs']:.2f}"
        builds = "–" if r["builds_per_ps"] is None else f"{r['builds_per_ps']:.0f}"
        lines.append(
            f"| {r['waters']} | {r['ranks']} | {r['case']} | {r['dt_fs']:g} | {r['k']} | "
            f"{r['inner_fs']:g} | {r['ms_per_outer_step']:.2f} | {r['ns_per_day']:.1f} | "
            f"{ratio} | {100 * s['Pair']:.1f} | {100 * s['Kspace']:.1f} | "
            f"{100 * s['Neigh']:.1f} | {100 * s['Modify']:.1f} | {builds} |")
    return "\n".join(lines) + "\n"


RESULT_KEYS = ("lammps", "arguments", "complete", "load_before", "load_after", "cpus", "runs",
               "rows")


def read_native(path: Path) -> dict:
    """A results file of this script; one line naming it otherwise."""
    return read_results(path, RESULT_KEYS, "respa_lammps_native.py")


def write_results(out: Path, result: dict) -> str:
    """The .json and .txt, each written whole beside and then moved into place."""
    text = report(result)
    for suffix, content in ((".json", json.dumps(result, indent=1) + "\n"), (".txt", text)):
        target = out.with_suffix(suffix)
        with tempfile.NamedTemporaryFile("w", dir=target.parent, prefix=target.name + ".",
                                         delete=False) as tmp:
            tmp.write(content)
        os.replace(tmp.name, target)
    return text


class Stop:
    """SIGINT and SIGTERM ask the loop to stop after the LAMMPS run under way."""

    def __init__(self):
        self.signal = None
        self.previous = {s: signal.signal(s, self._asked) for s in (signal.SIGINT,
                                                                    signal.SIGTERM)}

    def _asked(self, signum, frame):
        self.signal = signal.Signals(signum).name
        print(f"{self.signal}: stopping after the LAMMPS run under way", file=sys.stderr,
              flush=True)

    def restore(self):
        for s, handler in self.previous.items():
            signal.signal(s, handler)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=whole(1), default=3)
    ap.add_argument("--sizes", type=whole(1), nargs="+", default=list(PS),
                    help=f"waters, among {', '.join(map(str, PS))}")
    ap.add_argument("--ranks", type=whole(1), nargs="+", default=[1, 2],
                    help="MPI ranks of each run (one thread each)")
    ap.add_argument("--skin", type=positive, default=2.0, help="neighbour skin (Å)")
    ap.add_argument("--ps", type=positive,
                    help="simulated ps per run, every size (default: "
                    + ", ".join(f"{v:g} at {n} waters" for n, v in PS.items()) + ")")
    ap.add_argument("--quick", action="store_true",
                    help="one repeat, 216 waters, one rank, a few steps (a check of the script)")
    ap.add_argument("--out", type=Path, default=HERE / "respa_lammps_native")
    ap.add_argument("--resume", action="store_true",
                    help="continue the stopped measurement in --out (same arguments)")
    ap.add_argument("--report", action="store_true",
                    help="rewrite the .txt from --out's .json, measuring nothing")
    args = ap.parse_args(argv)
    if args.report:
        result = read_native(args.out.with_suffix(".json"))
        text = write_results(args.out, result)
        print(text)
        return result
    for n in args.sizes:
        if n not in PS:
            ap.error(f"argument --sizes: {n} waters is not among {', '.join(map(str, PS))}")
    for name, values in (("--sizes", args.sizes), ("--ranks", args.ranks)):
        if len(set(values)) != len(values):
            ap.error(f"argument {name}: a value given twice ({' '.join(map(str, values))})")
    ps, warmup = dict(PS) if args.ps is None else dict.fromkeys(PS, args.ps), 30
    if args.quick:
        args.repeats, args.sizes, args.ranks, ps, warmup = 1, [216], [1], {216: 0.048}, 2
    if not args.out.parent.is_dir():
        ap.error(f"argument --out: no folder {args.out.parent}")
    arguments = {"sizes": args.sizes, "ranks": args.ranks, "skin": args.skin,
                 "repeats": args.repeats, "ps": {str(n): ps[n] for n in args.sizes}}
    runs, load_before = [], os.getloadavg()[0]
    if args.resume:
        earlier = read_native(args.out.with_suffix(".json"))
        if earlier["arguments"] != arguments:
            ap.error(f"--resume: {args.out.with_suffix('.json')} was measured with "
                     f"{earlier['arguments']}, not {arguments}")
        runs, load_before = earlier["runs"], earlier["load_before"]
    elif args.out.with_suffix(".json").exists() and not args.quick:
        prior = read_json(args.out.with_suffix(".json"))
        if isinstance(prior, dict) and prior.get("complete") is False:
            ap.error(f"--out: {args.out.with_suffix('.json')} holds a stopped measurement; "
                     "continue it with --resume (or give another --out)")
    done = {(r["repeat"], r["waters"], r["ranks"], r["case"]) for r in runs}
    todo = [(rep, n, ranks, case) for rep in range(args.repeats) for n in args.sizes
            for ranks in args.ranks for case in CASES if (rep, n, ranks, case) not in done]
    from rigidmd.lammps import load_lammps

    version = load_lammps().version()
    stop = Stop()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            for n in args.sizes:
                write_data(work / f"water{n}.data", n)
            for i, (rep, n, ranks, case) in enumerate(todo):
                if stop.signal:
                    break
                t0 = time.perf_counter()
                r = run_case(work, n, ranks, case, args.skin, ps[n], warmup)
                r.update(waters=n, ranks=ranks, case=case, repeat=rep)
                runs.append(r)
                dt_fs = CASES[case][1]
                print(f"[{len(done) + i + 1}/{len(done) + len(todo)}] repeat {rep}, {n} "
                      f"waters, {ranks} rank(s), {case}: "
                      f"{r['steps'] * dt_fs / 1000 * 86.4 / r['loop_cpu_s']:.1f} ns/day CPU "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    finally:
        stop.restore()
    complete = len(runs) == len(done) + len(todo)
    result = {"lammps": version, "arguments": arguments, "complete": complete,
              "cpus": os.cpu_count(), "load_before": load_before,
              "load_after": os.getloadavg()[0], "runs": runs, "rows": analyse(runs)}
    if args.quick:
        print(report(result))
        return result
    text = write_results(args.out, result)
    if not complete:
        print(f"stopped ({stop.signal}) after {len(runs)} of {len(done) + len(todo)} runs; "
              f"written to {args.out.with_suffix('.json')}; continue with the same arguments "
              "and --resume", file=sys.stderr, flush=True)
        sys.exit(130 if stop.signal == "SIGINT" else 143)
    print(text)
    return result


if __name__ == "__main__":
    main()
