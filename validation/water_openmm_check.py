r"""Shows: OpenMM, from the same start with its own model files, gives the same density and ΔH_vap.

Density and ΔH_vap of ``water_models.py``'s NPT stage, run again in OpenMM.

``water_models.py`` measures each model's density and heat of vaporisation
with rigidmd's integrator, barostat and LAMMPS set-up.  This script runs the
same stage in OpenMM with OpenMM's own model files (:mod:`rigidmd.openmm`:
``tip3p``, ``spce``, ``tip4pew`` and Amber's ``opc``), its own integrator
(Langevin middle, 1/ps, 2 fs, SETTLE), thermostat and Monte Carlo barostat
(every 25 steps): another code from the same start (``water_box`` of the
same seed, molecules whole), at 298 K and 1 bar, with each model's cut-off
and long-range Lennard-Jones correction from ``water_models.SETUP`` and PME
at 1e-5.  Only the force field is shared, and only through the model files.
Energies and volumes are recorded every 0.1 ps; density and
:class:`~rigidmd.mdanalysis.thermo.HeatOfVaporization` (its polarisation
correction too) come with errors from ten blocks.

OpenMM's dispersion correction is larger than LAMMPS's by
:math:`(1 + 1/N_O) N / (N + 1)` (see :mod:`rigidmd.openmm`): at 216 waters
0.002-0.003 kJ/mol per molecule, well inside the errors.

Results go to ``<outdir>/openmm/<model>.json`` (the series to
``<model>.series.npz``) and are printed beside
``water_models.py``'s (``<outdir>/runs/<model>/results.json``, if there) and
the published value.

Run (measured: 100 + 500 ps of 216 waters in 32 min for TIP4P-Ew, 40 min for OPC, one
CPU thread each, two models side by side on two cores)::

    python validation/water_openmm_check.py --models opc tip4pew --outdir RUNS  # ~30 min a model
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import water_models as wm  # noqa: E402  (the benchmark beside this script)

FRAME_STEPS = 50  # 0.1 ps at 2 fs


def run(name, eq_ps, ps, n_side, seed, threads, series=None):
    """One model's NPT in OpenMM; returns the results (block averages of the series).

    ``series``: a path where the energy (kJ/mol) and volume (Å³) series go (``.npz``).
    """
    import openmm
    from ase import units
    from openmm import unit

    from rigidmd.mdanalysis.thermo import HeatOfVaporization, block_average
    from rigidmd.openmm import water_system
    from rigidmd.systems import water_box
    from rigidmd.water import water_model

    model = water_model(name)
    atoms = water_box(n_side, seed=seed, model=name, whole=True)
    n = len(atoms) // model.sites
    cutoff = min(wm.SETUP[name]["cutoff"], 0.49 * atoms.cell.lengths().min())
    top, system = water_system(atoms, model, cutoff, tail=wm.SETUP[name]["tail"],
                               error_tolerance=1e-5)
    kelvin = wm.TEMPERATURE_K * unit.kelvin
    system.addForce(openmm.MonteCarloBarostat(wm.PRESSURE_BAR * unit.bar, kelvin, 25))
    integrator = openmm.LangevinMiddleIntegrator(kelvin, 1 / unit.picosecond,
                                                 2 * unit.femtosecond)
    integrator.setRandomNumberSeed(seed + 1)
    context = openmm.Context(system, integrator, openmm.Platform.getPlatformByName("CPU"),
                             {"Threads": str(threads)})
    context.setPositions(atoms.positions / 10)
    context.computeVirtualSites()
    openmm.LocalEnergyMinimizer.minimize(context, 10.0, 200)
    context.setVelocitiesToTemperature(kelvin, seed + 2)
    t0 = time.perf_counter()
    integrator.step(max(int(round(eq_ps * 500)), 1))
    frames = max(int(round(ps * 500 / FRAME_STEPS)), 10)
    energy, volume = np.empty(frames), np.empty(frames)
    for i in range(frames):
        integrator.step(FRAME_STEPS)
        state = context.getState(getEnergy=True)
        energy[i] = state.getPotentialEnergy().value_in_unit(unit.kilojoule_per_mole)
        volume[i] = state.getPeriodicBoxVolume().value_in_unit(unit.angstrom**3)
    if series is not None:
        np.savez(series, energy_kj_mol=energy, volume_A3=volume, frame_ps=FRAME_STEPS / 500)
    grams = n * model.masses().sum() / units.kg * 1e3
    density = block_average(grams / (volume * 1e-24))
    hv = HeatOfVaporization(energy * units.kJ / units.mol, n, wm.TEMPERATURE_K,
                            model=model).run().results
    return {"model": name, "molecules": n, "cutoff": cutoff, "eq_ps": eq_ps, "ps": ps,
            "density": [float(v) for v in density],
            "dhvap": [hv.delta_h_kj_mol, hv.delta_h_stderr_kj_mol],
            "dhvap_corrected": hv.delta_h_corrected_kj_mol,
            "seconds": time.perf_counter() - t0,
            "openmm": openmm.__version__}


def report(result, outdir):
    """Lines of OpenMM's numbers beside water_models.py's and the published ones."""
    name = result["model"]
    ours_file = outdir / "runs" / name / "results.json"
    ours = json.loads(ours_file.read_text()) if ours_file.exists() else None
    lines = [f"{name}: OpenMM {result['openmm']}, {result['molecules']} molecules, cut-off "
             f"{result['cutoff']:.2f} Å, NPT {result['eq_ps']:g} + {result['ps']:g} ps "
             f"({result['seconds']:.0f} s)"]
    for key, label in (("density", "density (g/cm³)"), ("dhvap", "ΔH_vap (kJ/mol)")):
        value, err = result[key]
        line = f"  {label:18s} OpenMM {value:.4f} ± {err:.4f}"
        if ours is not None:
            line += f"   rigidmd {ours[key][0]:.4f} ± {ours[key][1]:.4f}"
        if key == "dhvap" and result["dhvap_corrected"] is not None:
            line += f"   (OpenMM corrected {result['dhvap_corrected']:.2f})"
        line += f"   published {wm.PUBLISHED[name][key][0]}"
        lines.append(line)
    return lines


def parse(argv=None):
    from rigidmd.openmm import FORCE_FIELD_FILES

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", nargs="+", default=list(FORCE_FIELD_FILES),
                   choices=list(FORCE_FIELD_FILES))
    p.add_argument("--outdir", type=Path, default=HERE, help="water_models.py's --outdir")
    p.add_argument("--eq-ps", type=float, default=50.0, help="equilibration (ps)")
    p.add_argument("--ps", type=float, default=250.0, help="production (ps)")
    p.add_argument("--n-side", type=int, default=6, help="waters per box edge (6: 216)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=1, help="OpenMM CPU threads")
    p.add_argument("--quick", action="store_true", help="a smoke run (0.2 + 1 ps): no results")
    args = p.parse_args(argv)
    if args.quick:
        args.eq_ps, args.ps = 0.2, 1.0
    return args


def main(argv=None):
    args = parse(argv)
    (args.outdir / "openmm").mkdir(parents=True, exist_ok=True)
    results = []
    for name in args.models:
        result = run(name, args.eq_ps, args.ps, args.n_side, args.seed, args.threads,
                     series=args.outdir / "openmm" / f"{name}.series.npz")
        (args.outdir / "openmm" / f"{name}.json").write_text(json.dumps(result, indent=1) + "\n")
        print("\n".join(report(result, args.outdir)), flush=True)
        results.append(result)
    return results


if __name__ == "__main__":
    main()
