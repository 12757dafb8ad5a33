r"""Time to solution: each code and integrator at its largest accurate step, side by side.

What a user pays for is simulated time at a stated accuracy.  This reads the time-step
table's collected results (``timestep_table_report.py``'s JSON: per code and integrator the
largest step no goal fails, ``not_excluded_fs``, and the largest step every goal is shown
to meet, ``shown_fs``), measures the CPU time of a step of each at those steps, and writes
ns/day and each one's ratio to LAMMPS's ``fix rigid/nvt/small`` at its own step.

The measurement: one thread, every code from the model's shared thermal start
(``timestep_table.load_start``), the CPU time of a run of ``--steps`` less that of a run of
20 (:func:`timestep_table.measure_ms`, so that set-ups do not count; a first run of each
pays its compiling), the codes interleaved in ``--rounds`` rounds and the best round kept.
ns/day = 86.4 · dt (fs) / (ms per step).  ``--extra CODE:INTEGRATOR:DT`` adds a point the
table does not hold (OpenMM's ``middle`` at a step of your choice, say), marked as such;
``rigidmd:INTEGRATOR:DT:SUBSTEPS:R_SPLIT`` is an r-RESPA split at the outer step DT.
The ratios are to LAMMPS at the step the table judged, or else at a step given.
``--skin S`` gives every LAMMPS force (rigidmd's, each level of a split, and LAMMPS's own
run) a neighbour skin of S Å: LAMMPS's metal default of 2 Å re-neighbours often at steps
of 3–6 fs, and at 216 waters 3 Å made BAOAB's 3 and 4 fs steps 7 and 13 % cheaper and the
split's 6 fs outer step 9 % (LAMMPS's own 1 fs step: the same), the forces unchanged.

Run::

    python validation/time_to_solution.py validation/timestep_table_216.json \
        --extra openmm:middle:4 --rounds 3 --steps 300 --name time_to_solution
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import timestep_table  # noqa: E402
from arguments import existing_file, read_json, whole  # noqa: E402

#: The code and integrator every ratio is taken against.
REFERENCE = ("lammps", "nvt_small")


def split_of(row):
    """``(scheme, substeps, r_split)`` of a row of the table's ``largest_steps``: a split's
    levels are its fields (``substeps`` above 1, ``r_split`` in Å); a row without them is
    one step of its integrator."""
    substeps = int(row.get("substeps") or 1)
    r_split = float(row["r_split"]) if substeps > 1 else 5.0
    return row.get("scheme", row["integrator"]), substeps, r_split


def chosen_points(table, extra=()):
    """``[(code, integrator, dt_fs, basis)]``: each code and integrator at its largest step
    no goal fails (``"not excluded"``) and, where it differs, the largest shown to meet
    every goal (``"shown"``); then the ``extra`` points (``"given"``).  Also
    ``{integrator: (scheme, substeps, r_split)}`` (:func:`split_of`) for each."""
    out, levels = [], {}
    for row in table["largest_steps"]:
        levels[row["integrator"]] = split_of(row)
        if row["not_excluded_fs"]:
            out.append((row["code"], row["integrator"], float(row["not_excluded_fs"]),
                        "not excluded"))
        if row["shown_fs"] and row["shown_fs"] != row["not_excluded_fs"]:
            out.append((row["code"], row["integrator"], float(row["shown_fs"]), "shown"))
    for item in extra:
        code, integrator, dt, *split = item.split(":")
        if split:  # an r-RESPA split: CODE:INTEGRATOR:DT:SUBSTEPS:R_SPLIT
            k, r_split = int(split[0]), float(split[1])
            name = f"{integrator} k={k} r={r_split:g}"
            levels.setdefault(name, (integrator, k, r_split))
        else:
            name = integrator
            levels.setdefault(name, (integrator, 1, 5.0))
        out.append((code, name, float(dt), "given"))
    return out, levels


def parse_extra(item):
    """``CODE:INTEGRATOR:DT`` (rigidmd also ``...:SUBSTEPS:R_SPLIT``, an r-RESPA split of
    outer step DT) checked, or argparse's error."""
    parts = item.split(":")
    codes = {"rigidmd": timestep_table.INTEGRATORS, "lammps": ("nvt_small",),
             "openmm": ("middle",)}
    try:
        ok = (len(parts) == 3 or (len(parts) == 5 and parts[0] == "rigidmd"
                                  and int(parts[3]) >= 2 and float(parts[4]) > 0)) \
            and parts[1] in codes[parts[0]] and float(parts[2]) > 0
    except (KeyError, ValueError):
        ok = False
    if not ok:
        raise argparse.ArgumentTypeError(
            f"{item!r}: give CODE:INTEGRATOR:DT_FS, e.g. openmm:middle:4 or rigidmd:baoab:4, "
            "or a split rigidmd:INTEGRATOR:DT_FS:SUBSTEPS:R_SPLIT, e.g. rigidmd:baoab:6:2:5")
    return item


