"""Liquid TIP3P water with rigid bodies: LAMMPS forces, MDAnalysis analyses.

A periodic box of rigid TIP3P waters (216 by default, 18.6 Å, 1.0 g/cm³)
with forces from LAMMPS through :class:`rigidmd.lammps.LAMMPSCalculator`
(``lj/cut/coul/long``, long-range electrostatics by PPPM or Ewald;
intramolecular pairs excluded, as in native LAMMPS).  The random lattice start is
quenched with strong Langevin friction, equilibrated at 298 K with the Bussi
thermostat, its centre-of-mass motion removed, then run in NVE at 2 fs with
``RigidVerlet`` while
``rigidmd.mdanalysis.MDAWriter`` streams an XTC trajectory (PSF topology).
MDAnalysis then gives the O–O radial distribution function, the diffusion
coefficient from the mean-squared displacement of the molecular centres of
mass, and the rotational correlation of the molecular dipoles with their
relaxation times, printed beside published values.

Run (a few minutes on two cores; ``--quick`` about half a minute)::

    python examples/tip3p_water.py [--outdir DIR] [--quick]
        [--equilibration-ps 20] [--production-ps 50] [--kspace pppm|ewald]
        [--analyse-only]

Writes to ``--outdir``: ``tip3p.psf`` and ``tip3p.xtc`` (read them with
``MDAnalysis.Universe("tip3p.psf", "tip3p.xtc")``), ``tip3p_rdf.png``,
``tip3p_msd.png``, ``tip3p_rotation.png``, ``tip3p_results.json`` and the MD
log ``tip3p.log``.

Each phase reports its progress at every quarter.  Ctrl-C or SIGTERM finishes the step
under way; in the production it closes the trajectory and the log whole, and
``--analyse-only`` then analyses what was run; before it nothing is kept (run again).
"""

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np
from ase import units
from ase.md.velocitydistribution import Stationary

from rigidmd import RigidBodies, RigidBussi, RigidLangevin, RigidVerlet
from rigidmd.lammps import tip3p_charges
from rigidmd.mdanalysis import (
    PS,
    MDAWriter,
    MeanSquaredDisplacement,
    RadialDistribution,
    RotationalCorrelation,
)
from rigidmd.systems import water_box

#: TIP3P O–O Lennard-Jones parameters (Jorgensen et al. 1983): 0.1521 kcal/mol, 3.15061 Å.
EPSILON_OO = 0.1521 * units.kcal / units.mol
SIGMA_OO = 3.15061
TEMPERATURE_K = 298.0

#: Published numbers printed beside ours; every entry was checked against the
#: source named (see the README); "not verified" where we could not.
REFERENCES = {
    "rdf": ("TIP3P O–O first peak: not verified here (see Jorgensen et al., J. Chem. Phys. "
            "79, 926 (1983); Mark & Nilsson, J. Phys. Chem. A 105, 9954 (2001))"),
    "diffusion": [
        ("TIP3P (CHARMM-modified, LJ on H), 298 K", 5.85,
         "Mark & Nilsson, J. Phys. Chem. A 105, 9954 (2001): 5.85 ± 0.08"),
        ("TIP3P re-fitted for Ewald (Price & Brooks)", 4.0,
         "Price & Brooks, J. Chem. Phys. 121, 10096 (2004); faster for the original"),
        ("experiment, 298 K", 2.299, "Mills 1973, as tabulated by Fennell (2006)"),
    ],
    "tau2": ("experiment: 2.3 ps (Krynicki 1966), 1.95-2.0 ps for O-H/H-H vectors by NMR; "
             "dipole itself not measurable (Fennell 2006; SklogWiki 'Rotational relaxation')"),
    "tau1": "experiment: 5.7 ps (Eisenberg & Kauzmann 1969, as tabulated by Fennell 2006)",
}

#: Shear viscosity of real water at 298 K (mPa s), SklogWiki, for the Yeh-Hummer term.
WATER_VISCOSITY_MPAS = 0.896


def lammps_calculator(kspace="pppm", accuracy=1e-5, cutoff=9.0):
    """:class:`~rigidmd.lammps.LAMMPSCalculator` for TIP3P with long-range electrostatics.

    Molecules come from the atoms' ``mol-id`` array; pairs within a molecule
    are excluded.

    Parameters
    ----------
    kspace : {"pppm", "ewald"}
    accuracy : float
        Relative force accuracy of the k-space solver.
    cutoff : float
        Real-space cut-off of LJ and Coulomb (Å), at most half the box.
    """
    from rigidmd.lammps import LAMMPSCalculator

    commands = [f"pair_style lj/cut/coul/long {cutoff}",
                "pair_coeff * * 0.0 1.0",  # no LJ on H (original TIP3P)
                f"pair_coeff 1 1 {EPSILON_OO!r} {SIGMA_OO}",
                f"kspace_style {kspace} {accuracy}"]
    return LAMMPSCalculator(commands, atom_types={"O": 1, "H": 2})


