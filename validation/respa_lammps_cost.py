r"""ns/day of a two-level LAMMPS split against single-step runs: TIP4P/2005, 216 waters, one core.

The full model is rigidmd's TIP4P/2005 through :class:`rigidmd.lammps.LAMMPSCalculator`
(explicit M sites, ``lj/cut/coul/long`` 9 Å with the tail correction, PPPM 1e-5: the
time-step table's model).  The split is :class:`rigidmd.MultipleTimeStep` with two LAMMPS
instances in this one process, each set up once: the fast level
``WaterModel.lammps_short_range_commands(r_split, alpha, smooth)`` (``coul/dsf`` and
Lennard-Jones at ``r_split``, no k-space; ``smooth``: ``lj/smooth/linear``, else
``lj/cut/coul/dsf``) and the slow level ``full - fast``
(``MultipleTimeStep(fast, full=full)``; the fast level's last inner call is at the slow
call's positions, so the difference costs one call of the full model and none of the fast
one).

Every run is :class:`rigidmd.RigidLangevinBAOAB` (298 K, friction 1/ps) from the same start
(``water_openmm_long.start_tip4p2005.npz``, equilibrated), for ``--ps`` of simulated time
after ``--warmup`` outer steps: single-step at 2 and 4 fs with the full model, the split at
outer steps of 4, 6 and 8 fs with k = 2 and 4 for each fast level of ``--fast`` (r_split 5
and 4 Å, smooth and not; alpha 0.2 1/Å).  The cases are interleaved (every case once,
then every case again), best of ``--repeats``.  For each: ns/day from the process's CPU time
(what one idle core would give; other processes on a shared machine do not inflate it)
and from the wall time, ms per outer step, the calls of each level per simulated ps and
each level's share of the time spent in force calls, and the drift of BAOAB's effective
energy (the total energy less the heat the thermostat put in; 20 samples, asked by an
observer, so in the steps' own calls) over the run: a first look at the outer step's
stability, not an accuracy study.

The accuracy study the issue asks for (energy conservation and sampling for outer steps of
2-8 fs and k = 1-8 against the BAOAB tolerances) is not run here: it needs CPU hours.  For
the sampling it is ``validation/timestep_table.py run --code rigidmd --integrator baoab
--dt-fs 2 4 6 8 --substeps 1 2 4 8 --r-split 5 --seed 1 2 3 --ps 200`` (about 7 core-hours
at these costs).

The full model's neighbour list is rebuilt when an atom has moved half the skin: at outer
steps of 6-8 fs that is nearly every call with LAMMPS's default 2 Å, and a rebuild costs
most of a step; ``--skin 3`` is the second set of results.

``--engine N`` puts every LAMMPS model in LAMMPS's own processes: the full model and each
fast level a :class:`rigidmd.lammps.engine.LAMMPSEngine` of N ranks (the split is then two
engines, which never compute at the same time, so each may take every core), and the
cases are those the goal compares (:data:`ENGINE_CASES`: the single step at 3 fs, BAOAB's
largest step meeting the time-step table's goals, and splits at outer steps of 6 and 8 fs).
The engines' work is in other processes: every time is then the wall time (best of the
repeats by it), on a machine left idle.

Writes ``respa_lammps_cost.json`` and ``respa_lammps_cost.txt`` beside this script. Run::

    python validation/respa_lammps_cost.py             # 2-3 minutes on one idle core
    python validation/respa_lammps_cost.py --skin 3 --out validation/respa_lammps_cost_skin3
    python validation/respa_lammps_cost.py --engine 2 --skin 3 \
        --out validation/respa_lammps_cost_engine2    # 3-4 minutes on two idle cores
    python validation/respa_lammps_cost.py --quick     # one repeat, a few steps: seconds
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

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
from arguments import positive, whole  # noqa: E402

START = HERE / "water_openmm_long.start_tip4p2005.npz"
TYPES = {"O": 1, "H": 2, "X": 3}
CUTOFF = 9.0
#: Fast levels: (r_split Å, smooth); alpha is --alpha.
FAST = [(5.0, True), (4.0, True), (5.0, False), (4.0, False)]
#: (outer step fs, substeps) of the split; the single-step runs are at 2 and 4 fs.
SPLITS = [(dt, k) for dt in (4.0, 6.0, 8.0) for k in (2, 4)]
#: With --engine: (fast level or None, outer step fs, k or None), the single step first.
ENGINE_CASES = [(None, 3.0, None), ((5.0, False), 6.0, 2), ((5.0, True), 6.0, 2),
                ((4.0, False), 6.0, 2), ((4.0, False), 8.0, 4)]


def fast_name(r_split, smooth):
    return f"{r_split:g} Å {'smooth' if smooth else 'lj/cut'}"


def start_atoms():
    """The 216 equilibrated TIP4P/2005 waters (explicit M), one body per molecule."""
    from ase import Atoms

    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    with np.load(START) as d:
        atoms = Atoms(numbers=d["numbers"], positions=d["positions"], cell=d["cell"],
                      pbc=True)
        momenta = d["momenta"]
    n = len(atoms) // 4
    atoms.set_masses(np.tile(model.masses(), n))
    atoms.set_momenta(momenta)
    atoms.set_initial_charges(model.charges(n))
    atoms.set_tags(np.repeat(np.arange(1, n + 1), 4))
    return atoms


class Counted:
    """Counts a calculator's calls and the CPU time they take (wrapping its ``calculate``)."""

    def __init__(self, calc, clock=time.process_time):
        self.calls, self.seconds = 0, 0.0
        inner = calc.calculate

        def calculate(*args, **kwargs):
            t = clock()
            try:
                return inner(*args, **kwargs)
            finally:
                self.seconds += clock() - t
                self.calls += 1

        calc.calculate = calculate

    def reset(self):
        self.calls, self.seconds = 0, 0.0