def measure(points, levels, model, waters, steps, rounds, outdir, skin=None):
    """Best CPU ms/step of each point over interleaved rounds (``levels``: each
    integrator's ``(scheme, substeps, r_split)``; ``skin``: the neighbour skin in Å of
    every LAMMPS force, rigidmd's and LAMMPS's own, None for LAMMPS's 2 Å); returns rows
    with ns/day."""
    for code, integrator in dict.fromkeys((c, i) for c, i, _, _ in points):
        name, k, r_split = levels[integrator]
        timestep_table.measure_ms(code, name, 2.0 * k, 40, model, waters, outdir, k,
                                  r_split, skin)  # compiles
    best = {}
    for r in range(rounds):
        for point in points:
            name, k, r_split = levels[point[1]]
            cpu, wall = timestep_table.measure_ms(point[0], name, point[2], steps, model,
                                                  waters, outdir, k, r_split, skin)
            if not cpu > 0:
                raise SystemExit(f"{point[0]} {point[1]} at {point[2]:g} fs: {steps} steps "
                                 f"took no more CPU time than 20 ({cpu:.3f} ms/step): the "
                                 "set-up's scatter hides the steps; give more --steps")
            key = point[:3]
            if key not in best or cpu < best[key][0]:
                best[key] = (cpu, wall)
            print(f"round {r + 1}/{rounds} {point[0]:8} {point[1]:10} {point[2]:g} fs: "
                  f"{cpu:.2f} ms/step CPU", flush=True)
    rows = []
    for code, integrator, dt, basis in points:
        cpu, wall = best[(code, integrator, dt)]
        scheme, substeps, r_split = levels[integrator]
        rows.append({"code": code, "integrator": integrator, "scheme": scheme,
                     "substeps": substeps, "r_split": r_split if substeps > 1 else None,
                     "dt_fs": dt, "basis": basis,
                     "cpu_ms_per_step": cpu, "wall_ms_per_step": wall,
                     "ns_per_day": 86.4 * dt / cpu})
    # The reference: LAMMPS's own integrator at the step the table judged, or else at a
    # step given (its largest accurate step lies below the table's steps).
    candidates = [r for r in rows if (r["code"], r["integrator"]) == REFERENCE]
    judged = [r for r in candidates if r["basis"] != "given"]
    reference = (judged or candidates or [None])[0]
    for row in rows:
        row["vs_lammps"] = (row["ns_per_day"] / reference["ns_per_day"]
                            if reference else None)
        row["reference"] = row is reference
    return rows


def text(rows, header):
    lines = [header, "", "| code | integrator | step (fs) | why this step | CPU ms/step | "
             "ns/day | × LAMMPS fix rigid/nvt/small |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = "—" if r["vs_lammps"] is None else f"{r['vs_lammps']:.2f}" + (
            " (the reference)" if r.get("reference") else "")
        lines.append(f"| {r['code']} | {r['integrator']} | {r['dt_fs']:g} | {r['basis']} | "
                     f"{r['cpu_ms_per_step']:.2f} | {r['ns_per_day']:.1f} | {ratio} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("table", type=existing_file, help="timestep_table_report.py's JSON")
    p.add_argument("--extra", nargs="*", type=parse_extra, default=[],
                   metavar="CODE:INTEGRATOR:DT")
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--rounds", type=whole(1), default=3)
    p.add_argument("--name", default="time_to_solution")
    p.add_argument("--outdir", type=Path, default=HERE)
    p.add_argument("--workdir", type=Path, default=Path("/tmp/time_to_solution"))
    p.add_argument("--skin", type=float, help="neighbour skin (Å) of every LAMMPS force, "
                   "rigidmd's and LAMMPS's own (default LAMMPS's metal 2 Å; a longer step "
                   "re-neighbours more often, and a larger skin can pay)")
    args = p.parse_args(argv)
    if args.steps <= 20:
        p.error("--steps must be above 20 (a run of 20 is taken off)")
    table = read_json(args.table)
    if not (isinstance(table, dict) and isinstance(table.get("largest_steps"), list)):
        p.error(f"{args.table}: not the JSON of timestep_table_report.py (no largest_steps)")
    points, levels = chosen_points(table, args.extra)
    if not points:
        p.error(f"{args.table}: no code and integrator with a step that meets the goals; "
                "give --extra points")
    waters = {row["waters"] for row in table["largest_steps"]} or {216}
    model = {row["model"] for row in table["largest_steps"]} or {"tip4p2005"}
    if len(waters) != 1 or len(model) != 1:
        p.error(f"{args.table}: one model and size at a time (has {sorted(model)}, "
                f"{sorted(waters)})")
    model, waters = model.pop(), waters.pop()
    if args.skin is not None and not args.skin > 0:
        p.error(f"--skin {args.skin:g}: a neighbour skin is a length above 0 Å")
    rows = measure(points, levels, model, waters, args.steps, args.rounds, args.workdir,
                   args.skin)
    skin = f"{args.skin:g} Å" if args.skin is not None else "LAMMPS's 2 Å"
    header = (f"{model}, {waters} waters, one thread, neighbour skin {skin}, CPU time of "
              f"{args.steps} steps less 20, "
              f"best of {args.rounds} interleaved rounds, from one thermal start; steps from "
              f"{args.table.name}; load average {os.getloadavg()[0]:.1f} on "
              f"{os.cpu_count()} cores at the end ({time.strftime('%Y-%m-%d')})")
    args.outdir.mkdir(parents=True, exist_ok=True)
    (args.outdir / f"{args.name}.txt").write_text(text(rows, header))
    (args.outdir / f"{args.name}.json").write_text(json.dumps(
        {"header": header, "model": model, "waters": waters, "rows": rows}, indent=1) + "\n")
    print(text(rows, header))
    return rows


if __name__ == "__main__":
    main()
