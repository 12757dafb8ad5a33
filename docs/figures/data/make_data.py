"""Write the figures' data that no benchmark or validation script already records.

Run once, from the repository root, and commit what it writes:

    python docs/figures/data/make_data.py [nve] [tip3p] [tip4p]

* ``nve_trace.csv``: 32 rigid TIP3P waters (``water_cluster(32, seed=0)``, ASE's
  ``TIP3P(rc=20)``), rigid Maxwell-Boltzmann velocities at 300 K (seed 0), then
  ``RigidVerlet`` NVE at 1, 2 and 4 fs for 2 ps each from that one start; energies and the
  temperature every 10 fs.
* ``tip3p_rdf.csv`` and ``tip3p_msd.csv``: ``examples/tip3p_water.py --quick`` (216
  waters, LAMMPS forces, 2 ps NVE), its trajectory analysed again with
  ``rigidmd.mdanalysis``'s ``RadialDistribution`` and ``MeanSquaredDisplacement``.
* ``tip4p2005_density.csv``: ``examples/tip4p2005.py --quick`` (216 waters, C-rescale NPT,
  1 ps), the density it records every 10 steps.

Each file's first lines (``#``) say how it was made: the command, the date and the commit.
Under a minute here (the two examples' quick forms took 13 and 23 s on one core).
"""

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]


def header(what):
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return (f"# {what}\n# made by: python docs/figures/data/make_data.py "
            f"({time.strftime('%Y-%m-%d', time.gmtime())}, commit {commit})\n")


def nve():
    from ase import units
    from ase.calculators.tip3p import TIP3P

    from rigidmd import RigidVerlet, kinetic_energy, rigid_maxwell_boltzmann, temperature
    from rigidmd.systems import water_cluster

    start = water_cluster(32, seed=0)
    rigid_maxwell_boltzmann(start, 300, rng=np.random.default_rng(0))
    rows = []
    for dt_fs in (1.0, 2.0, 4.0):
        atoms = start.copy()
        atoms.calc = TIP3P(rc=20.0)
        dyn = RigidVerlet(atoms, dt_fs * units.fs)
        every = max(int(round(10 / dt_fs)), 1)

        def record(dyn=dyn, atoms=atoms, dt_fs=dt_fs):
            epot = atoms.get_potential_energy()
            ekin = kinetic_energy(atoms)
            rows.append((dt_fs, dyn.nsteps * dt_fs / 1000, epot, ekin, epot + ekin,
                         temperature(atoms)))

        dyn.attach(record, interval=every)
        dyn.run(int(2000 / dt_fs))
    text = header("32 rigid TIP3P waters (ASE TIP3P rc=20), NVE from one 300 K start, "
                  "RigidVerlet at 1, 2 and 4 fs")
    text += "dt_fs,time_ps,epot_eV,ekin_eV,etot_eV,temperature_K\n"
    text += "".join(",".join(f"{v:.10g}" for v in row) + "\n" for row in rows)
    (HERE / "nve_trace.csv").write_text(text)


def run_example(args, outdir):
    subprocess.run([sys.executable, str(ROOT / "examples" / args[0]), *args[1:],
                    "--outdir", str(outdir)], check=True)


def tip3p():
    import MDAnalysis as mda

    from rigidmd.mdanalysis import MeanSquaredDisplacement, RadialDistribution

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run_example(["tip3p_water.py", "--quick"], out)
        u = mda.Universe(str(out / "tip3p.psf"), str(out / "tip3p.xtc"))
        rdf = RadialDistribution(u, "name OW", bin_width=0.02).run().results
        msd = MeanSquaredDisplacement(u, "resname SOL").run().results
    made = "examples/tip3p_water.py --quick: 216 rigid TIP3P waters, LAMMPS forces, 2 ps NVE"
    text = header(made + "; O-O g(r), RadialDistribution(bin_width=0.02)")
    pairs = zip(rdf.bins, rdf.rdf, strict=True)
    text += "r_A,g\n" + "".join(f"{r:.4f},{g:.6g}\n" for r, g in pairs)
    (HERE / "tip3p_rdf.csv").write_text(text)
    text = header(made + f"; MSD of the centres of mass, D = "
                  f"{msd.diffusion_coefficient_cm2_s:.4g} cm2/s")
    pairs = zip(msd.lagtimes, msd.timeseries, strict=True)
    text += "lag_ps,msd_A2\n" + "".join(f"{t:.4f},{m:.6g}\n" for t, m in pairs)
    (HERE / "tip3p_msd.csv").write_text(text)


def tip4p():
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run_example(["tip4p2005.py", "--quick"], out)
        data = np.load(out / "tip4p2005_com.npz")
        densities = data["densities"]
    text = header("examples/tip4p2005.py --quick: 216 TIP4P/2005 waters, RigidCRescale "
                  "298 K 1 bar, 2 fs, density every 10 steps of the 1 ps production")
    text += "time_ps,density_g_cm3\n" + "".join(
        f"{(i + 1) * 0.02:.3f},{d:.6f}\n" for i, d in enumerate(densities))
    (HERE / "tip4p2005_density.csv").write_text(text)


if __name__ == "__main__":
    jobs = {"nve": nve, "tip3p": tip3p, "tip4p": tip4p}
    for name in sys.argv[1:] or jobs:
        jobs[name]()
