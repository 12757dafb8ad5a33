r"""NPT density of rigid TIP4P/2005 against the step, with the Monte Carlo barostat.

The time-step table's NPT goal: the density at 298 K and 1 atm with ``RigidLangevinBAOAB``'s
part at 4 fs within 2σ of its value at 0.5 fs, σ ≤ 0.1 %.  One run is one point: 216 waters
from the table's shared start (``water_openmm_long.start_tip4p2005.npz``), LAMMPS's forces
as the table's (``lj/cut/coul/long`` 9 Å with the tail correction, PPPM 1e-5, pinned Ewald
parameter), :class:`rigidmd.RigidMCBarostat` with the thermostat part of ``--integrator``
(``baoab``: :class:`~rigidmd.couplings.baoab.LangevinBAOABThermostat`; ``langevin``:
:class:`~rigidmd.couplings.thermostats.LangevinThermostat`; friction 1/ps, ``fixcm=False``
as every barostat needs), isotropic volume moves every ``--move-fs`` of simulated time
whatever the step (the same moves per ps at every step; the move size adapts during the
first 500 moves, which lie inside ``--equil-ps``).  The Monte Carlo barostat reads the
bath's temperature, not the momenta, so BAOAB's kinetic bias does not reach the density.

A run writes ``<name>.json`` (the density with the standard error of ``--blocks`` block
means over the part after ``--equil-ps``, ⟨U⟩/N, T_tr, T_rot, the acceptance), its series
``<name>.series.npz`` (time, density, U, T_tr, T_rot every move) and its checkpoint
``<name>.chk.npz`` (rigidmd's, exact), the record of its arguments ``<name>.arguments``
and, while it runs, its claim ``<name>.claim`` (as ``timestep_table.py``'s).  It prints
progress (a line on a terminal, a log line a minute otherwise), stops on SIGTERM or SIGINT
at the end of the move interval it is in, writes what it has (``"complete": false``) and
``--resume`` continues it.  ``report`` compares the steps.  Run::

    python validation/npt_density.py run --dt-fs 0.5 4 --ps 400 --jobs 2 \
        --outdir validation/npt_runs
    python validation/npt_density.py run ... --resume     # continue stopped runs
    python validation/npt_density.py report validation/npt_runs/*.json \
        --out validation/npt_density
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from arguments import at_least_zero, positive, whole  # noqa: E402
from timestep_table import (  # noqa: E402
    FRICTION_PER_PS,
    TEMPERATURE_K,
    Claim,
    Progress,
    Stop,
    add_run_options,
    block_mean,
    complete_already,
    cutoff_for,
    intramolecular_energy,
    load_start,
    make_atoms,
    record_point,
    run_in_pieces,
    run_points,
)

PRESSURE_BAR = 1.01325
MODEL = "tip4p2005"
INTEGRATORS = ("baoab", "langevin")
KEYS = ("t_ps", "density", "U", "T_tr", "T_rot")


def run_name(p):
    return f"npt_{MODEL}_{p['waters']}_{p['integrator']}_dt{p['dt_fs']:g}_s{p['seed']}"


def dynamics(p, atoms):
    """``RigidMCBarostat`` with the point's thermostat part, a move every ``move_fs``."""
    from ase import units

    from rigidmd import RigidMCBarostat
    from rigidmd.couplings.baoab import LangevinBAOABThermostat
    from rigidmd.couplings.thermostats import LangevinThermostat

    rng = np.random.default_rng(5000 + p["seed"])
    friction = FRICTION_PER_PS * 1e-3 / units.fs
    part = {"baoab": LangevinBAOABThermostat, "langevin": LangevinThermostat}[p["integrator"]]
    dt = p["dt_fs"] * units.fs
    # BAOAB's part acts in the middle of the step: the dynamics cuts NO_SQUISH around it
    return RigidMCBarostat(atoms, dt, TEMPERATURE_K, PRESSURE_BAR * units.bar,
                           thermostat=part(TEMPERATURE_K, friction, rng, fixcm=False),
                           every=move_every(p), rng=rng)


def move_every(p):
    """Steps between volume moves: ``move_fs`` of simulated time (at least one step)."""
    return max(int(round(p["move_fs"] / p["dt_fs"])), 1)


