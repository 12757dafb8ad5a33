r"""Shows: rigidmd and LAMMPS, from one state, give the same water viscosity and diffusion.

η and D of a finished ``water_models.py`` run: rigidmd and LAMMPS from the same state.

The shear viscosity and the diffusion coefficient that ``water_models.py``
measures come from rigidmd's integrator and its molecular stress.  This
script takes the last state of a model's NVT production
(``<outdir>/runs/<model>/nvt.ckpt.npz``) and continues it at constant energy
twice: in rigidmd (:class:`rigidmd.RigidVerlet`, the benchmark's LAMMPS
calculator) and in LAMMPS itself, written as a deck by
:func:`rigidmd.lammps.deck.export_lammps` (``fix rigid/nve/small``; the same
pair style, cut-off, LJ tail and PPPM accuracy; 2 fs) and run in-process.
From one state and one energy both runs sample the same temperature, which
transport coefficients depend on steeply (D about 2.5 % per K), so the two
can be compared without a thermostat's noise.

Each run records its pressure tensor every 2 steps, the temperature with it
and the centres of mass every 0.1 ps.  rigidmd's is its molecular stress;
LAMMPS's is its own (the atomic virial with fix rigid's constraint virial
and the atoms' velocities), which differs from the molecular one by a time
derivative and has the same Green–Kubo integral.  The same analyses
(:class:`rigidmd.mdanalysis.viscosity.ShearViscosity`, the MSD fit of
``water_models.diffusion``) give η and D_PBC of each.  Temperatures are in
LAMMPS's count (6N − 3 degrees of freedom) on both sides.

Three-site models only: LAMMPS refuses atoms without mass, and rigidmd's
four-site models carry M as a massless atom.  Results go to
``<outdir>/runs/<model>/lammps_check/check.json`` and are printed.

Run::

    python validation/water_lammps_check.py --models tip3p --outdir RUNS   # ~25 min a model
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import water_models as wm  # noqa: E402  (the benchmark beside this script)

DT_PS = 0.002


def _start(name, outdir):
    """The model's last NVT state (atoms with momenta) and its results."""
    from ase.calculators.calculator import Calculator

    from rigidmd import load_checkpoint
    from rigidmd.water import water_model

    if water_model(name).sites != 3:
        raise SystemExit(f"water_lammps_check: {name} has a massless site M, which LAMMPS's "
                         "fix rigid refuses; three-site models only (tip3p, spce)")
    run = outdir / "runs" / name
    if not (run / "results.json").exists():
        raise SystemExit(f"water_lammps_check: {name} has no finished run in {outdir / 'runs'}"
                         " (run water_models.py first)")
    # The state only: each run below brings its own interactions.
    atoms = load_checkpoint(run / "nvt.ckpt.npz", Calculator()).atoms
    return atoms, json.loads((run / "results.json").read_text())


