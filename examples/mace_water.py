"""Rigid water under a machine-learned potential: MACE through its ASE calculator.

The model is built in code from a small MACE configuration (2 interactions,
16 channels, l <= 2, 5 Å cut-off; random weights from ``--seed``), so nothing
is downloaded: the run shows the mechanics (rigid bodies from MACE forces,
energy conservation, cost per step), not water's physics.  Give ``--model
FILE`` to use a trained MACE model instead (e.g. a MACE-OFF file you have).
The GPU is used when PyTorch sees one (``--device`` overrides).

Each water is one rigid body (NO_SQUISH, ``RigidVerlet``).  With a trained
``--model`` the water geometry is first relaxed with the same potential
(:func:`rigidmd.relax.relax_bodies`), so no internal strain is frozen in; the
random-weight model has no meaningful minimum, so its run keeps TIP3P's.

Needs ``pip install "rigidmd[ml]"`` (mace-torch and PyTorch; not in the test
extra).  Run::

    python examples/mace_water.py [--molecules 16] [--ps 1] [--timestep-fs 2]
        [--device cpu|cuda] [--model FILE] [--quick] [--json FILE]
"""

import argparse
import json
import time

import numpy as np
from ase import units

from rigidmd import RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.relax import relax_bodies
from rigidmd.systems import water_cluster


def small_mace(seed, dtype="float64"):
    """A small MACE model for H and O with random weights (no download)."""
    import importlib

    import torch
    from mace import modules

    o3 = importlib.import_module("e3nn.o3")  # after mace, which sets e3nn's torch.load mode

    torch.manual_seed(seed)
    block = modules.interaction_classes["RealAgnosticResidualInteractionBlock"]
    model = modules.MACE(
        r_max=5.0, num_bessel=8, num_polynomial_cutoff=5, max_ell=2,
        interaction_cls=block, interaction_cls_first=block, num_interactions=2,
        num_elements=2, hidden_irreps=o3.Irreps("16x0e + 16x1o"),
        MLP_irreps=o3.Irreps("16x0e"), gate=torch.nn.functional.silu,
        atomic_energies=np.array([-13.6, -2041.8]),  # eV, H and O: isolated-atom scale
        avg_num_neighbors=8.0, atomic_numbers=[1, 8], correlation=3)
    return model.to(getattr(torch, dtype))


def calculator(args):
    import torch
    from mace.calculators import MACECalculator

    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    if args.model:
        return MACECalculator(model_paths=args.model, device=device,
                              default_dtype="float64"), device
    return MACECalculator(models=small_mace(args.seed), device=device,
                          default_dtype="float64"), device


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--molecules", type=int, default=16)
    p.add_argument("--ps", type=float, default=1.0, help="NVE length (ps)")
    p.add_argument("--timestep-fs", type=float, default=2.0)
    p.add_argument("--device", choices=("cpu", "cuda"), help="default: cuda if available")
    p.add_argument("--model", help="a trained MACE model file instead of the small one")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", help="write the results to this file")
    p.add_argument("--quick", action="store_true", help="8 waters, 0.1 ps")
    args = p.parse_args(argv)
    if args.quick:
        args.molecules, args.ps = 8, 0.1
    for name in ("ps", "timestep_fs"):
        if not 0 < getattr(args, name) < float("inf"):
            p.error(f"argument --{name.replace('_', '-')}: must be positive, got "
                    f"{getattr(args, name)}")
    if args.molecules < 1:
        p.error(f"argument --molecules: must be at least 1, got {args.molecules}")
    import importlib.util

    missing = [m for m in ("torch", "mace") if importlib.util.find_spec(m) is None]
    if missing:  # (a ModuleNotFoundError traceback before)
        raise SystemExit(f"mace_water.py needs {' and '.join(missing)}: pip install "
                         '"rigidmd[ml]" (PyTorch and mace-torch, not in the test extra)')

    calc, device = calculator(args)
    atoms = water_cluster(args.molecules, seed=args.seed)
    if args.model:
        relaxed = relax_bodies(atoms, calc)
        water = relaxed.templates["OHH"]
        print(f"MACE on {device}: water relaxed to O-H {water.get_distance(0, 1):.4f} Å, "
              f"H-O-H {water.get_angle(1, 0, 2):.2f}° ({relaxed.strain_energies['OHH']:.3g} "
              "eV below the TIP3P geometry)")
        atoms = relaxed.atoms
    else:
        print(f"small random-weight MACE on {device}, TIP3P geometry")
    atoms.calc = calc
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(args.seed))
    dt = args.timestep_fs * units.fs
    dyn = RigidVerlet(atoms, dt)
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=5)
    steps = int(round(args.ps * 1000 / args.timestep_fs))
    start = time.perf_counter()
    dyn.run(steps)
    wall = time.perf_counter() - start
    energies = np.array(energies)
    t = np.arange(len(energies)) * 5 * args.timestep_fs / 1000
    results = {"device": device, "molecules": args.molecules, "steps": steps,
               "timestep_fs": args.timestep_fs, "ms_per_step": 1e3 * wall / steps,
               "energy_spread_eV": float(np.ptp(energies)),
               "energy_drift_eV_per_ps": float(np.polyfit(t, energies, 1)[0]),
               "degrees_of_freedom": dyn.degrees_of_freedom}
    print(f"{steps} NO_SQUISH steps of {args.timestep_fs:g} fs on {args.molecules} rigid "
          f"waters: {results['ms_per_step']:.1f} ms/step; energy spread "
          f"{results['energy_spread_eV']:.2e} eV, drift "
          f"{results['energy_drift_eV_per_ps']:+.2e} eV/ps")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return results


if __name__ == "__main__":
    main()
