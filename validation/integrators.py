"""Shows: each integrator's energy drift and noise against time step, beside LAMMPS's fixes.

Energy conservation of rigidmd's integrators beside LAMMPS fix rigid/nve and fix rigid.

A cluster of 32 rigid TIP3P waters (``water_cluster(32, seed=0)``, bodies from
``mol-id``, rigid Maxwell-Boltzmann velocities at 250 K from
``default_rng(0)``) is run for 10 ps of NVE at time steps of 0.5, 1, 2 and
4 fs, from the same start, with every built-in integrator of
``RigidVerlet`` and with LAMMPS ``fix rigid/nve`` and ``fix rigid``
(``run_rigid_reference``, on ASE's unit constants).  The total energy is
recorded about every 10 fs and each run reports:

* drift: slope of a straight-line fit of the total energy against time, eV/ps;
* RMS: root-mean-square deviation of the total energy about that line, eV;
* force evaluations per step;
* wall time, s: ``RigidVerlet.run`` including the force calls, or LAMMPS's
  loop time (whose pair forces are native C++, so the two columns compare
  whole runs, not integrators alone);
* status: "unstable" with the time of failure when the run raised (a
  non-finite force, ``ConvergenceError``, lost atoms, ...) or its energy
  moved more than 10 eV from the start; drift and RMS are then those of the
  part before the failure, in parentheses (× in the plot).

A drift below about RMS / 10 ps is within the fluctuation (and trajectories
that differ by roundoff part within picoseconds, so rigidmd and LAMMPS
agree in the statistics, not frame by frame).

rigidmd's forces come from ASE's ``LAMMPSlib`` calculator running the same
pair style as the reference runs (``lj/cut/coul/cut``, charges scaled to
ASE's Coulomb constant): about 0.4-0.8 ms per call, against 3-5 ms for
``ase.calculators.tip3p.TIP3P(rc=40)`` (pure Python; both are measured and
printed at the start of each run).  LAMMPSlib knows no molecules, so its
energy also holds the intramolecular Coulomb terms, which are constant for
rigid waters and cancel in every body's force and torque; that constant
(measured at the start) is subtracted, so all energies are the TIP3P energies
of the LAMMPS runs.

Every run, LAMMPSlib's and the references', uses one non-periodic 1000 Å box
and a 2000 Å cut-off, longer than any distance in the box.  Within 10 ps some
trajectories evaporate a molecule: with a 40 Å cut-off the atom pairs
crossing it made energy jumps of ~0.1 eV (k q_O q_H / 40 Å = 0.13 eV), and
atoms leaving a box 50 Å around the start were lost.  All pairs are inside
the cut-off anyway, so the cost per call is the same.  The full run takes
about 3 minutes on one core.

Writes the table to ``integrators.txt`` and a plot of |drift| and RMS against
the time step (LAMMPS dashed) to ``integrators.png`` beside this script
(``--quick``: 1 ps at 1 and 2 fs only, files in the temporary directory
unless ``--outdir`` is given).

Run:  python validation/integrators.py [--quick] [--outdir DIR]
"""

import argparse
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from ase import units
from ase.calculators.lammpslib import LAMMPSlib
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core.schemes import BUILTIN_SCHEMES, resolve_scheme
from rigidmd.lammps import (
    charge_factor,
    lammps_energy_forces,
    load_lammps,
    run_rigid_reference,
    tip3p_charges,
    tip3p_pair_commands,
)
from rigidmd.systems import water_cluster

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import NullLocator  # noqa: E402

N_WATERS = 32
TEMPERATURE_K = 250.0
BOX = 1000.0  # Å, the non-periodic box of every run (cube, cluster at its centre)
CUTOFF = 2000.0  # Å, LJ and Coulomb; longer than the box diagonal: no pair is ever cut
RECORD_FS = 10.0  # energy sampling interval, fs
JUMP_EV = 10.0  # an energy this far from the start marks a run unstable
LAMMPS_FIXES = {"LAMMPS rigid/nve": "rigid/nve", "LAMMPS rigid": "rigid"}
# LAMMPS curves share the colour of the rigidmd integrator implementing the same method.
PARTNER = {"LAMMPS rigid/nve": "no_squish", "LAMMPS rigid": "richardson"}


