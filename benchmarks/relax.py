"""Force calls to relax rigid water: rigidmd's RigidFilter against ASE's FixBondLengths.

ASE's route to a minimum of rigid molecules is an optimizer on the atoms with
``FixBondLengths`` on the three distances of every water (RATTLE-like
projection of positions and forces); rigidmd's is the same optimizer on
:class:`rigidmd.relax.filter.RigidFilter` (centres of mass, rotation vectors).
Both start from the same structure, a minimum perturbed by a random rigid
displacement of every molecule (centre of mass 0.1 Å, rotation 0.1 rad,
normal distributions), so that both fall back into one basin, and use ASE's
BFGS (default ``maxstep`` 0.2, ``alpha`` 70) with ASE's TIP3P calculator and
``FixBondLengths`` as ASE sets it up (its force projection runs its 500
iterations at every call on water triangles, about 1 s of CPU per step for 8
waters: wall times are ASE's, the force calls are the comparison).

Systems: a 32-water cluster (``water_cluster(32)``, ``TIP3P(rc=20)``, no
cutoff reached) and a periodic box of 64 waters (``water_box(4)``, 12.4 Å,
``TIP3P(rc=6)``).  The start and the minimum are made once and kept beside
this script (:func:`start_of`).  Reported per ``fmax`` (0.05 and 0.01 eV/Å),
both from one run to the smaller (BFGS's steps do not depend on ``fmax``):
force calls (calculator evaluations, counted in the calculator), optimizer
steps and the energy left above the minimum per molecule.  ``alpha`` sweeps
BFGS's initial Hessian (``alpha`` eV/Å² times the identity, in the
coordinates each route shows the optimizer).

``defaults`` compares what users get without tuning: ``relax()`` with its
defaults (:class:`rigidmd.relax.lbfgs.RigidLBFGS` with
:class:`rigidmd.relax.precon.RigidPrecon`) against ASE's BFGS with defaults on
the atoms with ``FixBondLengths``, from structures as built (unrelaxed
``water_cluster`` of 8-64 molecules, seeds 0-2; ``water_box`` of 64-512,
seeds 0-1), both to fmax 0.01 eV/Å, the 0.05 row read off the same run.
``compare`` (:mod:`relax_ase`) runs the same comparison per system with a cap
on steps and time, clusters of 8-64 and boxes of 64-512 built whole, rows
to a JSON-lines file; ``compare-table`` turns them into rows and totals,
``step-cost`` times one step of ASE's route.  ``large`` times the default on
SPC/E boxes with LAMMPS forces (the optimizer's own time: everything outside
the calculator), ``cell`` relaxes the cell (iso, aniso, full) of TIP4P/2005
ice Ih and an SPC/E liquid.

Run::

    python benchmarks/relax.py defaults 64 rows.txt  # systems up to 64 molecules
    python benchmarks/relax.py totals rows.txt     # sums over systems both routes finished
    python benchmarks/relax.py compare cluster32s0 box216s0 --out rows.jsonl --timeout 3000
    python benchmarks/relax.py compare-table rows.jsonl  # rows and totals of compare
    python benchmarks/relax.py step-cost 8         # one step of ASE's route, 512 waters
    python benchmarks/relax.py large 12            # 1728 waters, LAMMPS forces
    python benchmarks/relax.py large 24 none 5     # 13,824 waters, 5 steps
    python benchmarks/relax.py large 12 iso        # with the cell (iso, aniso, full)
    python benchmarks/relax.py large 12 none 2000 1e-3:none  # other CG tolerances
    python benchmarks/relax.py tolerances 1e-2:3e-2 1e-2:none  # force calls, 21 systems
    python benchmarks/relax.py cell                # cell relaxation, LAMMPS forces
    python benchmarks/relax.py                     # the perturbed-minimum study, in turn
    python benchmarks/relax.py box FixBondLengths  # one system (and route): rows to
                                                   # stdout, every step to stderr
    python benchmarks/relax.py alpha cluster       # BFGS's alpha swept (RigidFilter)

Every form prints its rows (``defaults`` and ``compare`` also to the file they are
given); ``benchmarks/relax.txt`` gathers the recorded results of all of them, by hand, and
no form writes over it.
"""