def calculators(fast_levels, alpha: float, skin: float = 2.0, engine: int | None = None):
    """The full model; per fast level its calculator and split (k set per case); counters
    of the full model's calls and of each fast level's.  ``engine``: each a
    ``LAMMPSEngine`` of that many ranks (counted in wall time), else a
    ``LAMMPSCalculator`` in this process (counted in CPU time)."""
    from rigidmd import MultipleTimeStep
    from rigidmd.lammps import LAMMPSCalculator
    from rigidmd.lammps.engine import LAMMPSEngine
    from rigidmd.water import water_model

    def lammps(commands, skin):
        if engine is None:
            return LAMMPSCalculator(commands, atom_types=TYPES, skin=skin)
        return LAMMPSEngine(commands, atom_types=TYPES, skin=skin, processes=engine)

    clock = time.process_time if engine is None else time.perf_counter
    model = water_model("tip4p2005")
    full = lammps(model.lammps_commands(CUTOFF, "pppm", 1e-5, tail=True), skin)
    splits, counters = {}, {"full": Counted(full, clock)}
    for r_split, smooth in fast_levels:
        fast = lammps(model.lammps_short_range_commands(r_split, alpha, smooth), 2.0)
        splits[r_split, smooth] = MultipleTimeStep(fast, full=full)
        counters[r_split, smooth] = Counted(fast, clock)
    return full, splits, counters