class Unstable(RuntimeError):
    """The total energy left the start value by more than ``JUMP_EV`` or became non-finite."""


@dataclass
class Run:
    name: str
    dt_fs: float
    force_calls: int
    time_ps: np.ndarray
    energy: np.ndarray
    wall: float
    failed_ps: float | None = None
    reason: str = ""

    @property
    def stable(self):
        return self.failed_ps is None

    def fit(self):
        """Drift (eV/ps) and RMS deviation about the fitted line (eV), up to any failure."""
        if len(self.time_ps) < 3:
            return np.nan, np.nan
        slope, offset = np.polyfit(self.time_ps, self.energy, 1)
        residual = self.energy - (slope * self.time_ps + offset)
        return slope, float(np.sqrt(np.mean(residual**2)))


# ---------------------------------------------------------------- system and forces

def start_configuration():
    """The cluster with rigid velocities, centred in a non-periodic ``BOX``, and its charges."""
    atoms = water_cluster(N_WATERS, seed=0)
    rigid_maxwell_boltzmann(atoms, TEMPERATURE_K, bodies="mol-id", rng=np.random.default_rng(0))
    atoms.cell = np.eye(3) * BOX
    atoms.pbc = False
    atoms.center()
    charges = tip3p_charges(atoms)
    # LAMMPSlib's charges, scaled so that LAMMPS uses ASE's Coulomb constant
    atoms.set_initial_charges(charges * charge_factor())
    return atoms, charges


def lammpslib():
    """LAMMPSlib with the TIP3P pair style (no molecule exclusion: LAMMPSlib sends no mol IDs)."""
    cmds = [c for c in tip3p_pair_commands(CUTOFF, oxygen_types=(1,)) if "exclude" not in c]
    return LAMMPSlib(lmpcmds=cmds, atom_types={"O": 1, "H": 2},
                     lammps_header=["units metal", "atom_style full",
                                    "atom_modify map array sort 0 0"],
                     keep_alive=True)


def per_call(atoms, calc, calls):
    """Wall time (s) of one force call on slightly moved atoms."""
    atoms = atoms.copy()
    atoms.calc = calc
    atoms.get_forces()
    t0 = time.perf_counter()
    for i in range(calls):
        atoms.positions[0, 0] += 1e-6 * (-1) ** i
        atoms.get_forces()
    return (time.perf_counter() - t0) / calls


def intramolecular_energy(atoms, charges, body_ids):
    """LAMMPSlib's energy minus the TIP3P energy (constant for rigid waters), eV."""
    atoms = atoms.copy()
    calc = lammpslib()
    atoms.calc = calc
    try:
        energy = atoms.get_potential_energy()
    finally:
        calc.clean()
    tip3p, _ = lammps_energy_forces(atoms, body_ids, tip3p_pair_commands(CUTOFF), charges)
    return energy - tip3p


# ---------------------------------------------------------------- runs

def run_rigidmd(start, integrator, dt_fs, nsteps, every, shift):
    atoms = start.copy()
    calc = lammpslib()
    atoms.calc = calc
    dyn = RigidVerlet(atoms, dt_fs * units.fs, bodies="mol-id", integrator=integrator)
    steps, energies = [], []

    def record():
        energy = atoms.get_total_energy() - shift
        e0 = energies[0] if energies else energy
        if not np.isfinite(energy) or abs(energy - e0) > JUMP_EV:
            raise Unstable(f"total energy {energy:.6g} eV (start {e0:.6g} eV)")
        steps.append(dyn.nsteps)
        energies.append(energy)

    dyn.attach(record, interval=every)
    failed, reason = None, ""
    t0 = time.perf_counter()
    try:
        dyn.run(nsteps)
    except Exception as err:  # reported as an unstable run
        # an energy jump is seen at a recorded step, anything else in the next step
        failed = (dyn.nsteps + (not isinstance(err, Unstable))) * dt_fs / 1000
        reason = f"{type(err).__name__}: {err}"
    finally:
        wall = time.perf_counter() - t0
        calc.clean()
    return Run(integrator, dt_fs, resolve_scheme(integrator).force_calls_per_step,
               np.array(steps) * dt_fs / 1000, np.array(energies), wall, failed, reason)