def run_point(p, paths, stop, progress, resume):
    """Run (or continue) one point; returns (series, steps, ms/step, U offset, first step)."""
    from ase import units
    from water_openmm_nve import lammps_calculator

    from rigidmd import load_checkpoint
    from rigidmd.core.checkpoint import read_checkpoint, save_checkpoint
    from rigidmd.water import water_model

    model = water_model(MODEL)
    state = load_start(MODEL, p["waters"])
    series = {k: [] for k in KEYS}
    if resume and paths["chk"].exists():
        chk = read_checkpoint(paths["chk"])
        dyn = load_checkpoint(chk, lammps_calculator(model, cutoff_for(state["cell"])))
        with np.load(paths["series"]) as d:
            series = {k: list(d[k][:chk.extra["samples"]]) for k in KEYS}
    else:
        dyn = dynamics(p, make_atoms(state, model))
    atoms = dyn.atoms
    kj = units.kJ / units.mol
    every = move_every(p)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))

    def observe():
        t = dyn.nsteps * p["dt_fs"] / 1000
        if series["t_ps"] and series["t_ps"][-1] >= t:
            return  # a resumed run's first call: this step is recorded
        for k, v in zip(KEYS, (t, dyn.get_density(), atoms.get_potential_energy() / kj,
                               *dyn.get_kinetic_temperatures()), strict=True):
            series[k].append(float(v))

    def save():
        tmp = paths["series"].with_name(paths["series"].name + ".tmp.npz")
        np.savez(tmp, **{k: np.asarray(v, dtype=float) for k, v in series.items()})
        os.replace(tmp, paths["series"])
        save_checkpoint(dyn, paths["chk"], extra={"samples": len(series["t_ps"])})

    dyn.attach(observe, interval=every)
    ms, s0 = run_in_pieces(dyn, total, every, stop, progress, p, save)
    atoms.get_potential_energy()
    offset = intramolecular_energy(model, atoms.calc)
    acceptance = float(dyn.barostat.acceptance)
    if hasattr(atoms.calc, "close"):
        atoms.calc.close()
    return series, dyn.nsteps, ms, offset, s0, acceptance


def analyse(series, p, offset):
    """The density (g/cm³), ⟨U⟩/N (kJ/mol, without the intramolecular constant), T_tr and
    T_rot (K), each with the standard error of ``blocks`` block means after ``equil_ps``."""
    t = np.asarray(series["t_ps"])
    keep = t > p["equil_ps"]
    out = {"recorded_ps": float(t[keep][-1] - t[keep][0]) if keep.sum() > 1 else 0.0,
           "samples": int(keep.sum())}
    out["density"] = block_mean(np.asarray(series["density"])[keep], p["blocks"])
    u = np.asarray(series["U"])[keep] / p["waters"] - offset
    out["U"] = block_mean(u, p["blocks"])
    for k in ("T_tr", "T_rot"):
        out[k] = block_mean(np.asarray(series[k])[keep], p["blocks"])
    return out


def point_main(p, resume):
    """Run one point and write its JSON; exit status 0 when complete, 3 when stopped."""
    outdir = Path(p["outdir"])
    outdir.mkdir(parents=True, exist_ok=True)
    name = run_name(p)
    with Claim(outdir / f"{name}.claim", name):  # (a second run of it refused)
        return _point_main(p, resume, outdir, name)


def _point_main(p, resume, outdir, name):
    """:func:`point_main` once the point is claimed."""
    paths = {k: outdir / f"{name}.{k}.npz" for k in ("series", "chk")}
    paths["json"], paths["record"] = outdir / f"{name}.json", outdir / f"{name}.arguments"
    arguments = {k: v for k, v in p.items() if k != "outdir"}
    if complete_already(paths["json"], name, resume, arguments, paths["chk"],
                        paths["record"]):
        return 0
    record_point(paths["record"], arguments)  # (before the first sample: --resume checks it)
    stop = Stop()
    progress = Progress(name, p["ps"], p["log_s"], shared=p.get("jobs", 1) > 1)
    wall = time.perf_counter()
    series, steps, ms, offset, first, acceptance = run_point(p, paths, stop, progress, resume)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))
    out = {"point": {k: v for k, v in p.items() if k != "outdir"}, "name": name,
           "complete": steps >= total, "steps": steps, "resumed_from_step": first,
           "ps": steps * p["dt_fs"] / 1000, "stopped_by": stop.signal, "ms_per_step": ms,
           "wall_s": time.perf_counter() - wall, "molecules": p["waters"],
           "temperature_K": TEMPERATURE_K, "pressure_bar": PRESSURE_BAR,
           "friction_per_ps": FRICTION_PER_PS, "move_every_steps": move_every(p),
           "acceptance": acceptance, "U_offset_per_molecule": offset,
           **analyse(series, p, offset)}
    tmp = paths["json"].with_name(paths["json"].name + ".tmp")
    tmp.write_text(json.dumps(out, indent=1, allow_nan=True) + "\n")
    os.replace(tmp, paths["json"])
    progress(out["ps"], force=True)
    if stop:
        print(f"{name}: stopped by {stop.signal} at {out['ps']:.3f} ps; written, continue "
              f"with --resume", flush=True)
        return 3
    return 0


