r"""The configurational temperature's estimator: its bias and noise against the displacement ε.

:class:`rigidmd.core.configurational.ConfigurationalTemperature` estimates the
Laplacians :math:`\sum\nabla^2U` and :math:`\sum\mathcal L^2U` by Hutchinson's
estimator with central differences of the body forces and torques at
:math:`\pm\epsilon w`.  This script measures, on 64 rigid TIP3P waters (ASE's
TIP3P, rc 6 Å, a periodic box at 1.0 g/cm³) in frames of a 300 K Langevin run,
for each displacement (the same ε for translation, Å, and rotation, rad):

- the **bias**: the estimate with the same random vectors at ε, against the
  one at ε = 1e-3 (the central difference's error is :math:`O(\epsilon^2)`);
- the **rounding noise**: the same at ε = 1e-3 against 1e-4 and smaller;
- the **probe noise**: the relative standard deviation of one probe's value
  (over the probes of one frame), which does not depend on ε: the
  off-diagonal second derivatives that Hutchinson's vectors average away.

Results: ``configurational_eps.txt``.  Run (a minute on one core)::

    python validation/configurational_eps.py
"""

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
from arguments import whole  # noqa: E402

EPS = (1e-5, 1e-4, 1e-3, 5e-3, 2e-2, 5e-2, 1e-1)
REFERENCE = 1e-3


def frames(n_frames, seed=0):
    """Dynamics of 64 waters at 300 K, stopped at ``n_frames`` frames 100 fs apart."""
    from ase import units
    from ase.calculators.tip3p import TIP3P

    from rigidmd import RigidLangevin, rigid_maxwell_boltzmann
    from rigidmd.systems import water_box

    atoms = water_box(n_side=4, seed=seed)
    atoms.calc = TIP3P(rc=6.0)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(seed))
    dyn = RigidLangevin(atoms, 1 * units.fs, temperature_K=300, friction=0.05,
                        rng=np.random.default_rng(seed + 1))
    dyn.run(1000)  # away from the lattice
    for _ in range(n_frames):
        dyn.run(100)
        yield dyn


def main(argv=None):
    from rigidmd.core.configurational import ConfigurationalTemperature

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=whole(1), default=4)
    parser.add_argument("--probes", type=whole(2), default=16)
    parser.add_argument("--outdir", default=str(HERE))
    args = parser.parse_args(argv)
    rows = {eps: [] for eps in EPS}  # per frame: (lap_t, lap_r) as the mean of the probes
    single = []  # one probe's values at the reference ε, per frame
    for dyn in frames(args.frames):
        for eps in EPS:
            tconf = ConfigurationalTemperature(dyn, probes=args.probes, rng=7,
                                               eps_translation=eps, eps_rotation=eps)
            rows[eps].append(tconf.sample()[1:4:2])
        one = [ConfigurationalTemperature(dyn, probes=1, rng=seed, eps_translation=REFERENCE,
                                          eps_rotation=REFERENCE).sample()[1:4:2]
               for seed in range(args.probes)]
        single.append(np.std(one, axis=0, ddof=1) / np.abs(np.mean(one, axis=0)))
    ref = np.array(rows[REFERENCE])
    lines = ["Hutchinson Laplacians of 64 rigid TIP3P waters (ASE TIP3P rc 6 Å, 300 K), "
             f"{args.frames} frames, {args.probes} probes each, the same vectors at every ε",
             "relative difference from ε = 1e-3 (max over frames): translation, rotation",
             f"{'eps (Å, rad)':>13} {'translation':>12} {'rotation':>12}"]
    for eps in EPS:
        d = np.abs(np.array(rows[eps]) / ref - 1).max(axis=0)
        lines.append(f"{eps:>13.0e} {d[0]:>12.2e} {d[1]:>12.2e}")
    s = np.mean(single, axis=0)
    lines.append(f"one probe's relative standard deviation (over {args.probes} probes, mean "
                 f"over frames): translation {s[0]:.3f}, rotation {s[1]:.3f}")
    text = "\n".join(lines)
    print(text)
    (Path(args.outdir) / "configurational_eps.txt").write_text(text + "\n")
    return rows


if __name__ == "__main__":
    main()