import time
from pathlib import Path

import numpy as np
from ase.calculators.tip3p import TIP3P
from ase.constraints import FixBondLengths
from ase.io import read, write
from ase.optimize import BFGS

from rigidmd.core import quaternion as quat
from rigidmd.relax.filter import RigidFilter, relax
from rigidmd.systems import random_quaternions, water_box, water_cluster


class CountingTIP3P(TIP3P):
    """ASE's TIP3P counting its evaluations and the seconds spent in them."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls = 0
        self.seconds = 0.0

    def calculate(self, *args, **kwargs):
        t = time.perf_counter()
        super().calculate(*args, **kwargs)
        self.seconds += time.perf_counter() - t
        self.calls += 1


def perturbed(atoms, seed, shift=0.1, angle=0.1):
    """Every water moved rigidly: centre of mass by N(0, shift) Å, turned by N(0, angle) rad."""
    rng = np.random.default_rng(seed)
    n = len(atoms) // 3
    out = atoms.copy()
    x = RigidFilter(atoms).get_positions()[:n]  # centres of mass (whole molecules)
    positions = out.positions.reshape(n, 3, 3)
    from rigidmd.core.bodies import RigidBodies
    whole = RigidBodies.resolve(atoms).whole_positions(atoms).reshape(n, 3, 3)
    axis = random_quaternions(n, rng)[:, 1:]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    turn = rng.normal(scale=angle, size=n)
    q = np.concatenate([np.cos(turn / 2)[:, None], np.sin(turn / 2)[:, None] * axis], axis=1)
    local = whole - x[:, None, :]
    positions[:] = (x + rng.normal(scale=shift, size=(n, 3)))[:, None, :] + quat.rotate(
        q[:, None, :], local)
    out.positions = positions.reshape(-1, 3)
    return out


class Recorder:
    """Force calls, steps and energy the first time the largest row falls below each ``fmax``.

    One relaxation to the smallest ``fmax`` gives the rows of every larger one:
    BFGS's steps do not depend on ``fmax`` (it is only the stopping test), so
    the state at the first test passed for ``fmax`` is where a run with that
    ``fmax`` stops.  The norms are read off the optimizer's own convergence
    test (no extra calculator or projection call) into :attr:`norms`; each test
    writes a line to ``log`` (``label``, step, force calls, energy divided by
    ``per``, the norm, seconds).  The calculator is a :class:`CountingTIP3P`.
    """

    def __init__(self, opt, atoms, fmaxes, log=None, label="", per=1):
        self.opt, self.atoms, self.log, self.label, self.per = opt, atoms, log, label, per
        self.todo = sorted(fmaxes, reverse=True)
        self.found = {}
        self.norms = [np.inf]
        self.t0 = time.perf_counter()
        optimizable = opt.optimizable
        original = optimizable.converged

        def converged(gradient, fmax):
            norm = float(optimizable.gradient_norm(gradient))
            self.record(norm)
            return original(gradient, fmax)

        optimizable.converged = converged

    def record(self, norm):
        self.norms.append(norm)
        energy = self.atoms.get_potential_energy()
        wall = time.perf_counter() - self.t0
        calls = self.atoms.calc.calls
        if self.log is not None:
            print(f"{self.label}{self.opt.nsteps:5d} {calls:5d} {energy / self.per:.8f} "
                  f"{norm:.5f} {wall:.1f}", file=self.log, flush=True)
        while self.todo and norm < self.todo[0]:
            self.found[self.todo.pop(0)] = (calls, self.opt.nsteps, True, energy, wall)

    def not_reached(self):
        """The end's values for each ``fmax`` not reached (``converged`` False)."""
        for fmax in self.todo:
            self.found[fmax] = (self.atoms.calc.calls, self.opt.nsteps, False,
                                self.atoms.get_potential_energy(),
                                time.perf_counter() - self.t0)
        self.todo = []
        return self.found


