"""Integrator cost per step: rigidmd's RigidVerlet beside LAMMPS fix rigid/nve.

For 64, 512, 4096 and 32768 rigid TIP3P-geometry waters on a lattice, with
forces that cost nothing, this prints per step:

* rigidmd: ``RigidVerlet.run`` wall time per step (numba backend, and the
  NumPy reference path up to 4096 waters), with a calculator that hands back
  a stored zero array, skipping ASE's calculator state checks, so only the
  integrator and ASE's MD loop are timed;
* LAMMPS: the ``Modify`` line of ``fix rigid/nve``'s timing breakdown (the
  fix's own time, ``pair_style zero``), same bodies, one process;
* ASE today: ``VelocityVerlet`` with ``FixBondLengths`` (RATTLE, 3 bonds per
  water) on the same waters;

the ratio rigidmd / LAMMPS (goal: at most 1.0 at 64 waters, at most 0.5 from
4096 up) and how many times faster rigidmd is than ASE's RATTLE.  All are
measured side by side in this one run, on one core.

Run:  python benchmarks/integrator_overhead.py [--quick]

``--ratio`` measures only the ratio docs/performance.md reports: rigidmd and
LAMMPS's fix at 64 and 4096 waters, three rounds interleaved (rigidmd, then
LAMMPS, at each size, three times; ``--rounds N`` on a busy machine), best of each side::

    python benchmarks/integrator_overhead.py --ratio [--rounds 7]
"""

import argparse
import time

import numpy as np
from ase import units
from ase.constraints import FixBondLengths
from ase.md.verlet import VelocityVerlet

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.lammps import run_rigid_reference
from rigidmd.systems import water_box


class ZeroForces:
    """A calculator stand-in that costs nothing: stored zero forces and energy."""

    def __init__(self, n):
        self.forces = np.zeros((n, 3))

    def get_forces(self, atoms=None):
        return self.forces

    def get_potential_energy(self, atoms=None, force_consistent=False):
        return 0.0


def system(n_side):
    atoms = water_box(n_side, seed=1)
    rigid_maxwell_boltzmann(atoms, 300, bodies="mol-id", rng=np.random.default_rng(1))
    return atoms


def per_step(run, steps, repeats=3):
    """Best of ``repeats`` wall times per step (s) of ``run(steps)``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(steps)
        times.append((time.perf_counter() - t0) / steps)
    return min(times)


def rigidmd_time(atoms, backend, steps):
    atoms = atoms.copy()
    atoms.calc = ZeroForces(len(atoms))
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id", backend=backend)
    dyn.run(2)  # compile (numba) and warm up
    return per_step(dyn.run, steps)


def lammps_time(atoms, steps):
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    pair = ["pair_style zero 1.0", "pair_coeff * *"]
    ref = run_rigid_reference(atoms, body_ids, pair, 1 * units.fs, steps, every=steps,
                              charges=np.zeros(len(atoms)))
    return ref.timing["sections"]["Modify"] / steps


def rattle_time(atoms, steps):
    atoms = atoms.copy()
    n = len(atoms) // 3
    o = 3 * np.arange(n)
    pairs = np.concatenate([np.stack([o, o + 1], 1), np.stack([o, o + 2], 1),
                            np.stack([o + 1, o + 2], 1)])
    atoms.set_constraint(FixBondLengths(pairs))
    atoms.calc = ZeroForces(len(atoms))
    dyn = VelocityVerlet(atoms, 1 * units.fs)
    dyn.run(1)
    # FixBondLengths iterates over bonds in Python: ~8 ms per water per step,
    # so one step is timed once for large systems.
    return per_step(dyn.run, steps, repeats=3 if len(atoms) < 3 * 4096 else 1)


def ratio(sides=(4, 16), rounds=3):
    """Best-of-``rounds`` interleaved times (µs per step) of rigidmd and LAMMPS's fix."""
    print(f"{'waters':>7} {'rigidmd':>10} {'LAMMPS':>10} {'ratio':>7} {'rounds':>18}   "
          "(µs per step, best of interleaved rounds)")
    for side in sides:
        n = side**3
        atoms = system(side)
        steps = max(200, min(20_000, 1_280_000 // n))
        ours, ref = [], []
        for _ in range(rounds):
            ours.append(rigidmd_time(atoms, "numba", steps))
            ref.append(lammps_time(atoms, steps))
        each = " ".join(f"{a / b:.2f}" for a, b in zip(ours, ref, strict=True))
        print(f"{n:7d} {min(ours) * 1e6:10.1f} {min(ref) * 1e6:10.1f} "
              f"{min(ours) / min(ref):7.2f} {each:>18}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps, up to 4096 waters")
    parser.add_argument("--ratio", action="store_true",
                        help="only rigidmd / LAMMPS at 64 and 4096 waters, interleaved rounds")
    parser.add_argument("--rounds", type=int, default=3,
                        help="interleaved rounds of --ratio (more on a busy machine)")
    args = parser.parse_args()
    if args.rounds < 1:  # (an empty min() traceback after the set-up)
        parser.error(f"argument --rounds: must be at least 1, got {args.rounds}")
    if args.ratio:
        ratio(rounds=args.rounds)
        return
    sides = [4, 8, 16] if args.quick else [4, 8, 16, 32]
    print(f"{'waters':>7} {'rigidmd':>10} {'(numpy)':>10} {'LAMMPS':>10} {'ASE RATTLE':>11}"
          f" {'rigidmd/LAMMPS':>15} {'RATTLE/rigidmd':>15}   (µs per step)")
    for side in sides:
        n = side**3
        atoms = system(side)
        steps = max(20, min(2000, 400_000 // n)) // (4 if args.quick else 1)
        ours = rigidmd_time(atoms, "numba", steps)
        numpy_ref = rigidmd_time(atoms, "numpy", max(10, steps // 4)) if n <= 4096 else np.nan
        ref = lammps_time(atoms, steps * 5)
        rattle = rattle_time(atoms, 1 if n >= 4096 else 3)
        print(f"{n:7d} {ours * 1e6:10.1f} {numpy_ref * 1e6:10.1f} {ref * 1e6:10.1f}"
              f" {rattle * 1e6:11.0f} {ours / ref:15.2f} {rattle / ours:15.0f}")


if __name__ == "__main__":
    main()