def run_many(args):
    """Every point of the values given, ``--jobs`` at a time, each in its own process
    (:func:`timestep_table.run_points`: a signal is passed on, each run writes what it has)."""
    if args.equil_ps >= args.ps:
        raise SystemExit(f"--equil-ps {args.equil_ps:g}: leaves nothing of --ps {args.ps:g}")
    for option in ("integrator", "dt_fs", "seed"):
        values = getattr(args, option)
        if len(set(values)) != len(values):
            raise SystemExit(f"--{option.replace('_', '-')}: a value given twice ({values})")
    base = {k: getattr(args, k) for k in ("waters", "ps", "equil_ps", "move_fs", "blocks",
                                          "save_s", "log_s", "jobs")}
    base["outdir"] = str(args.outdir)
    todo = [dict(base, integrator=i, dt_fs=dt, seed=s)
            for i, dt, s in itertools.product(args.integrator, args.dt_fs, args.seed)]
    return run_points(todo, __file__, run_name, point_main, args.jobs, args.resume)


def combine(values):
    """The weighted mean of ``[(mean, error), ...]`` (weights 1/error²) and its error."""
    x = np.array([v[0] for v in values])
    w = 1 / np.array([v[1] for v in values]) ** 2
    return float(np.sum(w * x) / np.sum(w)), float(1 / np.sqrt(np.sum(w)))


