"""Force calls to relax rigid water: rigidmd's RigidFilter against ASE's FixBondLengths.

ASE's route to a minimum of rigid molecules is an optimizer on the atoms with
``FixBondLengths`` on the three distances of every water (RATTLE-like
projection of positions and forces); rigidmd's is the same optimizer on
:class:`rigidmd.optimize.RigidFilter` (centres of mass, rotation vectors).
Both start from the same structure, a minimum perturbed by a random rigid
displacement of every molecule (centre of mass 0.1 Å, rotation 0.1 rad,
normal distributions), so that both fall back into one basin, and use ASE's
BFGS (default ``maxstep`` 0.2, ``alpha`` 70) with ASE's TIP3P calculator and
``FixBondLengths`` as ASE sets it up (its force projection runs its 500
iterations at every call on water triangles, about 1 s of CPU per step for 8
waters: wall times are ASE's, the force calls are the comparison).

Systems: a 32-water cluster (``water_cluster(32)``, ``TIP3P(rc=20)``, no
cutoff reached) and a periodic box of 64 waters (``water_box(4)``, 12.4 Å,
``TIP3P(rc=6)``).  The minimum is the rigid relaxation to ``fmax`` 1e-4 eV/Å
of the built structure.  Reported per ``fmax`` (0.05 and 0.01 eV/Å): force
calls (calculator evaluations, counted in the calculator), optimizer steps and
the energy left above the minimum per molecule.

Run::

    python benchmarks/relax.py              # everything, in turn
    python benchmarks/relax.py cluster 0.01  # one system and fmax (rows to stdout)

Results are written to ``benchmarks/relax.txt``.
"""

import time
from pathlib import Path

import numpy as np
from ase.calculators.tip3p import TIP3P
from ase.constraints import FixBondLengths
from ase.optimize import BFGS

from rigidmd import quaternion as quat
from rigidmd.optimize import RigidFilter, relax
from rigidmd.systems import random_quaternions, water_box, water_cluster


class CountingTIP3P(TIP3P):
    """ASE's TIP3P, counting its evaluations."""

    calls = 0

    def calculate(self, *args, **kwargs):
        CountingTIP3P.calls += 1
        super().calculate(*args, **kwargs)


def perturbed(atoms, seed, shift=0.1, angle=0.1):
    """Every water moved rigidly: centre of mass by N(0, shift) Å, turned by N(0, angle) rad."""
    rng = np.random.default_rng(seed)
    n = len(atoms) // 3
    out = atoms.copy()
    x = RigidFilter(atoms).get_positions()[:n]  # centres of mass (whole molecules)
    positions = out.positions.reshape(n, 3, 3)
    from rigidmd.bodies import RigidBodies
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


def run(system, rc, fmax):
    """Force calls, steps and final energy of both routes from one start."""
    rows = []
    start = system
    rigid = start.copy()
    rigid.calc = CountingTIP3P(rc=rc)
    CountingTIP3P.calls = 0
    t = time.perf_counter()
    result = relax(rigid, fmax=fmax, steps=5000)
    rows.append(("RigidFilter", CountingTIP3P.calls, result.steps, result.converged,
                 rigid.get_potential_energy(), time.perf_counter() - t))
    atomic = start.copy()
    atomic.calc = CountingTIP3P(rc=rc)
    n = len(atomic) // 3
    atomic.set_constraint(FixBondLengths(
        [(3 * i + a, 3 * i + b) for i in range(n) for a, b in ((0, 1), (0, 2), (1, 2))]))
    CountingTIP3P.calls = 0
    t = time.perf_counter()
    with BFGS(atomic, logfile=None) as opt:
        converged = opt.run(fmax=fmax, steps=5000)
        steps = opt.nsteps
    rows.append(("FixBondLengths", CountingTIP3P.calls, steps, converged,
                 atomic.get_potential_energy(), time.perf_counter() - t))
    return rows


HEADER = ["# Force calls to relax rigid TIP3P water (BFGS): RigidFilter vs FixBondLengths",
          "",
          "Start: the minimum (rigid BFGS to fmax 1e-4 eV/Å), every molecule moved rigidly "
          "(0.1 Å, 0.1 rad).",
          "ΔE: energy above the minimum per molecule (eV). Wall times with other jobs on the "
          "machine (2 cores shared, load 10-16).",
          "",
          "| system | fmax (eV/Å) | route | force calls | steps | converged | ΔE (eV/molecule) "
          "| wall (s) |",
          "|---|---|---|---|---|---|---|---|"]

SYSTEMS = {"cluster": ("32-water cluster", lambda: water_cluster(32, seed=0), 20.0),
           "box": ("64-water box", lambda: water_box(4, seed=0), 6.0)}


def rows(key, fmaxes):
    """Table rows of one system for each ``fmax``."""
    name, build, rc = SYSTEMS[key]
    atoms = build()
    atoms.calc = TIP3P(rc=rc)
    relax(atoms, fmax=1e-4, steps=5000)
    minimum = atoms.get_potential_energy()
    n = len(atoms) // 3
    start = perturbed(atoms, seed=1)
    start.calc = None
    out = []
    for fmax in fmaxes:
        for route, calls, steps, converged, energy, wall in run(start, rc, fmax):
            out.append(f"| {name} | {fmax} | {route} | {calls} | {steps} | {converged} "
                       f"| {(energy - minimum) / n:.2e} | {wall:.1f} |")
            print(out[-1], flush=True)
    return out


def main():
    import sys

    if len(sys.argv) == 3:
        rows(sys.argv[1], [float(sys.argv[2])])
        return
    lines = HEADER + rows("cluster", (0.05, 0.01)) + rows("box", (0.05, 0.01))
    text = "\n".join(lines) + "\n"
    Path(__file__).with_suffix(".txt").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
