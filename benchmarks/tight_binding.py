"""The time-step payoff of rigid water under tight binding (tblite, GFN2-xTB).

The same water cluster (GFN2-xTB's own water geometry, from
:func:`rigidmd.relax.relax_bodies`, 300 K) is run

* rigid, ``RigidVerlet`` (NO_SQUISH) at 1, 2 and 4 fs, and
* flexible, ASE's ``VelocityVerlet`` at 0.25 and 0.5 fs (every atom free),

each for ``--ps`` of simulated time, side by side in one process on one
thread.  Reported per run: the total-energy drift (slope of a straight-line
fit, eV/ps) and its peak-to-peak spread, force calls per ps, wall time per ps
of simulated time.  Then, at 64 and 512 molecules, the fraction of a rigid
step spent outside the force call (rigidmd's own cost around an expensive
calculator), timed with a wrapper around the calculator.

Run::

    OMP_NUM_THREADS=1 python benchmarks/tight_binding.py [--molecules 8] [--ps 2]

The results are printed; ``--output FILE`` also writes them there.  The recorded run is
``benchmarks/tight_binding.txt`` (its 512-water row by hand: that call did not end), from
which the docs' figure is drawn: a run writes over it only when named as ``--output``.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from ase import units  # noqa: E402
from ase.calculators.calculator import Calculator, all_changes  # noqa: E402
from ase.md.velocitydistribution import MaxwellBoltzmannDistribution, Stationary  # noqa: E402
from ase.md.verlet import VelocityVerlet  # noqa: E402
from tblite.ase import TBLite  # noqa: E402

from rigidmd import RigidVerlet, kinetic_energy, rigid_maxwell_boltzmann  # noqa: E402
from rigidmd.relax import relax_bodies  # noqa: E402
from rigidmd.systems import water_cluster  # noqa: E402

PS = 1000 * units.fs


class Timed(Calculator):
    """Forwards to another calculator and adds up the time spent in it."""

    implemented_properties = ["energy", "forces"]

    def __init__(self, inner):
        super().__init__()
        self.inner = inner
        self.seconds = 0.0
        self.calls = 0

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        start = time.perf_counter()
        copy = self.atoms.copy()
        copy.calc = self.inner
        self.results = {"energy": copy.get_potential_energy(), "forces": copy.get_forces()}
        self.seconds += time.perf_counter() - start
        self.calls += 1


def gfn2():
    return TBLite(method="GFN2-xTB", verbosity=0)


def run(atoms, dyn, steps, dt_fs):
    """Energies every 10 fs, wall time per ps and force calls per ps."""
    energies = []
    every = max(int(round(10 / dt_fs)), 1)
    dyn.attach(lambda: energies.append(atoms.get_potential_energy() + kinetic_energy(atoms)),
               interval=every)
    calc = atoms.calc
    calls = calc.calls
    start = time.perf_counter()
    dyn.run(steps)
    wall = time.perf_counter() - start
    ps = steps * dt_fs / 1000
    energies = np.array(energies)
    t = np.arange(len(energies)) * every * dt_fs / 1000
    return {"drift": np.polyfit(t, energies, 1)[0], "spread": np.ptp(energies),
            "calls_per_ps": (calc.calls - calls) / ps, "wall_per_ps": wall / ps}


def payoff(n, ps, lines):
    start = water_cluster(n, seed=3)
    relaxed = relax_bodies(start, gfn2())
    base = relaxed.atoms
    lines.append(f"{n} waters, GFN2-xTB geometry (O-H "
                 f"{relaxed.templates['OHH'].get_distance(0, 1):.4f} Å, "
                 f"{relaxed.templates['OHH'].get_angle(1, 0, 2):.2f}°), 300 K, {ps:g} ps each")
    header = "| run | step (fs) | drift (eV/ps) | spread (eV) | force calls / ps | wall s / ps |"
    lines += [header, "|---|---|---|---|---|---|"]
    results = {}
    for dt in (1.0, 2.0, 4.0):
        atoms = base.copy()
        atoms.calc = Timed(gfn2())
        rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(7))
        r = run(atoms, RigidVerlet(atoms, dt * units.fs), int(round(ps * 1000 / dt)), dt)
        results[("rigid", dt)] = r
    for dt in (0.25, 0.5):
        atoms = base.copy()
        atoms.calc = Timed(gfn2())
        MaxwellBoltzmannDistribution(atoms, temperature_K=300, rng=np.random.default_rng(7))
        Stationary(atoms)
        r = run(atoms, VelocityVerlet(atoms, dt * units.fs), int(round(ps * 1000 / dt)), dt)
        results[("flexible", dt)] = r
    for (kind, dt), r in results.items():
        lines.append(f"| {kind} | {dt:g} | {r['drift']:+.2e} | {r['spread']:.2e} | "
                     f"{r['calls_per_ps']:.0f} | {r['wall_per_ps']:.1f} |")
    return results


class Replay(Calculator):
    """Returns the same forces every call: rigidmd's own step cost, the force call aside."""

    implemented_properties = ["energy", "forces"]

    def __init__(self, forces):
        super().__init__()
        self.forces = forces

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.results = {"energy": 0.0, "forces": self.forces.copy()}


