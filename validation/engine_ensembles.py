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
effects).  Written to ``validation/engine_ensembles.txt`` (``--out``) when every run is
complete; a run stopped (Ctrl-C, SIGTERM) writes nothing and says so.
"""

import argparse
import os
import signal
import sys
from pathlib import Path

import numpy as np
from ase import units

from rigidmd import RigidNPT, rigid_maxwell_boltzmann
from rigidmd.lammps import LAMMPSCalculator, tip3p_charges
from rigidmd.lammps.engine import LAMMPSEngine
from rigidmd.systems import water_box

sys.path.insert(0, str(Path(__file__).resolve().parent))  # arguments.py, beside this script
from arguments import at_least_zero, positive, whole  # noqa: E402

COMMANDS = ["pair_style lj/cut/coul/long 6.0", "pair_coeff * * 0.0 1.0",
            "pair_coeff 1 1 0.0065956802 3.15061", "kspace_style pppm 1e-4"]
TYPES = {"O": 1, "H": 2}
AMU_PER_A3 = 1.66053906660  # g/cm³ per amu/Å³
RUNS = {"LAMMPSCalculator aniso": ("calc", "aniso"), "LAMMPSEngine aniso": ("engine", "aniso"),
        "LAMMPSEngine tri": ("engine", "tri"), "LAMMPSCalculator tri": ("calc", "tri"),
        "LAMMPSCalculator iso": ("calc", "iso")}
BLOCKS = 10  # of the means' standard errors
EVERY = 5  # steps between samples


def run(kind, couple, ps, seed, equilibration_ps=5.0, n_side=4):
    atoms = water_box(n_side)
    atoms.set_initial_charges(tip3p_charges(atoms))
    rigid_maxwell_boltzmann(atoms, 298, rng=np.random.default_rng(seed))
    if kind == "engine":
        atoms.calc = LAMMPSEngine(COMMANDS, atom_types=TYPES)
    else:
        atoms.calc = LAMMPSCalculator(COMMANDS, atom_types=TYPES)
    try:
        dyn = RigidNPT(atoms, 2 * units.fs, 298, 1.01325 * units.bar, 100 * units.fs,
                       1000 * units.fs, couple=couple)
        dyn.run(int(equilibration_ps * 500))
        samples = []
        dyn.attach(lambda: samples.append(atoms.cell.cellpar()), interval=EVERY)
        dyn.run(int(ps * 500))
    finally:  # also when stopped: the engine's lmp ends here
        close = getattr(atoms.calc, "close", None)
        if close:
            close()
    cellpar = np.array(samples)
    mass = atoms.get_masses().sum()
    volume = np.array([np.linalg.det(atoms.cell.new(c).array) for c in cellpar])
    density = mass / volume * AMU_PER_A3
    return np.column_stack([density, cellpar])


def block_mean(values, blocks=BLOCKS):
    n = len(values) // blocks * blocks
    means = values[:n].reshape(blocks, -1, values.shape[1]).mean(axis=1)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(blocks)


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP: raised in the run, so that it ends as a Ctrl-C does."""


def _stop(signum, frame):
    raise Stopped(signal.Signals(signum).name)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ps", type=positive, default=20.0,
                        help=f"ps sampled (a sample every {EVERY} steps of 2 fs; at least "
                             f"{BLOCKS} samples, for the {BLOCKS} blocks)")
    parser.add_argument("--equilibration-ps", type=at_least_zero, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--runs", nargs="*", default=list(RUNS), choices=list(RUNS))
    parser.add_argument("--append", action="store_true", help="add to --out")
    parser.add_argument("--n-side", type=whole(2), default=4, help="waters per box edge")
    parser.add_argument("--out", type=Path, default=Path(__file__).with_suffix(".txt"),
                        help="the table, written when every run is complete "
                             "(default: %(default)s)")
    args = parser.parse_args(argv)
    samples = int(args.ps * 500) // EVERY
    if samples < BLOCKS:
        parser.error(f"argument --ps: {args.ps:g} ps gives {samples} samples, fewer than the "
                     f"{BLOCKS} blocks (at least {BLOCKS * EVERY / 500:g} ps)")
    if not args.runs:
        parser.error("argument --runs: no run named")
    if not args.out.parent.is_dir():
        parser.error(f"argument --out: no folder {args.out.parent}")
    lines = [f"{args.n_side ** 3} TIP3P waters, 298 K, 1 atm, RigidNPT (MTK 1 ps), 2 fs; "
             f"{args.equilibration_ps:g} ps equilibration, "
             f"{args.ps:g} ps sampled, seed {args.seed}; means ± standard error (10 blocks)",
             f"{'run':>34} {'density g/cm3':>17} {'a Å':>14} {'b Å':>14} {'c Å':>14} "
             f"{'alpha':>13} {'beta':>13} {'gamma':>13}"]
    handlers = {sig: signal.signal(sig, _stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        for i, name in enumerate(args.runs):
            print(f"[{i + 1}/{len(args.runs)}] {name}: {args.equilibration_ps:g} ps "
                  f"equilibration, {args.ps:g} ps sampled ...", flush=True)
            kind, couple = RUNS[name]
            mean, error = block_mean(run(kind, couple, args.ps, args.seed,
                                         args.equilibration_ps, args.n_side))
            cells = " ".join(f"{m:7.4f}±{e:6.4f}" for m, e in zip(mean, error, strict=True))
            lines.append(f"{name:>34} {cells}")
            print(lines[-1], flush=True)
            if not np.all(np.isfinite(mean)):
                raise SystemExit(f"engine_ensembles.py: {name} gave non-finite means: nothing "
                                 f"written to {args.out}")
    except KeyboardInterrupt as why:  # Stopped too
        raise SystemExit(f"engine_ensembles.py: stopped ({str(why) or 'SIGINT'}) after "
                         f"{len(lines) - 2} of {len(args.runs)} runs: nothing written to "
                         f"{args.out}") from None
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    before = args.out.read_text() + "\n" if args.append and args.out.exists() else ""
    tmp = args.out.with_name(args.out.name + ".tmp")
    tmp.write_text(before + "\n".join(lines) + "\n")
    os.replace(tmp, args.out)


if __name__ == "__main__":
    main()