def run_route(route, start, rc, fmaxes, log=None, steps=5000, **bfgs):
    """``{fmax: (calls, steps, converged, energy, wall)}`` of one route from ``start``.

    ``bfgs``: further arguments of ASE's BFGS (``alpha``, the initial Hessian in eV/Å²).
    """
    atoms = start.copy()
    atoms.calc = CountingTIP3P(rc=rc)
    if route == "RigidFilter":
        target = RigidFilter(atoms)
    else:
        fix_water_bonds(atoms)
        target = atoms
    return recorded(BFGS(target, logfile=None, **bfgs), atoms, fmaxes, log, steps)


def water_pairs(n):
    """O-H1, O-H2 and H1-H2 of ``n`` waters ordered O H H, molecule by molecule."""
    return [(3 * i + a, 3 * i + b) for i in range(n) for a, b in ((0, 1), (0, 2), (1, 2))]


def fix_water_bonds(atoms, constraint=FixBondLengths):
    """ASE's rigid water: ``FixBondLengths`` (or ``constraint``, a class of its arguments)
    on the three distances of every molecule."""
    atoms.set_constraint(constraint(water_pairs(len(atoms) // 3)))


def recorded(opt, atoms, fmaxes, log, steps):
    """Run ``opt`` to the smallest ``fmax``: ``{fmax: (calls, steps, converged, energy,
    wall)}`` (a ``fmax`` not reached within ``steps`` gives the end's values)."""
    with opt:
        recorder = Recorder(opt, atoms, fmaxes, log)
        opt.run(fmax=min(fmaxes), steps=steps)
    return recorder.not_reached()


ROUTES = ("RigidFilter", "FixBondLengths")

HEADER = ["# Force calls to relax rigid TIP3P water (BFGS): RigidFilter vs FixBondLengths",
          "",
          "Start: a minimum with every molecule moved rigidly (0.1 Å, 0.1 rad), kept in "
          "relax_start_<system>.extxyz.",
          "ΔE: energy above the minimum of the start's basin per molecule (eV). Wall times "
          "with other jobs on the machine (2 cores shared).",
          "",
          "| system | fmax (eV/Å) | route | force calls | steps | converged | ΔE (eV/molecule) "
          "| wall (s) |",
          "|---|---|---|---|---|---|---|---|"]

SYSTEMS = {"cluster": ("32-water cluster", lambda: water_cluster(32, seed=0), 20.0),
           "box": ("64-water box", lambda: water_box(4, seed=0), 6.0)}


def start_of(key, write_start=None):
    """The start and the minimum's energy of one system, computed once and kept in a file.

    The file (``relax_start_<key>.extxyz`` beside this script) keeps every route
    on one start even when the rigid relaxation changes.  A new start: the
    built structure relaxed rigidly to fmax 1e-3 eV/Å (BFGS, ``alpha`` 5),
    every molecule moved (:func:`perturbed`), and the minimum of the start's
    basin by relaxing a copy of it rigidly to fmax 1e-4 eV/Å.  ``write_start``
    is called with the start's path before that last relaxation (so that a
    long route can begin meanwhile); the minimum is then added to the file.
    (The stored cluster start predates this: the built cluster relaxed to
    1e-4 with BFGS's default ``alpha`` 70, then moved; its minimum that one.)
    """
    path = Path(__file__).with_name(f"relax_start_{key}.extxyz")
    if path.exists():
        start = read(path)
        return start, start.info.get("minimum_energy")
    name, build, rc = SYSTEMS[key]
    atoms = build()
    atoms.calc = TIP3P(rc=rc)
    relax(atoms, fmax=1e-3, steps=5000, alpha=5.0)
    start = perturbed(atoms, seed=1)
    start.calc = None
    write(path, start)
    if write_start is not None:
        write_start(path)
    basin = start.copy()
    basin.calc = TIP3P(rc=rc)
    result = relax(basin, fmax=1e-4, steps=5000, alpha=5.0)
    start.info["minimum_energy"] = result.energy
    write(path, start)
    return start, result.energy


def by_fmax(found, minimum, n):
    """Each fmax of a route's run, loosest first: (fmax, calls, steps, converged, energy above
    the minimum per molecule (eV), wall seconds)."""
    for fmax in sorted(found, reverse=True):
        calls, steps, converged, energy, wall = found[fmax]
        yield fmax, calls, steps, converged, (energy - minimum) / n, wall


def rows(key, fmaxes=(0.05, 0.01), routes=ROUTES, log=None):
    """Table rows of one system for each ``fmax`` and route."""
    name, _, rc = SYSTEMS[key]
    start, _ = start_of(key)
    n = len(start) // 3
    out = []
    for route in routes:
        found = run_route(route, start, rc, fmaxes, log)
        minimum = start_of(key)[1]  # written by another process meanwhile, maybe
        for fmax, calls, steps, converged, excess, wall in by_fmax(found, minimum, n):
            out.append(f"| {name} | {fmax} | {route} | {calls} | {steps} | {converged} "
                       f"| {excess:.2e} | {wall:.1f} |")
            print(out[-1], flush=True)
    return out


ALPHAS = (70.0, 35.0, 20.0, 10.0, 7.0, 5.0, 3.0)


def alpha_rows(key, route="RigidFilter", fmaxes=(0.05, 0.01)):
    """Rows of one route for BFGS's initial Hessian ``alpha`` (eV/Å²) in :data:`ALPHAS`."""
    name, _, rc = SYSTEMS[key]
    start, minimum = start_of(key)
    n = len(start) // 3
    out = []
    for alpha in ALPHAS:
        found = run_route(route, start, rc, fmaxes, alpha=alpha)
        for fmax, calls, steps, converged, excess, _ in by_fmax(found, minimum, n):
            out.append(f"| {name} | {alpha:g} | {fmax} | {route} | {calls} | {steps} "
                       f"| {converged} | {excess:.2e} |")
            print(out[-1], flush=True)
    return out


# ---------------------------------------------------------------- relax() defaults vs ASE's route
def unrelaxed(kind, size, seed):
    """An unrelaxed structure as built (``water_cluster`` or ``water_box``) and its cut-off."""
    if kind == "cluster":
        return water_cluster(size, seed=seed), 20.0
    # Whole molecules: ASE's TIP3P moves a molecule by its O-O minimum image and so reads
    # a wrapped one (water_box's default) as a different, broken structure.
    return water_box(size, seed=seed, whole=True), 6.0


def default_optimizer(route, atoms, constraint=FixBondLengths):
    """What users get without tuning: ``relax()``'s optimizer with its defaults
    (``"relax"``: RigidLBFGS with RigidPrecon on RigidFilter) or ASE's BFGS with defaults
    on the atoms with ``FixBondLengths`` (``"ASE"``; ``constraint`` its class)."""
    if route == "relax":
        from rigidmd.relax.lbfgs import RigidLBFGS

        return RigidLBFGS(RigidFilter(atoms), logfile=None)
    if route == "ASE":
        fix_water_bonds(atoms, constraint)
        return BFGS(atoms, logfile=None)
    raise ValueError(f"route {route!r}: relax or ASE")


def run_defaults(route, start, rc, fmaxes, log=None, steps=5000):
    """``{fmax: (calls, steps, converged, energy, wall)}`` of :func:`default_optimizer`'s
    ``route``, one run to the smallest ``fmax`` (the steps of either do not depend on it).
    ``wall`` is the run's time; ``optimizer`` time is reported by :func:`defaults_rows`."""
    atoms = start.copy()
    atoms.calc = CountingTIP3P(rc=rc)
    return recorded(default_optimizer(route, atoms), atoms, fmaxes, log, steps)


#: (kind, size, seed), smallest first: clusters of 8-64 molecules, boxes of 64-512.
DEFAULT_SYSTEMS = sorted([("cluster", n, seed) for n in (8, 16, 24, 32, 64) for seed in (0, 1, 2)]
                         + [("box", side, seed) for side in (4, 5, 6, 8) for seed in (0, 1)],
                         key=lambda s: (s[1] ** 3 if s[0] == "box" else s[1], s[0], s[2]))


def defaults_rows(largest=64, routes=("relax", "ASE"), fmaxes=(0.05, 0.01), out=None):
    """One table row per system, fmax and route (systems up to ``largest`` molecules)."""
    rows = []
    for kind, size, seed in DEFAULT_SYSTEMS:
        start, rc = unrelaxed(kind, size, seed)
        n = len(start) // 3
        if n > largest:
            continue
        for route in routes:
            found = run_defaults(route, start, rc, fmaxes)
            for fmax in sorted(found, reverse=True):
                calls, steps, converged, energy, wall = found[fmax]
                rows.append(f"| {kind} {n} seed {seed} | {fmax} | {route} | {calls} | {steps} "
                            f"| {converged} | {energy / n:.6f} | {wall:.1f} |")
                print(rows[-1], flush=True)
                if out is not None:
                    with open(out, "a") as fh:
                        fh.write(rows[-1] + "\n")
    return rows


def tolerance_sweep(settings, largest=216):
    """Force calls of ``relax()``'s defaults to fmax 0.05 and 0.01 eV/Å summed over
    :data:`DEFAULT_SYSTEMS` up to ``largest`` molecules, for each ``(CG_TOLERANCE,
    SCALE_TOLERANCE)`` of ``settings`` (``None``: the scale's solve to ``CG_TOLERANCE``),
    and the mean energy per molecule at 0.01: one line each."""
    from rigidmd.relax import lbfgs, precon

    saved = precon.CG_TOLERANCE, lbfgs.SCALE_TOLERANCE
    out = []
    try:
        for cg, scale in settings:
            precon.CG_TOLERANCE, lbfgs.SCALE_TOLERANCE = cg, scale
            calls, energy, k = {0.05: 0, 0.01: 0}, 0.0, 0
            for kind, size, seed in DEFAULT_SYSTEMS:
                start, rc = unrelaxed(kind, size, seed)
                n = len(start) // 3
                if n > largest:
                    continue
                found = run_defaults("relax", start, rc, (0.05, 0.01))
                for fmax in calls:
                    calls[fmax] += found[fmax][0]
                energy += found[0.01][3] / n
                k += 1
            out.append(f"| {cg:g} | {scale} | {k} | {calls[0.05]} / {calls[0.01]} "
                       f"| {energy / k:.6f} |")
            print(out[-1], flush=True)
    finally:
        precon.CG_TOLERANCE, lbfgs.SCALE_TOLERANCE = saved
    return out


def totals(lines):
    """Sum of force calls and mean energy per molecule per (fmax, route) over systems that
    both routes finished: ``{fmax: {route: (calls, mean energy)}}``."""
    table = {}
    for line in lines:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 8 or not cells[3].isdigit():
            continue
        table.setdefault((cells[0], cells[1]), {})[cells[2]] = (int(cells[3]), float(cells[6]))
    out = {}
    for (_system, fmax), routes in table.items():
        if len(routes) < 2:
            continue
        for route, (calls, energy) in routes.items():
            c, e, k = out.setdefault(fmax, {}).get(route, (0, 0.0, 0))
            out[fmax][route] = (c + calls, e + energy, k + 1)
    return {fmax: {route: (c, e / k) for route, (c, e, k) in r.items()}
            for fmax, r in out.items()}


def large(n_side=12, fmax=0.05, model="spce", cell=False, steps=2000, tolerances=None):
    """``relax()`` defaults on ``n_side**3`` waters with LAMMPS forces: the optimizer's own time.

    SPC/E (``water_box``, 3.1 Å spacing), ``lj/cut/coul/long`` 9 Å with PPPM 1e-5 through
    :class:`rigidmd.lammps.LAMMPSCalculator`.  Time inside the calculator is measured around
    its ``calculate``; everything else in ``relax()`` (the filter's placement and reduction,
    the preconditioner, the optimizer, ASE's loop) is the optimizer's own, in CPU time of the
    process (single-threaded: what the process itself spent, less sensitive to other jobs
    on a shared machine) and in wall-clock time.  Returns ``(row, breakdown)``: a table row
    and the lines that split both into

    - before ``relax()``: the process's CPU from its start (the interpreter, the imports of
      numpy, ASE, numba, LAMMPS and rigidmd, building the box), not in any share below;
    - numba's start, measured apart just before ``relax()`` (the first call of any
      compiled function in a process loads numba's typing and lowering registries, about
      0.13 s; rigidmd's dynamics pay it as well, once per process);
    - one-off, in the first step: the optimizer's own (the loading of the compiled
      kernels from numba's cache, the filter's set-up, the preconditioner's scale
      estimate, nearest-neighbour distance and first pair list) and LAMMPS's first call
      (its instance, the box plugin, the first PPPM set-up, one evaluation);
    - per step after the first: own and LAMMPS (ms), and the own share of their sum;
    - the whole ``relax()`` call: own of total, one-offs included, without and with
      numba's start;
    - the preconditioner's conjugate gradients (:func:`rigidmd.relax._numba.conjugate_gradient`,
      part of own): solves, iterations per solve, CPU per step.

    ``tolerances``: ``(CG_TOLERANCE, SCALE_TOLERANCE)`` for this run instead of
    :data:`rigidmd.relax.precon.CG_TOLERANCE` and :data:`rigidmd.relax.lbfgs.SCALE_TOLERANCE`
    (``None`` for the second: the scale's solve to ``CG_TOLERANCE`` as well).
    """
    import resource

    from rigidmd.lammps import LAMMPSCalculator
    from rigidmd.water import water_model

    water = water_model(model)
    atoms = water_box(n_side, seed=0, model=water.name)
    atoms.set_initial_charges(water.charges(len(atoms) // water.sites))
    calc = LAMMPSCalculator(water.lammps_commands(9.0, "pppm", 1e-5, tail=True),
                            atom_types={"O": 1, "H": 2})
    spent = [0.0, 0.0, 0, 0.0]  # wall, CPU, calls, CPU of the first call
    original = calc.calculate

    def calculate(*args, **kwargs):
        t, c = time.perf_counter(), time.process_time()
        original(*args, **kwargs)
        spent[0] += time.perf_counter() - t
        spent[1] += time.process_time() - c
        spent[2] += 1
        if spent[2] == 1:
            spent[3] = spent[1]

    calc.calculate = calculate
    atoms.calc = calc
    first = []  # (CPU, CPU in the calculator) at the end of the first step

    def after(step, energy, largest):
        if step == 1:
            first.append((time.process_time() - c0, spent[1]))

    from rigidmd.relax import _numba, lbfgs, precon

    if tolerances is not None:
        precon.CG_TOLERANCE, lbfgs.SCALE_TOLERANCE = tolerances
    solver, solves = _numba.conjugate_gradient, [0, 0, 0.0, 0]  # solves, iterations, CPU, most

    def conjugate_gradient(*args):
        c = time.process_time()
        x, iterations = solver(*args)
        solves[0] += 1
        solves[1] += iterations
        solves[2] += time.process_time() - c
        solves[3] = max(solves[3], iterations)
        return x, iterations

    _numba.conjugate_gradient = conjugate_gradient
    c_start = time.process_time()
    _numba.dot(np.ones(4), np.ones(4))  # numba's start (a kernel from its cache)
    numba_start = time.process_time() - c_start
    t0, c0 = time.perf_counter(), time.process_time()
    result = relax(atoms, fmax=fmax, steps=steps, cell=cell, observers=(after,))
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = len(atoms) // water.sites
    own, own_cpu = total - spent[0], cpu - spent[1]
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    start_cpu, start_calc = first[0] if first else (cpu, spent[1])
    once = start_cpu - start_calc  # own CPU of the first step
    later = max(result.steps - 1, 1)
    per_own, per_calc = (own_cpu - once) / later, (spent[1] - start_calc) / later
    row = (f"| {n} {model} waters{', cell ' + cell if cell else ''} | {fmax} | {spent[2]} "
           f"| {result.steps} | {result.converged} | {result.energy / n:.6f} | {total:.1f} "
           f"| {own:.1f} ({100 * own / total:.1f} %) | {cpu:.1f} "
           f"| {own_cpu:.2f} ({100 * own_cpu / cpu:.1f} %) | {once:.2f} / {spent[3]:.2f} "
           f"| {1e3 * per_own:.2f} / {1e3 * per_calc:.1f} "
           f"({100 * per_own / (per_own + per_calc):.1f} %) | {rss:.0f} |")
    load = " ".join(f"{x:.2f}" for x in __import__("os").getloadavg())
    breakdown = [
        f"before relax(): {c_start:.2f} s CPU (interpreter, imports, the box; in no share); "
        f"numba's start {numba_start:.3f} s CPU",
        f"one-off, first step: own {once:.3f} s CPU (the cached kernels' loading, the "
        f"filter's set-up, the preconditioner's estimate and first pairs); LAMMPS's first "
        f"call {spent[3]:.3f} s CPU (instance, box plugin, PPPM set-up, one evaluation)",
        f"per step after the first ({later} steps): own {1e3 * per_own:.2f} ms, LAMMPS "
        f"{1e3 * per_calc:.2f} ms CPU: own {100 * per_own / (per_own + per_calc):.1f} %",
        f"whole relax(): own {own_cpu:.3f} of {cpu:.3f} s CPU ({100 * own_cpu / cpu:.1f} %), "
        f"{own:.3f} of {total:.3f} s wall ({100 * own / total:.1f} %); with numba's start "
        f"counted as own: {100 * (own_cpu + numba_start) / (cpu + numba_start):.1f} % of CPU; "
        f"load average {load}",
        f"conjugate gradients (CG_TOLERANCE {precon.CG_TOLERANCE:g}, SCALE_TOLERANCE "
        f"{lbfgs.SCALE_TOLERANCE}): {solves[0]} solves in {result.steps} steps, "
        f"{solves[1] / max(solves[0], 1):.1f} iterations a solve (at most {solves[3]}), "
        f"{1e3 * solves[2] / max(result.steps, 1):.2f} ms CPU a step",
    ]
    return row, breakdown


#: Columns of :func:`large`'s row.
LARGE_HEADER = ("| system | fmax | force calls | steps | converged | E/molecule (eV) | wall (s) "
                "| own wall (s, %) | CPU (s) | own CPU (s, %) | one-off own / LAMMPS first call "
                "(s CPU) | per step own / LAMMPS (ms CPU, own %) | peak RSS (MiB) |")


def cell_rows(optimizers=("RigidLBFGS", "BFGS"), modes=("iso", "aniso", "full"), fmax=0.01):
    """Cell relaxation at 0 bar with LAMMPS forces: TIP4P/2005 ice Ih (96 molecules) and a
    216-molecule SPC/E box, per mode and optimizer: force calls, steps, density, energy."""
    from rigidmd.lammps import LAMMPSCalculator
    from rigidmd.systems import ice_ih
    from rigidmd.water import water_model

    rows = []
    for name, model, build in (("ice Ih", "tip4p2005", lambda: ice_ih((3, 2, 2), seed=0)),
                               ("liquid", "spce", lambda: water_box(6, seed=0, model="spce"))):
        water = water_model(model)
        for mode in modes:
            for optimizer in optimizers:
                atoms = build()
                n = len(atoms) // water.sites
                atoms.set_initial_charges(water.charges(n))
                types = {"O": 1, "H": 2, "X": 3} if water.sites == 4 else {"O": 1, "H": 2}
                atoms.calc = LAMMPSCalculator(water.lammps_commands(8.5, "pppm", 1e-5, tail=True),
                                              atom_types=types)
                calls = [0]
                original = atoms.calc.calculate

                def calculate(*args, _original=original, _calls=calls, **kwargs):
                    _calls[0] += 1
                    _original(*args, **kwargs)

                atoms.calc.calculate = calculate
                t0 = time.perf_counter()
                result = relax(atoms, fmax=fmax, steps=3000, cell=mode, optimizer=optimizer)
                density = atoms.get_masses().sum() / atoms.get_volume() * 1e24 / 6.02214076e23
                rows.append(f"| {name} ({n}) | {mode} | {optimizer} | {calls[0]} "
                            f"| {result.steps} | {result.converged} | {density:.4f} "
                            f"| {result.energy / n:.5f} | {time.perf_counter() - t0:.1f} |")
                print(rows[-1], flush=True)
    return rows


def _whole(text, what):
    """``text`` as a whole number >= 1, or SystemExit in one line naming ``what``."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise SystemExit(f"relax.py: {what} must be a whole number >= 1, got {text!r}")
    return value


COMMANDS = ("compare", "compare-table", "step-cost", "cell", "tolerances", "large",
            "defaults", "totals", "alpha")


def main():
    import sys

    args = sys.argv[1:]
    # (a mistyped word, a missing file or a non-number failed with a KeyError, IndexError or
    # ValueError traceback)
    if args and args[0] not in COMMANDS and args[0] not in SYSTEMS:
        raise SystemExit(f"relax.py: {args[0]!r} is not a command ({', '.join(COMMANDS)}) or "
                         f"a system ({', '.join(SYSTEMS)}); see the module's docstring")
    if args[:1] in (["totals"], ["compare-table"]) and len(args) < 2:
        raise SystemExit(f"relax.py {args[0]}: give the rows file(s) to read")
    if args[:1] in (["large"], ["defaults"], ["step-cost"]) and len(args) > 1:
        _whole(args[1], f"{args[0]}'s first argument")
    if args[:1] == ["large"] and len(args) > 3:
        _whole(args[3], "large's steps")
    if args[:1] in (["compare"], ["compare-table"], ["step-cost"]):  # relax_ase.py
        import json

        import relax_ase

        if args[0] == "compare":
            relax_ase.main(args[1:])
        elif args[0] == "step-cost":
            print(relax_ase.step_cost(int(args[1]) if len(args) > 1 else 8), flush=True)
        else:
            records = [json.loads(line) for name in args[1:]
                       for line in Path(name).read_text().splitlines() if line.strip()]
            print("\n".join(relax_ase.table(records) + [""] + relax_ase.compact(records)))
        return
    if args[:1] == ["cell"]:  # cell: cell relaxation with LAMMPS forces, rows to stdout
        cell_rows()
        return
    if args[:1] == ["tolerances"]:  # tolerances CG:SCALE ...: force calls over 21 systems
        print("| CG_TOLERANCE | SCALE_TOLERANCE | systems | force calls to 0.05 / 0.01 "
              "| mean E at 0.01 (eV/molecule) |\n|---|---|---|---|---|", flush=True)
        tolerance_sweep([(float(cg), None if scale == "none" else float(scale))
                         for cg, scale in (a.split(":") for a in args[1:])])
        return
    if args[:1] == ["large"]:  # large [N_SIDE [CELL [STEPS [CG:SCALE]]]]: own time, LAMMPS
        cell = args[2] if len(args) > 2 and args[2] != "none" else False
        tolerances = None
        if len(args) > 4:
            cg, scale = args[4].split(":")
            tolerances = (float(cg), None if scale == "none" else float(scale))
        row, breakdown = large(int(args[1]) if len(args) > 1 else 12, cell=cell,
                               steps=int(args[3]) if len(args) > 3 else 2000,
                               tolerances=tolerances)
        print(LARGE_HEADER, row, *breakdown, sep="\n", flush=True)
        return
    if args[:1] == ["defaults"]:  # defaults [LARGEST [FILE]]: relax() against ASE's route
        largest = int(args[1]) if len(args) > 1 else 64
        defaults_rows(largest, out=args[2] if len(args) > 2 else None)
        return
    if args[:1] == ["totals"]:  # totals FILE: sums over the systems both routes finished
        for fmax, routes in totals(Path(args[1]).read_text().splitlines()).items():
            print(fmax, routes)
        return
    if args[:1] == ["alpha"]:  # alpha SYSTEM [ROUTE]: BFGS's alpha swept, rows to stdout
        alpha_rows(args[1], *args[2:])
        return
    if args:  # SYSTEM [ROUTE]: rows to stdout, per-step log to stderr
        rows(args[0], routes=args[1:] or ROUTES, log=sys.stderr)
        return
    lines = HEADER + rows("cluster") + rows("box")
    # (printed only: relax.txt holds every study's recorded rows, and this replaced them)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