def body_forces_and_torques(atoms, bodies, forces):
    """Total force (eV/Å) and torque about the centre of mass (eV) of every body.

    Returns
    -------
    F, tau : numpy.ndarray, shape (n_bodies, 3)
    """
    g = bodies.geometry(atoms)
    x = bodies.whole_positions(atoms)[g.model.order]
    f = forces[g.model.order]
    r = x - g.com[g.model.atom_body]
    return np.add.reduceat(f, g.model.starts), np.add.reduceat(np.cross(r, f), g.model.starts)


def compare_kspace(atoms, bodies, kspace, accuracy, cutoff):
    """Body forces and torques from ``kspace`` against Ewald at 1e-7 (relative RMS)."""
    calc = lammps_calculator("ewald", 1e-7, cutoff)
    reference = atoms.copy()
    reference.calc = calc
    F0, T0 = body_forces_and_torques(reference, bodies, reference.get_forces())
    test = atoms.copy()
    test.calc = lammps_calculator(kspace, accuracy, cutoff)
    F1, T1 = body_forces_and_torques(test, bodies, test.get_forces())

    def rel(a, b):
        return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2)))

    return rel(F1, F0), rel(T1, T0)


class Stopped(Exception):
    """A stop signal ended the phase ``name`` after ``done`` of its ``steps``."""

    def __init__(self, name, done, steps, dt_ps):
        super().__init__(name)
        self.name, self.done, self.steps, self.dt_ps = name, done, steps, dt_ps


#: The signal that asked the run to stop (None: none).
STOP = {"signal": None}


def ask_to_stop(signum, frame):
    STOP["signal"] = signal.Signals(signum).name
    print(f"{STOP['signal']}: stopping after the step under way", flush=True)