def run_lammps(start, charges, body_ids, name, dt_fs, nsteps, every):
    with tempfile.TemporaryDirectory(prefix="rigidmd-bench-") as workdir:
        try:
            # LAMMPSlib's box (the data file's is 50 Å around the atoms), and
            # thermo output at every frame so that lost atoms stop the run there
            box = " ".join(f"{x} final 0 {BOX!r}" for x in "xyz")
            extra = [f"change_box all {box} units box", f"thermo {every}"]
            ref = run_rigid_reference(start, body_ids, tip3p_pair_commands(CUTOFF),
                                      dt_fs * units.fs, nsteps, every=every,
                                      fix=LAMMPS_FIXES[name], charges=charges,
                                      extra_commands=extra, workdir=workdir)
        except RuntimeError as err:
            # the frames written before the failure: "step pe ke" rows
            path = Path(workdir) / "energies.txt"
            rows = np.loadtxt(path, comments="#", ndmin=2) if path.exists() else np.zeros((0, 3))
            run = Run(name, dt_fs, 1, rows[:, 0] * dt_fs / 1000, rows[:, 1] + rows[:, 2], np.nan)
            if not energy_jump(run):
                run.failed_ps = ((rows[-1, 0] if len(rows) else 0) + every) * dt_fs / 1000
                run.reason = f"RuntimeError: {err}"
            return run
    run = Run(name, dt_fs, 1, ref.step * dt_fs / 1000, ref.total_energy,
              ref.timing.get("loop_time", np.nan))
    energy_jump(run)
    return run


def energy_jump(run):
    """Mark ``run`` unstable from its first frame that fails the energy test, cut the rest."""
    e = run.energy
    bad = np.flatnonzero(~np.isfinite(e) | (np.abs(e - e[0]) > JUMP_EV)) if len(e) else []
    if len(bad):
        k = bad[0]
        run.failed_ps = float(run.time_ps[k])
        run.reason = f"Unstable: total energy {e[k]:.6g} eV (start {e[0]:.6g} eV)"
        run.time_ps, run.energy = run.time_ps[:k], e[:k]
    return len(bad) > 0


# ---------------------------------------------------------------- report

def table(runs):
    lines = [f"{'integrator':<18} {'dt fs':>5} {'F/step':>6} {'drift eV/ps':>12} {'RMS eV':>9}"
             f" {'wall s':>7}  status"]
    previous = None
    for run in runs:
        if previous is not None and run.name != previous:
            lines.append("")
        previous = run.name
        drift, rms = run.fit()
        status = "stable" if run.stable else f"unstable at {run.failed_ps:.3f} ps"
        if run.stable:
            numbers = f"{drift:12.2e} {rms:9.2e}"
        else:  # the part before the failure, in parentheses
            numbers = f"{f'({drift:.2e})':>12} {f'({rms:.1e})':>9}".replace("(nan)", "-")
        wall = f"{run.wall:7.2f}" if np.isfinite(run.wall) else f"{'-':>7}"
        lines.append(f"{run.name:<18} {run.dt_fs:5.1f} {run.force_calls:6d} {numbers}"
                     f" {wall}  {status}")
    failures = [r for r in runs if not r.stable]
    if failures:
        lines += ["", "unstable runs:"]
        lines += [f"  {r.name} at {r.dt_fs:g} fs, {r.failed_ps:.3f} ps: {r.reason[:150]}"
                  for r in failures]
    return lines