def run_case(fast, dt_fs, k, calcs, ps, warmup, seed=1, wall_clock=False):
    """One run (``fast`` None: single-step with the full model); its costs and the drift
    of its effective energy.  ``wall_clock``: the forces are timed in wall time (engines),
    so their share of a step is of the wall time."""
    from ase import units

    from rigidmd import RigidLangevinBAOAB

    full, splits, every_counter = calcs
    atoms = start_atoms()
    if fast is None:
        atoms.calc = full
    else:
        atoms.calc = splits[fast]
        atoms.calc.substeps = k
    counters = {"full": every_counter["full"]}
    if fast is not None:
        counters["fast"] = every_counter[fast]
    dyn = RigidLangevinBAOAB(atoms, dt_fs * units.fs, temperature_K=298.0,
                             friction=1.0 / (1000 * units.fs),
                             rng=np.random.default_rng(seed))
    dyn.run(warmup)  # (before the observer is attached)
    steps = max(int(round(ps * 1000 / dt_fs)), 2)
    every = max(steps // 20, 1)
    times, energies = [], []

    def sample():  # an observer: its steps ask the levels for the energy in the same call
        times.append(dyn.nsteps * dt_fs / 1000)
        energies.append(dyn.get_conserved_energy())

    dyn.attach(sample, interval=every)
    for c in counters.values():
        c.reset()
    wall, cpu = time.perf_counter(), time.process_time()
    dyn.run(steps)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    sim_ps = steps * dt_fs / 1000
    n = len(atoms) // 4
    drift = np.polyfit(times, np.array(energies) / n, 1)[0] if len(times) > 1 else np.nan
    force_s = sum(c.seconds for c in counters.values())
    return {"label": "single" if fast is None else "split",
            "fast": None if fast is None else fast_name(*fast), "dt_fs": dt_fs, "k": k,
            "steps": steps,
            "cpu_ms_per_step": 1000 * cpu / steps, "wall_ms_per_step": 1000 * wall / steps,
            "ns_per_day_cpu": sim_ps * 1e-3 / cpu * 86400,
            "ns_per_day_wall": sim_ps * 1e-3 / wall * 86400,
            "calls_per_ps": {"fast": 0.0} | {name: c.calls / sim_ps
                                             for name, c in counters.items()},
            "force_share": {"fast": 0.0} | {name: c.seconds / force_s if force_s
                                            else float("nan") for name, c in counters.items()},
            "force_fraction_of_step": force_s / (wall if wall_clock else cpu),
            "drift_meV_per_ps_per_water": 1000 * float(drift),
            "effective_energy_std_meV_per_water": 1000 * float(np.std(energies)) / n}


def report(result) -> str:
    engine = result.get("engine")
    clock = "CPU" if engine is None else "wall"
    rate = f"ns_per_day_{clock.lower()}"
    base_fs = 2.0 if engine is None else 3.0
    base = next(r for r in result["best"] if r["k"] is None and r["dt_fs"] == base_fs)
    title = __doc__.splitlines()[0]
    if engine is not None:
        title = title.replace(", one core.", f", LAMMPSEngine of {engine} rank(s) per model.")
    lines = [title, "",
             ("" if engine is None else f"Every model a LAMMPSEngine of {engine} rank(s); "
              "times are wall times. ")
             + f"216 TIP4P/2005 waters; DSF alpha {result['alpha']} 1/Å; the full model's "
             f"neighbour skin {result['skin']:g} Å; {result['ps']} ps per "
             f"run after {result['warmup']} outer steps; best of {result['repeats']} "
             f"interleaved repeats (by {clock} time); "
             f"load average {result['load_before']:.1f} before, {result['load_after']:.1f} "
             f"after, on {result['cpus']} cores.", "",
             f"| run | fast level | outer fs | k | inner fs | ms/outer step ({clock}) "
             f"| ns/day (CPU) | ns/day (wall) | vs single {base_fs:g} fs ({clock}) "
             "| fast calls/ps | full calls/ps "
             "| fast share of force time | force time / step | E_eff drift (meV/ps/water) "
             "| E_eff std (meV/water) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["best"]:
        k = r["k"] or 1
        lines.append(
            f"| {r['label']} | {r['fast'] or '-'} | {r['dt_fs']:g} | {r['k'] or '-'} | "
            f"{r['dt_fs'] / k:g} | "
            f"{r[f'{clock.lower()}_ms_per_step']:.2f} | {r['ns_per_day_cpu']:.2f} | "
            f"{r['ns_per_day_wall']:.2f} | {r[rate] / base[rate]:.2f} | "
            f"{r['calls_per_ps']['fast']:.0f} | {r['calls_per_ps']['full']:.0f} | "
            f"{100 * r['force_share']['fast']:.0f} % | "
            f"{100 * r['force_fraction_of_step']:.0f} % | "
            f"{r['drift_meV_per_ps_per_water']:+.3f} | "
            f"{r['effective_energy_std_meV_per_water']:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=whole(1), default=3)
    ap.add_argument("--ps", type=positive, default=0.4, help="simulated ps per run")
    ap.add_argument("--warmup", type=int, default=10, help="outer steps before timing")
    ap.add_argument("--alpha", type=float, default=0.2, help="fast level's DSF damping (1/Å)")
    ap.add_argument("--skin", type=float, default=2.0,
                    help="the full model's neighbour skin (Å); the fast levels' is 2 Å")
    ap.add_argument("--engine", type=whole(1), metavar="RANKS",
                    help="every LAMMPS model a LAMMPSEngine of RANKS ranks; wall times")
    ap.add_argument("--quick", action="store_true", help="one repeat, 24 fs per run")
    ap.add_argument("--out", type=Path, default=HERE / "respa_lammps_cost")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeats, args.ps, args.warmup = 1, 0.024, 1
    if args.engine is None:
        cases = [(None, 2.0, None), (None, 4.0, None)] + [
            (fast, dt, k) for fast in FAST for dt, k in SPLITS]
    else:
        cases = ENGINE_CASES
    fast_levels = list(dict.fromkeys(fast for fast, _, _ in cases if fast is not None))
    timed = "cpu_ms_per_step" if args.engine is None else "wall_ms_per_step"
    calcs = calculators(fast_levels, args.alpha, args.skin, args.engine)
    load_before = os.getloadavg()[0]
    runs, best = [], {}
    try:
        for rep in range(args.repeats):
            for fast, dt, k in cases:
                r = run_case(fast, dt, k, calcs, args.ps, args.warmup,
                             wall_clock=args.engine is not None) | {"repeat": rep}
                runs.append(r)
                print(f"repeat {rep} {r['fast'] or 'single':16} {dt:g} fs k={k or 1}: "
                      f"{r['cpu_ms_per_step']:.2f} "
                      f"ms/step CPU, {r['ns_per_day_cpu']:.2f} ns/day CPU "
                      f"({r['ns_per_day_wall']:.2f} wall), drift "
                      f"{r['drift_meV_per_ps_per_water']:+.3f} meV/ps/water", flush=True)
                key = (fast, dt, k)
                if key not in best or r[timed] < best[key][timed]:
                    best[key] = r
    finally:
        for calc in {id(c): c for c in [calcs[0], *(s.fast for s in calcs[1].values())]
                     }.values():
            if hasattr(calc, "close"):
                calc.close()
    result = {"fast_levels": [fast_name(*f) for f in fast_levels], "alpha": args.alpha,
              "engine": args.engine, "skin": args.skin, "ps": args.ps,
              "warmup": args.warmup, "repeats": args.repeats, "cpus": os.cpu_count(),
              "load_before": load_before, "load_after": os.getloadavg()[0],
              "best": [best[case] for case in cases], "runs": runs}
    text = report(result)
    print(text)
    if not args.quick:
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
        args.out.with_suffix(".txt").write_text(text)
    return result


if __name__ == "__main__":
    main()
