"""Measure how closely rigidmd's RigidVerlet follows LAMMPS fix rigid/nve.

Prints, for water clusters of 2, 8 and 27 TIP3P molecules (and a CO2 + water
+ neon mixture), the largest atom-position gap every 100 steps of 1 fs and
the largest total-energy gap over 500 steps, with LAMMPS run on ASE's unit
constants (the algorithm alone) and on its own ``metal`` constants.  The
table of docs/validation/lammps.md and the test comments quote this script's output.

Run:  python examples/validate_against_lammps.py
"""

import sys
from pathlib import Path

import numpy as np
from ase import units
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.lammps import run_rigid_reference, tip3p_charges, tip3p_pair_commands
from rigidmd.systems import water_cluster

NSTEPS, EVERY = 500, 100


def gaps(atoms, pair, charges, labels=None, ase_constants=True, fix="rigid/nve"):
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    ref = run_rigid_reference(atoms, body_ids, pair, 1 * units.fs, NSTEPS, every=EVERY, fix=fix,
                              charges=charges, type_labels=labels, ase_constants=ase_constants)
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    pos, energy = [], []
    dyn.attach(lambda: (pos.append(atoms.positions.copy()),
                        energy.append(atoms.get_total_energy())), interval=EVERY)
    dyn.run(NSTEPS)
    gap = np.abs(np.array(pos) - ref.positions).max(axis=(1, 2))
    return gap, np.abs(np.array(energy) - ref.total_energy).max()


def water(n):
    atoms = water_cluster(n, seed=n)
    atoms.calc = TIP3P(rc=40)
    rigid_maxwell_boltzmann(atoms, 250, rng=np.random.default_rng(n))
    return atoms, tip3p_pair_commands(40.0), tip3p_charges(atoms), None


def mixture():
    """4 CO2, 4 waters and 2 neon atoms with the tests' charges + LJ force field."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from helpers import coulomb_lj_lammps
    from helpers import mixture as build

    atoms = build()
    return (atoms, *coulomb_lj_lammps(atoms))


def main():
    header = "system              constants " + " ".join(
        f"{'step ' + str(s):>9}" for s in range(0, NSTEPS + 1, EVERY)) + "   max|dE| eV"
    print("position gap (Å) to LAMMPS fix rigid/nve, 1 fs steps")
    print(header)
    systems = [("2 waters", lambda: water(2)), ("8 waters", lambda: water(8)),
               ("27 waters", lambda: water(27)), ("4 CO2+4 H2O+2 Ne", mixture)]
    for name, make in systems:
        for ase_constants in (True, False):
            atoms, pair, charges, labels = make()
            gap, de = gaps(atoms, pair, charges, labels, ase_constants)
            label = "ASE" if ase_constants else "LAMMPS"
            print(f"{name:<19} {label:<9} " + " ".join(f"{g:9.1e}" for g in gap)
                  + f"   {de:9.1e}")


if __name__ == "__main__":
    import argparse  # no options (--help started the minutes-long comparison)

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    main()