def plot(runs, names, path, duration_ps):
    fig, (ax_drift, ax_rms) = plt.subplots(1, 2, figsize=(11, 5.2), constrained_layout=True)
    colours = {name: f"C{i}" for i, name in enumerate(n for n in names if n not in PARTNER)}
    for name in names:
        mine = [r for r in runs if r.name == name]
        ok = [r for r in mine if r.stable]
        broken = [r for r in mine if not r.stable]
        lammps = name in PARTNER
        colour = colours[PARTNER.get(name, name)]
        label = name
        if broken:
            label += f" (unstable at {', '.join(f'{r.dt_fs:g}' for r in broken)} fs: ×)"
        style = {"color": colour, "linestyle": "--" if lammps else "-",
                 "marker": "s" if lammps else "o",
                 "markerfacecolor": "none" if lammps else None,
                 "markersize": 9 if lammps else 5}
        cross = {"color": colour, "marker": "x", "linestyle": "none", "markersize": 8}
        (style if ok else cross)["label"] = label  # one legend entry per curve
        for runs_, kw in ((ok, style), (broken, cross)):
            if runs_:
                dts = np.array([r.dt_fs for r in runs_])
                fits = np.array([r.fit() for r in runs_])
                ax_drift.plot(dts, np.abs(fits[:, 0]), **kw)
                ax_rms.plot(dts, fits[:, 1], **kw)
    for ax, what in ((ax_drift, "|energy drift| (eV/ps)"),
                     (ax_rms, "RMS energy fluctuation about the drift (eV)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        dts = sorted({r.dt_fs for r in runs})
        ax.set_xticks(dts, [f"{d:g}" for d in dts])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.set_xlabel("time step (fs)")
        ax.set_ylabel(what)
        ax.grid(True, which="major", alpha=0.3)
    ax_drift.set_title("drift (slope of a linear fit)")
    ax_rms.set_title("fluctuation")
    handles, labels = ax_rms.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=9)
    fig.suptitle(f"{N_WATERS} rigid TIP3P waters (cluster) started at {TEMPERATURE_K:g} K, "
                 f"{duration_ps:g} ps NVE from one start")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1 ps at 1 and 2 fs only")
    parser.add_argument("--outdir", type=Path, default=None,
                        help="where to write integrators.txt and .png (default: beside this "
                        "script; with --quick the temporary directory)")
    args = parser.parse_args()
    if args.outdir is None:
        args.outdir = Path(tempfile.gettempdir()) if args.quick else Path(__file__).parent
    duration_ps = 1.0 if args.quick else 10.0
    dts = [1.0, 2.0] if args.quick else [0.5, 1.0, 2.0, 4.0]
    t_start = time.perf_counter()

    load_lammps().close()  # loads the MPI library LAMMPSlib's lammps module needs
    start, charges = start_configuration()
    body_ids = RigidBodies.resolve(start, "mol-id").body_ids
    shift = intramolecular_energy(start, charges, body_ids)
    lib_cost = per_call(start, lammpslib(), 300)
    tip3p_cost = per_call(start, TIP3P(rc=40.0), 30)
    # compile numba and warm everything up outside the timings
    for integrator in BUILTIN_SCHEMES:
        run_rigidmd(start, integrator, 1.0, 2, 1, shift)

    names = list(BUILTIN_SCHEMES) + list(LAMMPS_FIXES)
    runs = []
    for name in names:
        for dt in dts:
            nsteps = round(duration_ps * 1000 / dt)
            every = max(1, round(RECORD_FS / dt))
            if name in LAMMPS_FIXES:
                run = run_lammps(start, charges, body_ids, name, dt, nsteps, every)
            else:
                run = run_rigidmd(start, name, dt, nsteps, every, shift)
            runs.append(run)
            print(f"  {name} dt={dt:g} fs: {run.wall:.1f} s"
                  + ("" if run.stable else f", unstable at {run.failed_ps:.3f} ps"),
                  file=sys.stderr, flush=True)

    e0 = {r.name: r.energy[0] for r in runs if len(r.energy)}
    total = time.perf_counter() - t_start
    lines = [
        f"{N_WATERS} rigid TIP3P waters (cluster), {TEMPERATURE_K:g} K, {duration_ps:g} ps NVE,"
        f" energy every ~{RECORD_FS:g} fs; unstable: raised or |E - E0| > {JUMP_EV:g} eV",
        f"rigidmd forces: LAMMPSlib {lib_cost * 1e3:.2f} ms/call"
        f" (ASE TIP3P(rc=40): {tip3p_cost * 1e3:.2f} ms/call);"
        f" intramolecular constant {shift:.4f} eV removed",
        "E0 (eV): " + ", ".join(f"{name} {e:.10f}" for name, e in e0.items()),
        "",
        *table(runs),
        "",
        f"total runtime {total:.0f} s",
    ]
    text = "\n".join(lines)
    print(text)
    args.outdir.mkdir(parents=True, exist_ok=True)
    (args.outdir / "integrators.txt").write_text(text + "\n")
    plot(runs, names, args.outdir / "integrators.png", duration_ps)
    print(f"wrote {args.outdir / 'integrators.txt'} and {args.outdir / 'integrators.png'}")


if __name__ == "__main__":
    main()