def overhead(n, steps, lines, gfn2_call=True):
    """Fraction of a rigid step outside the force call, n waters, GFN2-xTB.

    Without ``gfn2_call`` the forces are replayed (random, of thermal size) and
    only rigidmd's own time is measured: a GFN2-xTB call on 512 waters takes more
    than 10 minutes on one thread here, so the fraction is bounded by that.
    """
    atoms = water_cluster(n, seed=3, tries=1 if n > 100 else 64)
    if gfn2_call:
        atoms.calc = Timed(gfn2())
    else:
        forces = np.random.default_rng(0).normal(scale=0.5, size=(len(atoms), 3))
        atoms.calc = Timed(Replay(forces))
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(7))
    dyn = RigidVerlet(atoms, 2 * units.fs)
    dyn.run(1)  # the first call (and numba's compilation) out of the timing
    inside, calls = atoms.calc.seconds, atoms.calc.calls
    start = time.perf_counter()
    dyn.run(steps)
    wall = time.perf_counter() - start
    inside = atoms.calc.seconds - inside
    per_step = wall / steps
    outside = (wall - inside) / steps
    if gfn2_call:
        lines.append(f"| {n} | {per_step * 1e3:.1f} | {inside / steps * 1e3:.1f} | "
                     f"{outside * 1e3:.2f} | {100 * outside / per_step:.2f} % | "
                     f"{(atoms.calc.calls - calls) / steps:.0f} |")
    else:
        lines.append(f"| {n} | > 600 000 (one GFN2-xTB call did not end in 600 s) | "
                     f"> 600 000 | {outside * 1e3:.2f} | < {100 * outside / 600:.1e} % | 1 |")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--molecules", type=int, default=8)
    p.add_argument("--ps", type=float, default=2.0)
    p.add_argument("--overhead", type=int, nargs="*", default=[64, 512],
                   help="cluster sizes for the overhead measurement")
    p.add_argument("--output", type=Path,
                   help="also write the results here (default: printed only)")
    args = p.parse_args()
    lines = [f"# {__doc__.splitlines()[0]}", ""]
    payoff(args.molecules, args.ps, lines)
    lines += ["", "Overhead: rigid NO_SQUISH step at 2 fs, GFN2-xTB clusters, one thread",
              "| waters | ms / step | in the force call | outside | fraction | calls / step |",
              "|---|---|---|---|---|---|"]
    for n in args.overhead:
        overhead(n, 10, lines, gfn2_call=n <= 100)
    text = "\n".join(lines) + "\n"
    if args.output is not None:
        args.output.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