def report(files, out=None, sigma_goal_pct=0.1):
    """The runs, then each step's runs combined against the smallest step of the same
    integrator: Δρ, Δ/σ and the goal (within 2σ, σ/ρ ≤ ``sigma_goal_pct`` at both steps).
    With ``out``, also ``OUT.md``, ``OUT.json`` (the combined rows) and ``OUT.runs.json``
    (every run's JSON, a bundle ``report`` reads again)."""
    runs, seen = [], {}
    for f in files:  # a run's JSON, or a bundle of them (a list, ``--out``'s ``.runs.json``)
        try:
            data = json.loads(Path(f).read_text())
        except (OSError, ValueError) as err:
            raise SystemExit(f"{f}: not a readable run or bundle ({err})") from None
        for run in data if isinstance(data, list) else [data]:
            if not isinstance(run, dict) or "density" not in run or "point" not in run:
                raise SystemExit(f"{f}: holds something that is not an NPT run (no density)")
            p = run["point"]
            which = (p.get("integrator"), p.get("dt_fs"), p.get("seed"), run.get("molecules"))
            if which in seen:  # a run given twice: its σ would fall by √2
                raise SystemExit(f"{f}: the run {run.get('name', which)} is also in "
                                 f"{seen[which]}; give each run once")
            seen[which] = f
            runs.append(run)
    if not runs:
        raise SystemExit("report: no runs given")
    for field in ("molecules", "equil_ps", "move_fs"):  # one header says them for all
        values = sorted({str(r.get(field, r["point"].get(field))) for r in runs})
        if len(values) > 1:
            raise SystemExit(f"report: the runs differ in {field} ({', '.join(values)}); "
                             "report runs made alike")
    runs.sort(key=lambda r: (r["point"]["integrator"], r["point"]["dt_fs"], r["point"]["seed"]))
    first = runs[0]["point"]
    lines = [f"NPT density of {runs[0]['molecules']} rigid TIP4P/2005 waters, 298 K, 1 atm, Monte "
             f"Carlo barostat, friction 1/ps; standard errors of block means after the "
             f"first {first['equil_ps']:g} ps of each run.", "",
             "| integrator | dt (fs) | seed | ps | density (g/cm³) | σ/ρ (%) | ⟨U⟩/N (kJ/mol) | "
             "T_tr (K) | T_rot (K) | move every (fs) | acceptance | ms/step |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        p = r["point"]
        rho, err = r["density"]
        if not np.all(np.isfinite(r["density"])):
            lines.append(f"| {p['integrator']} | {p['dt_fs']:g} | {p['seed']} | {r['ps']:.0f}"
                         f"{'' if r['complete'] else ' (stopped)'} | none yet: not past the "
                         f"first {p['equil_ps']:g} ps |" + " |" * 7)
            continue
        lines.append(
            f"| {p['integrator']} | {p['dt_fs']:g} | {p['seed']} | {r['ps']:.0f}"
            f"{'' if r['complete'] else ' (stopped)'} | {rho:.4f} ± {err:.4f} | "
            f"{100 * err / rho:.3f} | {r['U'][0]:.3f} ± {r['U'][1]:.3f} | "
            f"{r['T_tr'][0]:.1f} ± {r['T_tr'][1]:.1f} | {r['T_rot'][0]:.1f} ± "
            f"{r['T_rot'][1]:.1f} | {r['move_every_steps'] * p['dt_fs']:g} | "
            f"{r['acceptance']:.2f} | {r['ms_per_step']:.1f} |")
    steps = sorted({(r["point"]["integrator"], r["point"]["dt_fs"]) for r in runs})
    rows = []
    for integrator, dt in steps:
        mine = [r for r in runs if (r["point"]["integrator"], r["point"]["dt_fs"]) ==
                (integrator, dt) and np.all(np.isfinite(r["density"]))]
        if not mine:  # (no run of this step got past its equilibration)
            continue
        rho, err = combine([r["density"] for r in mine])
        rows.append({"integrator": integrator, "dt_fs": dt, "runs": len(mine),
                     "ps": float(sum(r["ps"] for r in mine)), "density": [rho, err],
                     "rel_err_pct": 100 * err / rho})
    for row in rows:
        ref = min((q for q in rows if q["integrator"] == row["integrator"]),
                  key=lambda q: q["dt_fs"])
        (rho, err), (rho0, err0) = row["density"], ref["density"]
        sig = float(np.hypot(err, err0))
        row["reference_dt_fs"] = ref["dt_fs"]
        row["diff_pct"] = 100 * (rho - rho0) / rho0
        row["z"] = (rho - rho0) / sig if ref is not row else float("nan")
        precise = max(row["rel_err_pct"], ref["rel_err_pct"]) <= sigma_goal_pct
        if ref is row:
            row["goal"] = "—"
        elif not np.isfinite(row["z"]):
            row["goal"] = "?"
        elif abs(row["z"]) > 2:
            row["goal"] = "✗"
        else:
            row["goal"] = "✓" if precise else f"? (σ above {sigma_goal_pct:g} %)"
    lines += ["", f"Each step's runs combined (weights 1/σ²), against the smallest step of the "
              f"same integrator; the goal: within 2σ of it, with σ/ρ ≤ {sigma_goal_pct:g} % "
              "at both steps.", "",
              "| integrator | dt (fs) | runs | ps | density (g/cm³) | σ/ρ (%) | Δρ (%) | Δ/σ | "
              "goal |", "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        rho, err = row["density"]
        z = "" if row["z"] != row["z"] else f"{row['z']:+.1f}"
        lines.append(f"| {row['integrator']} | {row['dt_fs']:g} | {row['runs']} | "
                     f"{row['ps']:.0f} | {rho:.4f} ± {err:.4f} | {row['rel_err_pct']:.3f} | "
                     f"{row['diff_pct']:+.3f} | {z} | {row['goal']} |")
    text = "\n".join(lines) + "\n"
    if out:
        Path(str(out) + ".md").write_text(text)
        Path(str(out) + ".json").write_text(json.dumps(rows, indent=1) + "\n")
        Path(str(out) + ".runs.json").write_text(json.dumps(runs, indent=1) + "\n")
    return text


def parse(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run points")
    r.add_argument("--integrator", nargs="+", choices=INTEGRATORS, default=["baoab"])
    r.add_argument("--waters", type=whole(1), default=216,
                   help="216 (the table's) or a size timestep_table.py start made")
    r.add_argument("--dt-fs", nargs="+", type=positive, required=True)
    r.add_argument("--seed", nargs="+", type=whole(0), default=[1])
    r.add_argument("--ps", type=positive, required=True, help="length of each run, ps")
    r.add_argument("--equil-ps", type=at_least_zero, default=30.0,
                   help="left out of the averages at the start, ps")
    r.add_argument("--move-fs", type=positive, default=50.0, help="a volume move every, fs")
    r.add_argument("--blocks", type=whole(2), default=10, help="blocks for the errors")
    add_run_options(sub, r, HERE / "npt_runs")
    rep = sub.add_parser("report", help="the table of finished or stopped runs")
    rep.add_argument("files", nargs="+", type=Path)
    rep.add_argument("--out", type=Path, help="also write OUT.md, OUT.json, OUT.runs.json")
    return ap.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    if args.command == "run":
        return run_many(args)
    if args.command == "_point":
        return point_main(json.loads(args.point), args.resume)
    print(report(args.files, args.out), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
