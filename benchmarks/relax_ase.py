"""``relax()`` with its defaults against ASE's route for rigid water, at 8-512 molecules.

The ``compare`` subcommand of ``benchmarks/relax.py``.  Both routes start from
one structure as built (``water_cluster(n, seed)``, ASE's ``TIP3P(rc=20)``;
``water_box(side, seed, whole=True)``, ``TIP3P(rc=6)``), with the same counting
calculator, and run once to the smallest ``fmax``; the rows of the larger ones
are read off the same run (neither route's steps depend on ``fmax``):

- ``relax``: :class:`rigidmd.relax.lbfgs.RigidLBFGS` (its defaults, with
  :class:`rigidmd.relax.precon.RigidPrecon`) on
  :class:`rigidmd.relax.filter.RigidFilter`, what ``relax(atoms)`` runs;
- ``ASE``: ASE's ``BFGS`` with its defaults on the atoms with
  ``FixBondLengths`` on the O-H, O-H and H-H distances of every water.

Boxes are built whole (``whole=True``): ASE's ``TIP3P`` takes the minimum
image of the O-O vector and moves the whole molecule by it, so a molecule
split across the cell (``water_box``'s default wraps every atom) is a
different energy to it (3.004 eV per molecule for the 64-water box of seed 0
as built, against 0.011 whole; rigidmd's filter places whole molecules and
sees 0.011 either way).

``FixBondLengths`` is ASE's own or, by default, :class:`WaterBondLengths`:
the same Gauss-Seidel sweeps (each molecule's pairs in ASE's order, the same
updates and tolerance, the same test for the end of the sweeps) done for
every molecule at once instead of one pair at a time in Python; molecules
share no atom, so the sweeps are the same.  It exists so that 216 and 512
waters finish at all (ASE's takes about 100 ms per 64 pairs per sweep here).
``--ase-own`` uses ASE's class.  :func:`check_equivalent` compares them.

Each route is stopped after ``--max-steps`` optimizer steps or ``--timeout``
seconds and is then reported as not converged, with where it stood.  Rows are
appended to a JSON-lines file as each route ends, and every step goes to a
log beside it (step, force calls, energy, fmax, seconds), so partial results
survive.

Run::

    python benchmarks/relax.py compare cluster32s0 box216s1 --out rows.jsonl
    python benchmarks/relax.py compare box512s0 --routes ASE --max-steps 20
    python benchmarks/relax.py compare-table rows.jsonl   # rows and totals, Markdown
    python benchmarks/relax.py step-cost 8                # one BFGS step at 512 waters
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from ase.calculators.tip3p import TIP3P
from ase.constraints import FixBondLengths
from ase.geometry import find_mic
from ase.optimize import BFGS
from relax import CountingTIP3P, Recorder, default_optimizer, unrelaxed, water_pairs

from rigidmd.systems import water_box

FMAXES = (0.05, 0.01)


class WaterBondLengths(FixBondLengths):
    """ASE's ``FixBondLengths`` on water triangles, every molecule's pair at once.

    ``pairs`` must be consecutive triples per molecule, no atom in two
    molecules (as :func:`water_pairs` makes them).  ASE's sweep visits the
    pairs in order and updates a pair whose correction exceeds the tolerance;
    pairs of different molecules share no atom, so visiting the first pair of
    every molecule, then the second, then the third, does the same updates.
    The sweeps end, as ASE's, after one in which no pair was updated
    (``RuntimeError`` after ``maxiter``).
    """

    def __init__(self, pairs, **kwargs):
        super().__init__(pairs, **kwargs)
        stages = self.pairs.reshape(-1, 3, 2)
        atoms_of = stages.reshape(len(stages), -1)
        if len(np.unique(atoms_of)) != 3 * len(stages) or any(
                len(np.unique(m)) != 3 for m in atoms_of):
            raise ValueError("WaterBondLengths: pairs must be triangles of disjoint molecules")
        self.stages = [(stages[:, k, 0], stages[:, k, 1]) for k in range(3)]

    def _sweeps(self, atoms, update):
        if self.bondlengths is None:
            self.bondlengths = self.initialize_bond_lengths(atoms)
        lengths = self.bondlengths.reshape(-1, 3)
        for _ in range(self.maxiter):
            converged = True
            for k in range(3):
                if update(k, lengths[:, k]):
                    converged = False
            if converged:
                return
        raise RuntimeError("Did not converge")

    def _geometry(self, atoms):
        old = atoms.positions
        masses = atoms.get_masses()
        out = []
        for a, b in self.stages:
            r0 = old[a] - old[b]
            d0 = find_mic(r0, atoms.cell, atoms.pbc)[0]
            out.append((a, b, r0, d0, masses[a], masses[b],
                        1 / (1 / masses[a] + 1 / masses[b])))
        return out

    def adjust_positions(self, atoms, new):
        geometry = self._geometry(atoms)

        def update(k, cd):
            a, b, r0, d0, ma, mb, m = geometry[k]
            d1 = new[a] - new[b] - r0 + d0
            x = 0.5 * (cd**2 - np.einsum("ij,ij->i", d1, d1)) / np.einsum("ij,ij->i", d0, d1)
            moved = np.abs(x) > self.tolerance
            if not moved.any():
                return False
            x, d0, a, b = x[moved, None], d0[moved], a[moved], b[moved]
            new[a] += x * m[moved, None] / ma[moved, None] * d0
            new[b] -= x * m[moved, None] / mb[moved, None] * d0
            return True

        self._sweeps(atoms, update)

    def adjust_momenta(self, atoms, p):
        geometry = self._geometry(atoms)

        def update(k, cd):
            a, b, _, d, ma, mb, m = geometry[k]
            dv = p[a] / ma[:, None] - p[b] / mb[:, None]
            x = -np.einsum("ij,ij->i", dv, d) / cd**2
            moved = np.abs(x) > self.tolerance
            if not moved.any():
                return False
            x, d, a, b = x[moved, None], d[moved], a[moved], b[moved]
            p[a] += x * m[moved, None] * d
            p[b] -= x * m[moved, None] * d
            return True

        self._sweeps(atoms, update)


# ------------------------------------------------------------------------------------ systems
def parse_system(name):
    """``"cluster32s0"`` -> ("cluster", 32, 0); ``"box216s1"`` -> ("box", 216, 1)."""
    kind = "cluster" if name.startswith("cluster") else "box"
    if not name.startswith(kind):
        raise ValueError(f"{name!r}: not clusterNsS or boxNsS")
    size, seed = name[len(kind):].split("s")
    return kind, int(size), int(seed)


def build(name):
    """The structure as built and its TIP3P cut-off (Å) (:func:`relax.unrelaxed`)."""
    kind, n, seed = parse_system(name)
    if kind == "cluster":
        return unrelaxed(kind, n, seed)
    side = round(n ** (1 / 3))
    if side**3 != n:
        raise ValueError(f"{name}: a box holds a cube number of waters")
    return unrelaxed(kind, side, seed)


def bond_error(atoms, pairs, lengths):
    """Largest |d - d0| (Å) over the constrained pairs, minimum image."""
    pairs = np.asarray(pairs)
    d = find_mic(atoms.positions[pairs[:, 0]] - atoms.positions[pairs[:, 1]],
                 atoms.cell, atoms.pbc)[1]
    return float(np.abs(d - lengths).max())


# ------------------------------------------------------------------------------------- runs
def run(name, route, fmaxes=FMAXES, max_steps=5000, timeout=None, log=None, own=False):
    """One route on one system to ``min(fmaxes)``: a dict of rows per fmax and the end state.

    ``rows[fmax]``: force calls, steps, converged, energy per molecule (eV), seconds, the
    first time the largest row's norm fell below ``fmax`` (else the end's values).  ``end``:
    why it stopped (``converged``, ``max-steps``, ``timeout``), its energy re-evaluated by
    a fresh ``TIP3P`` on the atoms as they stand (per molecule), the largest bond-length
    error of the water triangles, seconds inside the calculator and in all (wall and CPU).
    """
    start, rc = build(name)
    n = len(start) // 3
    atoms = start.copy()
    calc = atoms.calc = CountingTIP3P(rc=rc)
    pairs = water_pairs(n)
    lengths = find_mic(start.positions[np.asarray(pairs)[:, 0]]
                       - start.positions[np.asarray(pairs)[:, 1]], start.cell, start.pbc)[1]
    opt = default_optimizer(route, atoms, FixBondLengths if own else WaterBondLengths)
    c0 = time.process_time()
    reason = "max-steps"
    logfh = open(log, "a") if log else None
    try:
        with opt:
            recorder = Recorder(opt, atoms, fmaxes, logfh, label=f"{name} {route} ", per=n)
            for converged in opt.irun(fmax=min(fmaxes), steps=max_steps):
                if converged:
                    reason = "converged"
                    break
                if timeout is not None and time.perf_counter() - recorder.t0 > timeout:
                    reason = "timeout"
                    break
    finally:
        if logfh:
            logfh.close()
    wall = time.perf_counter() - recorder.t0
    energy = atoms.get_potential_energy()
    reached = set(recorder.found)
    rows = {}
    for fmax, (calls, steps, converged, e, seconds) in recorder.not_reached().items():
        rows[fmax] = dict(calls=calls, steps=steps, converged=converged, energy=e / n,
                          wall=seconds)
        if fmax not in reached:
            rows[fmax].update(wall=wall, fmax_reached=recorder.norms[-1])
    norms = recorder.norms
    check = atoms.copy()
    check.set_constraint()
    check.calc = TIP3P(rc=rc)
    return dict(system=name, route=route, n=n, rows={str(k): v for k, v in rows.items()},
                end=dict(reason=reason, calls=calc.calls, steps=opt.nsteps, fmax=norms[-1],
                         energy=energy / n, energy_fresh=check.get_potential_energy() / n,
                         bond_error=bond_error(atoms, pairs, lengths),
                         calculator_s=calc.seconds, wall=wall, cpu=time.process_time() - c0,
                         start_energy=_energy(start, rc) / n,
                         fixbondlengths="ASE" if own else "WaterBondLengths"))


def _energy(atoms, rc):
    atoms = atoms.copy()
    atoms.calc = TIP3P(rc=rc)
    return atoms.get_potential_energy()


def check_equivalent(name="cluster8s0", steps=30):
    """ASE's ``FixBondLengths`` against :class:`WaterBondLengths` on one BFGS run.

    Returns the largest difference of positions (Å) and energies (eV) over ``steps``
    steps, and the seconds of each.
    """
    out = {}
    for own in (True, False):
        atoms, rc = build(name)
        atoms.calc = TIP3P(rc=rc)
        atoms.set_constraint((FixBondLengths if own else WaterBondLengths)(
            water_pairs(len(atoms) // 3)))
        t = time.perf_counter()
        trace = []
        with BFGS(atoms, logfile=None) as opt:
            for _ in opt.irun(fmax=0.0, steps=steps):
                trace.append((atoms.positions.copy(), atoms.get_potential_energy()))
        out[own] = trace, time.perf_counter() - t
    (a, ta), (b, tb) = out[True], out[False]
    pairs = list(zip(a, b, strict=True))
    return dict(positions=max(float(np.abs(p - q).max()) for (p, _), (q, _) in pairs),
                energy=max(abs(e - f) for (_, e), (_, f) in pairs),
                ase_s=ta, vectorised_s=tb, steps=len(a))


def step_cost(side=8, seed=0, repeats=2):
    """Seconds of the parts of one step of ASE's route on ``side**3`` waters (a box).

    ``eigh``: BFGS's diagonalisation of its ``3N x 3N`` Hessian; ``tip3p``: one force
    call; ``project_forces`` / ``project_positions``: ``FixBondLengths`` (ASE's and
    :class:`WaterBondLengths`) on the forces and on a BFGS-sized step; each as (wall, CPU)
    seconds, best of ``repeats`` (CPU time is the one to read on a shared machine).
    """
    atoms = water_box(side, seed=seed, whole=True)
    n = len(atoms) // 3
    atoms.calc = TIP3P(rc=6.0)
    out = dict(waters=n, coordinates=3 * len(atoms))

    def best(f):  # (wall, CPU) seconds, best of repeats
        times = []
        for _ in range(repeats):
            t, c = time.perf_counter(), time.process_time()
            f()
            times.append((time.perf_counter() - t, time.process_time() - c))
        return min(times)

    forces = atoms.get_forces()
    out["tip3p"] = best(lambda: (atoms.calc.reset(), atoms.get_forces()))
    hessian = np.eye(3 * len(atoms)) * 70.0
    out["eigh"] = best(lambda: np.linalg.eigh(hessian + 1e-3 * np.outer(forces, forces)))
    step = np.random.default_rng(0).normal(scale=0.02, size=atoms.positions.shape)
    for label, cls in (("ase", FixBondLengths), ("vectorised", WaterBondLengths)):
        constraint = cls(water_pairs(n))
        out[f"project_forces_{label}"] = best(
            lambda c=constraint: c.adjust_forces(atoms, forces.copy()))
        out[f"project_positions_{label}"] = best(
            lambda c=constraint: c.adjust_positions(atoms, atoms.positions + step))
    return out


# ------------------------------------------------------------------------------------ tables
def paired(records):
    """``(system, {route: record})`` of the systems both routes ran, clusters first, by size;
    the later record of a system and route counts."""
    by = {}
    for r in records:
        by.setdefault(r["system"], {})[r["route"]] = r
    for system in sorted(by, key=lambda s: (parse_system(s)[0], parse_system(s)[1:])):
        if set(by[system]) == {"relax", "ASE"}:
            yield system, by[system]


def compact(records):
    """One Markdown row per system: force calls at each fmax and energies at the smallest."""
    lines = ["| system | force calls to 0.05, relax / ASE | to 0.01 | E at 0.01, relax / ASE "
             "(eV/molecule) |", "|---|---|---|---|"]
    for system, routes in paired(records):
        cells = []
        for fmax in ("0.05", "0.01"):
            a, b = routes["relax"]["rows"][fmax], routes["ASE"]["rows"][fmax]
            late = "" if b["converged"] else f" (stopped, fmax {b['fmax_reached']:.2f})"
            cells.append(f"{a['calls']} / {b['calls']}{late}")
        a, b = routes["relax"]["rows"]["0.01"], routes["ASE"]["rows"]["0.01"]
        lines.append(f"| {system} | {cells[0]} | {cells[1]} "
                     f"| {a['energy']:.4f} / {b['energy']:.4f} |")
    return lines


def table(records):
    """Markdown rows per system and fmax (both routes side by side) and totals."""
    lines = ["| system | fmax (eV/Å) | force calls relax / ASE | ratio | converged relax / ASE "
             "| E relax / ASE (eV/molecule) | wall relax / ASE (s) |",
             "|---|---|---|---|---|---|---|"]
    sums = {}
    for system, routes in paired(records):
        for fmax in sorted(routes["relax"]["rows"], key=float, reverse=True):
            a, b = routes["relax"]["rows"][fmax], routes["ASE"]["rows"][fmax]
            lines.append(f"| {system} | {fmax} | {a['calls']} / {b['calls']} "
                         f"| {b['calls'] / a['calls']:.1f} | {a['converged']} / "
                         f"{b['converged']} | {a['energy']:.6f} / {b['energy']:.6f} "
                         f"| {a['wall']:.1f} / {b['wall']:.1f} |")
            if a["converged"] and b["converged"]:
                kind = parse_system(system)[0]
                for key in (kind, "all"):
                    s = sums.setdefault((fmax, key), [0, 0, 0.0, 0.0, 0, 0])
                    s[0] += a["calls"]
                    s[1] += b["calls"]
                    s[2] += a["energy"]
                    s[3] += b["energy"]
                    s[4] += 1
                    s[5] += a["energy"] > b["energy"]
    lines += ["", "| fmax (eV/Å) | systems | force calls relax / ASE | ratio "
              "| mean E relax / ASE (eV/molecule) | relax higher on |", "|---|---|---|---|---|---|"]
    for (fmax, key), (ca, cb, ea, eb, k, higher) in sorted(sums.items()):
        lines.append(f"| {fmax} | {key} ({k}) | {ca} / {cb} | {cb / ca:.2f} "
                     f"| {ea / k:.6f} / {eb / k:.6f} | {higher} |")
    return lines


def main(argv):
    parser = argparse.ArgumentParser(prog="relax.py compare")
    parser.add_argument("systems", nargs="+", help="e.g. cluster32s0 box216s1")
    parser.add_argument("--routes", default="relax,ASE")
    parser.add_argument("--fmax", type=float, nargs="+", default=list(FMAXES))
    parser.add_argument("--max-steps", type=int, default=5000)
    parser.add_argument("--timeout", type=float, default=None, help="seconds per route")
    parser.add_argument("--out", default="relax_compare.jsonl")
    parser.add_argument("--ase-own", action="store_true", help="ASE's FixBondLengths class")
    args = parser.parse_args(argv)
    # Every system and route checked before the first run (a bad route was refused only
    # after the routes before it had run and been recorded).
    for system in args.systems:
        try:
            kind, n, _ = parse_system(system)
        except ValueError:
            parser.error(f"argument systems: {system!r} is not clusterNsS or boxNsS "
                         "(e.g. cluster32s0, box216s1)")
        if n < 1 or kind == "box" and round(n ** (1 / 3)) ** 3 != n:
            parser.error(f"argument systems: {system}: a cluster of at least 1 water, or a "
                         "box of a cube number of waters")
    for route in args.routes.split(","):
        if route not in ("relax", "ASE"):
            parser.error(f"argument --routes: {route!r} is not relax or ASE")
    for system in args.systems:
        for route in args.routes.split(","):
            record = run(system, route, args.fmax, args.max_steps, args.timeout,
                         log=Path(args.out).with_suffix(".log"), own=args.ase_own)
            with open(args.out, "a") as fh:
                fh.write(json.dumps(record) + "\n")
            print(json.dumps(record), flush=True)