def _lammps_run(name, atoms, result, directory, nsteps, frame):
    """NVE in LAMMPS: (stress series in ASE's convention, temperatures, centres of mass)."""
    from rigidmd.lammps.deck import export_lammps
    from rigidmd.lammps.library import load_lammps
    from rigidmd.water import water_model

    pair = water_model(name).lammps_commands(result["cutoff_A"], "pppm", 1e-5,
                                             tail=result["tail"])
    out = export_lammps(atoms, np.repeat(np.arange(len(atoms) // 3), 3), directory, pair,
                        DT_PS * wm.PS, nsteps, charges=atoms.get_initial_charges(),
                        dump_every=frame, thermo_every=max(nsteps // 20, 1))
    every = wm.STRESS_EVERY
    text = out["input"].read_text()
    text = text.replace('read_data "data.rigidmd"', f'read_data "{directory / "data.rigidmd"}"')
    text = text.replace(" frames.dump ", f" {directory / 'frames.dump'} ")
    text = text.replace(f"run {nsteps}", (
        "compute rmd_p all pressure thermo_temp\n"
        f"fix rmd_p all ave/time {every} 1 {every} c_rmd_p[1] c_rmd_p[2] c_rmd_p[3] "
        f"c_rmd_p[4] c_rmd_p[5] c_rmd_p[6] c_thermo_temp file {directory / 'pressure.txt'} "
        f"format ' %.12g'\nrun {nsteps}"))
    out["input"].write_text(text)
    for stale in ("pressure.txt", "frames.dump"):
        (directory / stale).unlink(missing_ok=True)
    lmp = load_lammps(["-log", str(directory / "log.lammps"), "-screen", "none", "-nocite"])
    try:
        lmp.file(str(out["input"]))
        nktv2p = lmp.extract_global("nktv2p")  # LAMMPS's bar per eV/Å³
    finally:
        lmp.close()
    p = np.loadtxt(directory / "pressure.txt")
    # ASE's stress is minus the pressure; Voigt xx yy zz yz xz xy from LAMMPS's xx yy zz xy xz yz.
    stress = -p[:, [1, 2, 3, 6, 5, 4]] / nktv2p
    masses = atoms.get_masses().reshape(-1, 3)
    return stress, p[:, 7], _com_frames(directory / "frames.dump", masses, 3)


def _com_frames(path, masses, k):
    """Centres of mass (frames, molecules, 3) from a ``dump custom id xu yu zu ...`` file."""
    frames = []
    with open(path) as f:
        while f.readline():  # ITEM: TIMESTEP
            f.readline()
            f.readline()
            n = int(f.readline())
            for _ in range(5):  # box bounds and the ATOMS header
                f.readline()
            rows = np.array([f.readline().split()[:4] for _ in range(n)], dtype=float)
            x = rows[np.argsort(rows[:, 0]), 1:4].reshape(-1, k, 3)
            frames.append(np.einsum("ms,msk->mk", masses, x) / masses.sum(axis=1)[:, None])
    return np.array(frames)


def _rigidmd_run(name, atoms, result, nsteps, frame):
    """NVE in rigidmd: (stress series, temperatures in LAMMPS's count, centres of mass)."""
    from rigidmd import RigidVerlet

    atoms = atoms.copy()
    atoms.calc = wm.calculator(name, result["cutoff_A"])
    dyn = RigidVerlet(atoms, DT_PS * wm.PS)
    dyn.stress_on_observed_steps = True
    stress, temperature, com = [], [], []

    def record():
        stress.append(dyn.get_stress(include_ideal_gas=True))
        temperature.append(wm.temperature(dyn))

    dyn.attach(record, interval=wm.STRESS_EVERY)
    dyn.attach(lambda: com.append(dyn.com_positions), interval=frame)
    dyn.run(nsteps)
    return np.array(stress), np.array(temperature), np.array(com)


def _analyse(stress, temperature, com, volume, frame, L):
    from rigidmd.mdanalysis.thermo import block_average
    from rigidmd.mdanalysis.viscosity import ShearViscosity

    t = float(np.mean(temperature))
    gk = ShearViscosity(stress, volume, t, wm.STRESS_EVERY * DT_PS, max_lag_ps=L["max_lag"],
                        plateau_ps=L["plateau"], blocks=L["blocks"]).run().results
    com = com - com.mean(axis=1, keepdims=True)
    d_pbc, d_err = wm.diffusion(com, frame * DT_PS, L["msd_fit"], L["blocks"])
    return {"temperature_K": list(block_average(temperature)),
            "eta": [gk.viscosity_mPa_s, gk.viscosity_stderr_mPa_s],
            "D_pbc": [10 * d_pbc, 10 * d_err]}


def check(name, outdir, quick=False, lammps_ps=None):
    """Both continuations of one model, analysed alike; returns (and writes) the numbers."""
    L = wm.lengths(quick)
    ps = float(lammps_ps if lammps_ps is not None else (L["nvt_prod"] if quick else 400.0))
    if not quick:
        # Shorter than the benchmark's NVT: parts of 50 ps (five times the stress
        # correlation's longest lag) and the MSD's slope over 5-20 ps lags (the same as over
        # 10-40 ps within 1 %, measured on SPC/E's 1 ns), so that each part has both.
        L = dict(L, blocks=max(int(ps // 50), 2), msd_fit=(5.0, 20.0))
    nsteps = max(int(round(ps / DT_PS)), 1)
    frame = 5 if quick else int(round(0.1 / DT_PS))
    atoms, result = _start(name, outdir)
    directory = outdir / "runs" / name / "lammps_check"
    directory.mkdir(exist_ok=True)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    volume = atoms.get_volume()
    lammps = _lammps_run(name, atoms, result, directory, nsteps, frame)
    ours = _rigidmd_run(name, atoms, result, nsteps, frame)
    # The two runs start as one trajectory: the same temperature at step 0 (to LAMMPS's
    # Boltzmann constant, 1.1e-6 relative from ASE's) and centres of mass that part only as
    # the dynamics' chaos amplifies the constants' differences.
    start = {"temperature_step0_relative_gap": float(abs(lammps[1][0] / ours[1][0] - 1)),
             "com_gap_first_frames_A": float(np.abs(lammps[2][:5] - ours[2][:5]).max())}
    # LAMMPS's pressure at step 0 is not its dynamics' (fix rigid's virial is set only by the
    # first step: measured 2x the next steps' on a quick SPC/E box): both series start at the
    # first recorded step after it.
    lammps = (lammps[0][1:], lammps[1][1:], lammps[2])
    ours = (ours[0][1:], ours[1][1:], ours[2])
    out = {"model": name, "ps": ps, "ensemble": "NVE from the last NVT state", "start": start,
           "lammps": _analyse(*lammps, volume, frame, L),
           "rigidmd": _analyse(*ours, volume, frame, L)}
    (directory / "check.json").write_text(json.dumps(out, indent=1) + "\n")
    return out


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", nargs="+", default=["tip3p"], choices=list(wm.SETUP))
    p.add_argument("--outdir", type=Path, default=HERE, help="water_models.py's --outdir")
    p.add_argument("--ps", type=float, help="length of each run (ps; default 400)")
    p.add_argument("--quick", action="store_true", help="a smoke run of a --quick outdir")
    return p.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    results = []
    for name in args.models:
        r = check(name, args.outdir, args.quick, args.ps)
        for side in ("rigidmd", "lammps"):
            x = r[side]
            print(f"{name} {side:>7}, NVE {r['ps']:g} ps: T {x['temperature_K'][0]:.2f} ± "
                  f"{x['temperature_K'][1]:.2f} K, η {x['eta'][0]:.3f} ± {x['eta'][1]:.3f} "
                  f"mPa s, D_PBC {x['D_pbc'][0]:.2f} ± {x['D_pbc'][1]:.2f} 1e-5 cm²/s")
        results.append(r)
    return results


if __name__ == "__main__":
    main()
