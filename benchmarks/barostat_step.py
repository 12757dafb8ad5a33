"""rigidmd's own cost of a barostatted step: time and Python calls per step, no force cost.

TIP3P-sized rigid waters (``tests/data/water_box_27.traj`` replicated) with a
calculator stand-in that costs nothing (stored zero forces, zero energy and a
fixed stress near 1 bar of liquid water), so that what is left is rigidmd's
step: the scheme's compiled loops and the coupling parts.  Rows: ``RigidVerlet``
(NVE), ``RigidNPT`` (Nosé–Hoover + MTK, iso) and ``RigidCRescale`` (Bussi +
stochastic cell rescaling, every step), on the ``"numba"`` backend (the
compiled coupling kernels, :mod:`rigidmd.couplings._numba`) and on the
``"numpy"`` backend (their NumPy references).  CPU time (this process): best of ``--rounds``
interleaved rounds of ``--steps`` steps.  Calls: Python function calls per step
counted by ``cProfile`` over 100 steps (NumPy's ufuncs are not counted; each
of its array functions is one or more calls).  Parts: the coupling parts' own share of a
step (their half steps, the drift's matrices and the variables saved for the rollback),
timed by wrapping each of those methods with ``time.perf_counter`` (wall time, best of 9
more runs of 100 steps; the wrappers add about 0.1 µs a call).

Run ``python benchmarks/barostat_step.py`` (about a minute), ``--waters 216 1728``.
"""

import argparse
import cProfile
import os
import pstats
import time
from pathlib import Path

import numpy as np
from ase import units
from ase.io import read

from rigidmd import RigidBodies, RigidCRescale, RigidNPT, RigidVerlet, rigid_maxwell_boltzmann

ROOT = Path(__file__).resolve().parents[1]


class StandIn:
    """Costs nothing: stored forces, energy and a fixed stress (eV/Å³; liquid water, ~1 bar)."""

    implemented_properties = ["energy", "forces", "stress"]

    def __init__(self, n):
        self.forces = np.zeros((n, 3))
        self.stress = np.array([-5e-4, -5e-4, -5e-4, 0.0, 0.0, 0.0])

    def get_forces(self, atoms=None, md=False):
        return self.forces

    def get_potential_energy(self, atoms=None, force_consistent=False):
        return 0.0

    def get_stress(self, atoms=None, voigt=True, include_ideal_gas=False):
        return self.stress


def water_box(waters):
    replicas = round((waters / 27) ** (1 / 3))
    base = read(ROOT / "tests" / "data" / "water_box_27.traj")
    base.positions = RigidBodies.resolve(base, "tags").whole_positions(base)
    atoms = base.repeat(replicas)
    atoms.set_tags(np.repeat(np.arange(1, len(atoms) // 3 + 1), 3))
    rigid_maxwell_boltzmann(atoms, 298, bodies="tags", rng=np.random.default_rng(0))
    return atoms


def dynamics(atoms, kind, backend):
    a = atoms.copy()
    a.calc = StandIn(len(a))
    options = dict(bodies="tags", backend=backend)
    if kind == "NVE":
        return RigidVerlet(a, units.fs, **options)
    if kind == "MTK":
        return RigidNPT(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                        1000 * units.fs, **options)
    return RigidCRescale(a, units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                         1000 * units.fs, 4.5e-5 / units.bar, rng=np.random.default_rng(1),
                         **options)


def parts_per_step(dyn, steps=100, rounds=9):
    """Wall time per step (µs) inside the coupling parts' methods: best of wrapped runs."""
    spent, depth = [0.0], [0]  # a second half that calls the first half counts once
    clock = time.perf_counter

    def timed(method):
        def run(*args):
            depth[0] += 1
            start = clock()
            try:
                return method(*args)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    spent[0] += clock() - start
        return run

    for part in dyn.couplings:  # instance attributes shadow the methods for this run only
        for name in ("first_half", "second_half", "drift_matrices", "get_state"):
            setattr(part, name, timed(getattr(part, name)))
    best = float("inf")
    try:
        for _ in range(rounds):
            spent[0] = 0.0
            dyn.run(steps)
            best = min(best, spent[0])
    finally:
        for part in dyn.couplings:
            for name in ("first_half", "second_half", "drift_matrices", "get_state"):
                delattr(part, name)
    return 1e6 * best / steps


def calls_per_step(dyn, steps=100):
    profile = cProfile.Profile()
    profile.enable()
    dyn.run(steps)
    profile.disable()
    return pstats.Stats(profile).total_calls / steps


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--waters", type=int, nargs="+", default=[216])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    for waters in args.waters:  # (100 printed "100 waters" and timed 216)
        if waters < 27 or round((waters / 27) ** (1 / 3)) ** 3 * 27 != waters:
            parser.error(f"argument --waters: {waters} is not 27 r^3 (27, 216, 729, 1728, "
                         "...): the box is the 27-water box repeated r times along each edge")
    for name in ("steps", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"argument --{name}: must be at least 1, got {getattr(args, name)}")
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; load average "
          + ", ".join(f"{v:.2f}" for v in os.getloadavg()))
    for waters in args.waters:
        atoms = water_box(waters)
        runs = {(kind, backend): dynamics(atoms, kind, backend)
                for kind in ("NVE", "MTK", "C-rescale") for backend in ("numba", "numpy")}
        times = {key: [] for key in runs}
        for dyn in runs.values():
            dyn.run(5)  # compilation and set-up out of the timing
        for _ in range(args.rounds):
            for key, dyn in runs.items():
                start = time.process_time()
                dyn.run(args.steps)
                times[key].append((time.process_time() - start) / args.steps)
        print(f"{waters} waters, {args.steps} steps, best of {args.rounds} interleaved rounds")
        print(f"{'run':>20} {'µs/step':>8} {'calls/step':>10} {'parts µs/step':>13}")
        for (kind, backend), dyn in runs.items():
            parts = f"{parts_per_step(dyn):13.1f}" if dyn.couplings else f"{'':>13}"
            print(f"{f'{kind}, {backend}':>20} {1e6 * min(times[kind, backend]):8.1f} "
                  f"{calls_per_step(dyn):10.0f} {parts}")


if __name__ == "__main__":
    main()
