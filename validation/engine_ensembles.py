"""Shows: NPT through LAMMPSEngine (fix ipi) gives in-process LAMMPS's cell and density.

Anisotropic and triclinic NPT through LAMMPSEngine: the same cell and density as in-process.

64 TIP3P waters (``rigidmd.systems.water_box(4)``; ``--n-side 6``: 216),
``lj/cut/coul/long 6.0``
and PPPM at 1e-4, 298 K and 1 atm, ``RigidNPT`` (Nosé–Hoover 100 fs, MTK
1 ps), 2 fs steps; 5 ps of equilibration, then ``--ps`` of sampling:

* ``LAMMPSCalculator`` (in-process), ``couple="aniso"``;
* ``LAMMPSEngine`` (``fix ipi``), ``couple="aniso"``;
* ``LAMMPSEngine``, ``couple="tri"`` (the cell's six degrees of freedom:
  the run that needs the virial's shear components, which ``fix ipi`` sends
  as one triangle);
* ``LAMMPSCalculator``, ``couple="tri"`` (one LAMMPS instance whose box the
  plugin changes, the cell rotated into LAMMPS's frame at each step);
* ``LAMMPSCalculator``, ``couple="iso"``.

Means with standard errors from 10 blocks: density, the three cell lengths,
the angles (triclinic).  A liquid has no shear modulus: under ``aniso`` and
``tri`` the cell's shape wanders freely at a given volume, so only the
density is to be compared between runs (the shape's means are shown to show
that wandering; 64 waters feel their cell's shape through finite-size
effects).  Written to ``validation/engine_ensembles.txt``.
"""

import argparse
from pathlib import Path

import numpy as np
from ase import units

from rigidmd import RigidNPT, rigid_maxwell_boltzmann
from rigidmd.lammps import LAMMPSCalculator, tip3p_charges
from rigidmd.lammps.engine import LAMMPSEngine
from rigidmd.systems import water_box

COMMANDS = ["pair_style lj/cut/coul/long 6.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956802 3.15061", "kspace_style pppm 1e-4"]
TYPES = {"O": 1, "H": 2}
AMU_PER_A3 = 1.66053906660  # g/cm³ per amu/Å³
RUNS = {"LAMMPSCalculator aniso": ("calc", "aniso"), "LAMMPSEngine aniso": ("engine", "aniso"),
        "LAMMPSEngine tri": ("engine", "tri"), "LAMMPSCalculator tri": ("calc", "tri"),
        "LAMMPSCalculator iso": ("calc", "iso")}


def run(kind, couple, ps, seed, equilibration_ps=5.0, n_side=4):
    atoms = water_box(n_side)
    atoms.set_initial_charges(tip3p_charges(atoms))
    rigid_maxwell_boltzmann(atoms, 298, rng=np.random.default_rng(seed))
    if kind == "engine":
        atoms.calc = LAMMPSEngine(COMMANDS, atom_types=TYPES)
    else:
        atoms.calc = LAMMPSCalculator(COMMANDS, atom_types=TYPES)
    dyn = RigidNPT(atoms, 2 * units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                   1000 * units.fs, couple=couple)
    dyn.run(int(equilibration_ps * 500))
    samples = []
    dyn.attach(lambda: samples.append(atoms.cell.cellpar()), interval=5)
    dyn.run(int(ps * 500))
    close = getattr(atoms.calc, "close", None)
    if close:
        close()
    cellpar = np.array(samples)
    mass = atoms.get_masses().sum()
    volume = np.array([np.linalg.det(atoms.cell.new(c).array) for c in cellpar])
    density = mass / volume * AMU_PER_A3
    return np.column_stack([density, cellpar])


def block_mean(values, blocks=10):
    n = len(values) // blocks * blocks
    means = values[:n].reshape(blocks, -1, values.shape[1]).mean(axis=1)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(blocks)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ps", type=float, default=20.0)
    parser.add_argument("--equilibration-ps", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--runs", nargs="*", default=list(RUNS), choices=list(RUNS))
    parser.add_argument("--append", action="store_true", help="add to the .txt")
    parser.add_argument("--n-side", type=int, default=4, help="waters per box edge")
    args = parser.parse_args()
    lines = [f"{args.n_side ** 3} TIP3P waters, 298 K, 1 atm, RigidNPT (MTK 1 ps), 2 fs; "
             f"{args.equilibration_ps:g} ps equilibration, "
             f"{args.ps:g} ps sampled, seed {args.seed}; means ± standard error (10 blocks)",
             f"{'run':>34} {'density g/cm3':>17} {'a Å':>14} {'b Å':>14} {'c Å':>14} "
             f"{'alpha':>13} {'beta':>13} {'gamma':>13}"]
    for name in args.runs:
        kind, couple = RUNS[name]
        mean, error = block_mean(run(kind, couple, args.ps, args.seed, args.equilibration_ps,
                                    args.n_side))
        cells = " ".join(f"{m:7.4f}±{e:6.4f}" for m, e in zip(mean, error, strict=True))
        lines.append(f"{name:>34} {cells}")
        print(lines[-1], flush=True)
    path = Path(__file__).with_suffix(".txt")
    before = path.read_text() + "\n" if args.append and path.exists() else ""
    path.write_text(before + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