def run_steps(dyn, steps, name, log):
    """``dyn.run(steps)``, ten steps at a time: progress at each quarter, and
    :class:`Stopped` after the step under way when a stop signal came."""
    reports = {steps * q // 4 for q in (1, 2, 3)} - {0}
    dt_ps = dyn.dt / (1000 * units.fs)
    done = 0
    while done < steps:
        if STOP["signal"]:
            raise Stopped(name, done, steps, dt_ps)
        due = min([r for r in reports if r > done] + [steps])
        chunk = min(10, due - done)
        dyn.run(chunk)
        done += chunk
        if done in reports:
            log(f"{name} {done * dt_ps:g} / {steps * dt_ps:g} ps")


def equilibrate(atoms, args, log):
    """Quench the lattice start, then thermalise at 298 K; return the elapsed time (s)."""
    start = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    # Strong friction (damping time 5 fs) at half-femtosecond steps: the
    # lattice start has overlapping molecules and would heat by thousands of K.
    quench = RigidLangevin(atoms, 0.5 * units.fs, temperature_K=TEMPERATURE_K,
                           friction=0.2 / units.fs, rng=rng, bodies="mol-id")
    run_steps(quench, max(int(round(args.quench_ps * 1000 / 0.5)), 1), "quench", log)
    log(f"quench: {quench.nsteps} steps of 0.5 fs, T = {atoms.get_temperature():.0f} K")
    dt = args.timestep_fs * units.fs
    steps = max(int(round(args.equilibration_ps * 1000 / args.timestep_fs)), 1)
    if args.thermostat == "bussi":
        thermo = RigidBussi(atoms, dt, temperature_K=TEMPERATURE_K, taut=100 * units.fs,
                            rng=rng, bodies="mol-id")
    else:
        thermo = RigidLangevin(atoms, dt, temperature_K=TEMPERATURE_K,
                               friction=0.01 / units.fs, rng=rng, bodies="mol-id")
    temperatures = []
    thermo.attach(lambda: temperatures.append(atoms.get_temperature()), interval=10)
    run_steps(thermo, steps, "equilibration", log)
    last = np.array(temperatures[len(temperatures) // 2:])
    log(f"equilibration: {args.equilibration_ps:g} ps with {args.thermostat} at "
        f"{TEMPERATURE_K:g} K, second half T = {last.mean():.1f} ± {last.std():.1f} K")
    return time.perf_counter() - start


def production(atoms, args, outdir, log):
    """NVE run streamed to tip3p.xtc; returns (energies (eV), frame interval (ps), elapsed s)."""
    dt = args.timestep_fs * units.fs
    steps = max(int(round(args.production_ps * 1000 / args.timestep_fs)), 1)
    every = max(int(round(args.sample_fs / args.timestep_fs)), 1)
    # Thermostats leave the box with a random total momentum of thermal size
    # (here ~0.3 Å/ps), which would add V² t² to the MSD: remove it.  A uniform
    # velocity is a rigid motion, so nothing else changes.
    v_cm = atoms.get_momenta().sum(axis=0) / atoms.get_masses().sum()
    Stationary(atoms)
    log(f"removed the centre-of-mass velocity, {np.linalg.norm(v_cm) * PS:.3f} Å/ps")
    logfile = outdir / "tip3p.log"
    logfile.unlink(missing_ok=True)
    dyn = RigidVerlet(atoms, dt, bodies="mol-id", logfile=str(logfile),
                      loginterval=max(steps // 50, 1))
    energies = []
    dyn.attach(lambda: energies.append(atoms.get_total_energy()), interval=every)
    start = time.perf_counter()
    with MDAWriter(dyn, outdir / "tip3p.xtc", overwrite=True) as writer:  # closed whole,
        dyn.attach(writer, interval=every)  # also after a stop (the log is flushed by line)
        run_steps(dyn, steps, "production", log)
    elapsed = time.perf_counter() - start
    log(f"production: {steps} NVE steps of {args.timestep_fs:g} fs ({args.production_ps:g} ps), "
        f"{writer.n_frames} frames every {every * args.timestep_fs:g} fs, "
        f"{1e3 * elapsed / steps:.1f} ms/step")
    return np.array(energies), every * args.timestep_fs * 1e-3, elapsed


def yeh_hummer(box_length, viscosity_mpas, temperature_K=TEMPERATURE_K):
    """Finite-size correction 2.837297 kB T / (6 pi eta L) in cm²/s (Yeh & Hummer 2004)."""
    kT = 1.380649e-23 * temperature_K
    return 2.837297 * kT / (6 * math.pi * viscosity_mpas * 1e-3 * box_length * 1e-10) * 1e4


def analyse(outdir, log):
    """RDF, MSD and rotational correlation from the written trajectory."""
    import MDAnalysis as mda

    u = mda.Universe(str(outdir / "tip3p.psf"), str(outdir / "tip3p.xtc"))
    rdf = RadialDistribution(u, "name OW", bin_width=0.02).run()
    rdf.plot(outdir / "tip3p_rdf.png")
    msd = MeanSquaredDisplacement(u, "resname SOL").run()
    msd.plot(outdir / "tip3p_msd.png")
    # The three Cartesian directions are independent estimates: their spread
    # gives a rough statistical error.
    msd.results.per_axis = [MeanSquaredDisplacement(u, "resname SOL", msd_type=axis).run()
                            .results.diffusion_coefficient_cm2_s for axis in "xyz"]
    rot = RotationalCorrelation(u, "resname SOL", vector="dipole",
                                max_lag=min(10.0, u.trajectory.totaltime / 2)).run()
    rot.plot(outdir / "tip3p_rotation.png")
    log(f"analysed {u.trajectory.n_frames} frames, {len(u.residues)} molecules "
        f"({u.trajectory.totaltime:.2f} ps)")
    return u, rdf.results, msd.results, rot.results


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--outdir", type=Path, default=Path("."), help="output directory")
    p.add_argument("--n-side", type=int, default=6, help="waters per box edge (6: 216)")
    p.add_argument("--spacing", type=float, default=3.1, help="lattice spacing (Å)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--kspace", choices=("pppm", "ewald"), default="pppm")
    p.add_argument("--accuracy", type=float, default=1e-5, help="k-space relative accuracy")
    p.add_argument("--cutoff", type=float, default=9.0, help="real-space cut-off (Å)")
    p.add_argument("--thermostat", choices=("bussi", "langevin"), default="bussi")
    p.add_argument("--quench-ps", type=float, help="default 0.2 (--quick: 0.1)")
    p.add_argument("--equilibration-ps", type=float, help="default 20 (--quick: 1)")
    p.add_argument("--production-ps", type=float, help="default 50 (--quick: 2)")
    p.add_argument("--timestep-fs", type=float, default=2.0)
    p.add_argument("--sample-fs", type=float,
                   help="trajectory interval (fs); default 20 (--quick: 10)")
    p.add_argument("--viscosity-mpas", type=float, default=WATER_VISCOSITY_MPAS,
                   help="shear viscosity for the Yeh-Hummer correction (mPa s)")
    p.add_argument("--analyse-only", action="store_true",
                   help="skip the simulation; analyse tip3p.psf/xtc already in --outdir")
    p.add_argument("--quick", action="store_true",
                   help="a short smoke run: 0.1 ps quench, 1 ps equilibration, 2 ps production")
    args = p.parse_args(argv)
    times = {"quench_ps": (0.2, 0.1), "equilibration_ps": (20.0, 1.0),
             "production_ps": (50.0, 2.0), "sample_fs": (20.0, 10.0)}
    for key, (full, quick) in times.items():  # a time given explicitly is kept
        if getattr(args, key) is None:
            setattr(args, key, quick if args.quick else full)
    for key in ("timestep_fs", "spacing", "cutoff", "accuracy", *times):
        if not 0 < getattr(args, key) < float("inf"):
            p.error(f"argument --{key.replace('_', '-')}: must be positive, got "
                    f"{getattr(args, key)}")
    if args.n_side < 1:
        p.error(f"argument --n-side: must be at least 1, got {args.n_side}")
    if args.analyse_only:
        missing = [n for n in ("tip3p.psf", "tip3p.xtc") if not (args.outdir / n).is_file()]
        if missing:
            p.error(f"argument --analyse-only: no {', '.join(missing)} in {args.outdir} "
                    "(run the simulation first)")
    return args


def simulate(args, outdir, log):
    """Build, quench, equilibrate and run the box; return the run's statistics."""
    t_start = time.perf_counter()
    atoms = water_box(args.n_side, seed=args.seed, spacing=args.spacing)
    atoms.set_initial_charges(tip3p_charges(atoms))  # -0.834 / +0.417 e
    box = float(atoms.cell.lengths()[0])
    if args.cutoff > box / 2:
        raise SystemExit(f"--cutoff {args.cutoff} Å is more than half the box ({box:.2f} Å)")
    n_water = len(atoms) // 3
    density = atoms.get_masses().sum() / units.mol / (atoms.get_volume() * 1e-24)
    log(f"{n_water} TIP3P waters in a {box:.2f} Å box ({density:.3f} g/cm³), "
        f"lj/cut/coul/long {args.cutoff:g} Å + {args.kspace} {args.accuracy:g}")
    atoms.calc = lammps_calculator(args.kspace, args.accuracy, args.cutoff)

    t_eq = equilibrate(atoms, args, log)
    bodies = RigidBodies.resolve(atoms, "mol-id")
    force_err, torque_err = compare_kspace(atoms, bodies, args.kspace, args.accuracy,
                                           args.cutoff)
    log(f"{args.kspace} {args.accuracy:g} against Ewald 1e-7 at this configuration: relative "
        f"RMS error of the body forces {force_err:.1e}, of the torques {torque_err:.1e}")

    energies, frame_ps, t_prod = production(atoms, args, outdir, log)
    times = np.arange(len(energies)) * frame_ps
    drift = float(np.polyfit(times, energies, 1)[0]) if len(energies) > 2 else float("nan")
    log(f"NVE: T = {atoms.get_temperature():.1f} K at the end, total energy drift "
        f"{drift:+.2e} eV/ps ({drift / n_water:+.1e} eV/ps per molecule), "
        f"RMS {energies.std():.1e} eV")
    return {
        "n_water": n_water, "box_length_A": box, "kspace": args.kspace,
        "equilibration_ps": args.equilibration_ps, "production_ps": args.production_ps,
        "timestep_fs": args.timestep_fs, "energy_drift_eV_per_ps": drift,
        "force_error_vs_ewald": force_err, "torque_error_vs_ewald": torque_err,
        "wall_time_s": {"equilibration": t_eq, "production": t_prod,
                        "simulation": time.perf_counter() - t_start},
    }


def report(outdir, args, log):
    """Analyse tip3p.psf/xtc in ``outdir``, print beside published values; return numbers."""
    u, rdf, msd, rot = analyse(outdir, log)
    box = float(u.dimensions[0])
    d = msd.diffusion_coefficient_cm2_s * 1e5
    d_err = float(np.std(msd.per_axis, ddof=1) / np.sqrt(3)) * 1e5
    correction = yeh_hummer(box, args.viscosity_mpas) * 1e5
    print()
    print(f"Rigid TIP3P, {len(u.residues)} molecules, {TEMPERATURE_K:g} K, "
          f"{u.trajectory.totaltime:g} ps NVE")
    print(f"  O–O g(r) first peak   {rdf.first_peak_position:.3f} Å, height "
          f"{rdf.first_peak_height:.2f}; first minimum (shallow) "
          f"{rdf.first_minimum_position:.2f} Å, {rdf.coordination_number:.2f} neighbours")
    print(f"      {REFERENCES['rdf']}")
    print(f"  diffusion D           {d:.2f} ± {d_err:.2f} e-5 cm²/s (MSD of the centres of "
          f"mass, fit {msd.fit_range[0]:.1f}-{msd.fit_range[1]:.1f} ps; error from the spread "
          "of x, y, z)")
    print(f"      finite size: Yeh & Hummer, J. Phys. Chem. B 108, 15873 (2004): "
          f"D(L = inf) = D + 2.837297 kT/(6 pi eta L) = D + {correction:.2f}e-5 cm²/s for "
          f"L = {box:.1f} Å, eta = {args.viscosity_mpas:g} mPa s (real water; give TIP3P's "
          "with --viscosity-mpas)")
    for label, value, source in REFERENCES["diffusion"]:
        print(f"      {label}: {value}e-5 cm²/s ({source})")
    print(f"  dipole reorientation  tau1 = {rot.tau1:.2f} ps (integral {rot.tau1_integral:.2f}), "
          f"tau2 = {rot.tau2:.2f} ps (integral {rot.tau2_integral:.2f})")
    print(f"      {REFERENCES['tau2']}")
    print(f"      {REFERENCES['tau1']}")
    return {
        "n_frames": int(u.trajectory.n_frames),
        "rdf_first_peak_position_A": rdf.first_peak_position,
        "rdf_first_peak_height": rdf.first_peak_height,
        "rdf_first_minimum_A": rdf.first_minimum_position,
        "coordination_number": rdf.coordination_number,
        "diffusion_1e-5_cm2_s": d, "diffusion_error_1e-5_cm2_s": d_err,
        "diffusion_fit_range_ps": list(msd.fit_range),
        "yeh_hummer_correction_1e-5_cm2_s": correction,
        "tau1_ps": rot.tau1, "tau2_ps": rot.tau2,
        "tau1_integral_ps": rot.tau1_integral, "tau2_integral_ps": rot.tau2_integral,
    }


def main(argv=None):
    args = parse(argv)
    outdir = args.outdir
    outdir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    def log(text):
        print(f"[{time.perf_counter() - t_start:7.1f} s] {text}", flush=True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, ask_to_stop)
    path = outdir / "tip3p_results.json"
    if args.analyse_only:
        results = json.loads(path.read_text()) if path.exists() else {}
    else:
        earlier = sorted(p.name for p in outdir.glob("tip3p*"))
        if earlier:
            print(f"replacing an earlier run's {', '.join(earlier)} in {outdir}", flush=True)
        try:
            results = simulate(args, outdir, log)
        except Stopped as stop:
            path.unlink(missing_ok=True)  # (an earlier run's results: not this run's)
            where = (f"{stop.done * stop.dt_ps:g} of {stop.steps * stop.dt_ps:g} ps of the "
                     f"{stop.name}")
            if stop.name == "production":
                hint = (f"tip3p.psf, tip3p.xtc and tip3p.log hold it whole: python "
                        f"{sys.argv[0]} --outdir {outdir} --analyse-only analyses it; run "
                        "again for the whole production")
            else:
                hint = "nothing is kept before the production: run again"
            print(f"stopped ({STOP['signal']}) at {where}; {hint}", flush=True)
            raise SystemExit(130 if STOP["signal"] == "SIGINT" else 143) from None
    results.update(report(outdir, args, log))
    # Strict JSON: a quantity a short run cannot give (NaN) is null.
    results = {k: None if isinstance(v, float) and not np.isfinite(v) else v
               for k, v in results.items()}
    path.write_text(json.dumps(results, indent=2, allow_nan=False) + "\n")
    print(f"wrote {', '.join(sorted(p.name for p in outdir.glob('tip3p*')))} in {outdir} "
          f"({time.perf_counter() - t_start:.0f} s)")
    return results


if __name__ == "__main__":
    main()
