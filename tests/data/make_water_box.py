"""Make ``water_box_27.traj``: 27 rigid TIP3P waters, equilibrated near 250 K.

A random lattice start (``rigidmd.systems.water_box``) has molecules pointing
hydrogens at each other; run from it, a box heats to ~2000 K within 40 fs.
This script quenches it (rigid MD with every step's velocities scaled by
0.9), then equilibrates 2 ps at 250 K with velocity rescaling every 10 steps,
with ASE's TIP3P (4.5 Å smooth cut-off, the largest the 9.3 Å cell allows).
The ASE trajectory keeps positions and momenta at full precision, and the
molecule of each atom as its tag (``bodies="tags"``).

Run:  python tests/data/make_water_box.py   (about a minute)
"""

from pathlib import Path

import numpy as np
from ase import units
from ase.calculators.tip3p import TIP3P
from ase.io import write

from rigidmd import RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.systems import water_box

OUT = Path(__file__).with_name("water_box_27.traj")


def main(temperature_K=250.0):
    atoms = water_box(3, seed=5, whole=False)  # the start this file was made from
    atoms.calc = TIP3P(rc=4.5, width=1.0)
    dyn = RigidVerlet(atoms, 0.5 * units.fs, bodies="mol-id")
    for _ in range(1500):  # quench
        dyn.run(1)
        atoms.set_momenta(0.9 * atoms.get_momenta())
    print(f"quenched: E_pot = {atoms.get_potential_energy():.4f} eV")
    rigid_maxwell_boltzmann(atoms, temperature_K, bodies="mol-id",
                            rng=np.random.default_rng(5))
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    for _ in range(200):  # 2 ps, rescaled every 10 fs
        dyn.run(10)
        atoms.set_momenta(atoms.get_momenta()
                          * np.sqrt(temperature_K / atoms.get_temperature()))
    print(f"equilibrated: E_pot = {atoms.get_potential_energy():.4f} eV, "
          f"T = {atoms.get_temperature():.1f} K")
    # Wrapped, so that molecules straddle the cell faces (ASE's TIP3P would
    # now need them made whole again; RigidVerlet does that).
    atoms.wrap()
    atoms.calc = None
    atoms.set_tags(atoms.arrays["mol-id"])
    atoms.constraints = []
    write(OUT, atoms)
    print(f"wrote {OUT.name}")


if __name__ == "__main__":
    main()
