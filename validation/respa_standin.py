"""r-RESPA on a TIP3P cluster split at 4-7 Å: force calls per ps at equal energy conservation.

16 rigid TIP3P waters (a cluster, 250 K).  The split is the stand-in of the guide's
Multiple time steps page: ``fast = TIP3P(rc=7, width=3)`` (molecule pairs within 4 Å in
full, switched off between 4 and 7 Å), ``slow = TIP3P(rc=40) - fast`` (the same fast
instance, so the difference costs one call of the full model).  For each k = 1, 2, 4, 8
and outer step Δt the NVE conserved energy's standard deviation over 0.5 ps is measured
(one start for all runs); the table gives it, the fast and slow calls per simulated ps,
and, per k, the largest Δt of the grid whose fluctuation stays under the target (that of
k = 1 at 1 fs), with its calls per ps.  A fluctuation that grows faster than Δt² marks a
resonance.  Writes respa_standin.txt; run with ``python validation/respa_standin.py``
(about 5 minutes on one core; ``--quick``: two steps, seconds).
"""

import argparse
from pathlib import Path

import numpy as np
from ase import units
from ase.calculators.mixing import LinearCombinationCalculator
from ase.calculators.tip3p import TIP3P

from rigidmd import MultipleTimeStep, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.systems import water_cluster


def start():
    atoms = water_cluster(16, seed=3)
    rigid_maxwell_boltzmann(atoms, 250, rng=np.random.default_rng(3))
    return atoms


def fluctuation(atoms, k, dt_fs, time_fs):
    atoms = atoms.copy()
    fast = TIP3P(rc=7.0, width=3.0)
    slow = LinearCombinationCalculator([TIP3P(rc=40.0), fast], [1.0, -1.0])
    atoms.calc = MultipleTimeStep(fast, slow, substeps=k)
    dyn = RigidVerlet(atoms, dt_fs * units.fs)
    steps = int(round(time_fs / dt_fs))
    energies = np.array([dyn.get_conserved_energy() for _ in dyn.irun(steps)])
    if not np.isfinite(energies).all():
        return np.inf
    return float(np.std(energies))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two steps of 50 fs, k = 1, 4")
    parser.add_argument("--output", default=str(Path(__file__).with_suffix(".txt")))
    args = parser.parse_args()
    ks, steps, time_fs = (1, 2, 4, 8), (0.5, 1, 2, 3, 4, 6, 8, 10), 500.0
    if args.quick:
        ks, steps, time_fs = (1, 4), (1, 2), 50.0
    atoms = start()
    rows, table = {}, []
    for k in ks:
        for dt in steps:
            value = fluctuation(atoms, k, dt, time_fs)
            rows[k, dt] = value
            line = (f"k = {k}  dt = {dt:4g} fs  std(E_cons) = {value:.3e} eV  "
                    f"fast calls/ps = {1000 * k / dt:6.0f}  slow calls/ps = {1000 / dt:5.0f}")
            print(line, flush=True)
            table.append(line)
    target = rows[ks[0], 1]
    table.append(f"\ntarget: k = 1 at 1 fs, std(E_cons) = {target:.3e} eV")
    for k in ks:
        fine = [dt for dt in steps if rows[k, dt] <= target]
        if not fine:
            table.append(f"k = {k}: no step of the grid meets the target")
            continue
        dt = max(fine)
        table.append(f"k = {k}: largest dt meeting it {dt:g} fs: fast calls/ps "
                     f"{1000 * k / dt:.0f}, slow calls/ps {1000 / dt:.0f} (k = 1 at 1 fs: "
                     "1000 of each)")
    text = "\n".join(table) + "\n"
    print(text)
    if not args.quick:
        Path(args.output).write_text(text)


if __name__ == "__main__":
    main()
