r"""Four-site water in rigidmd and in OpenMM from one state: equipartition and step size.

LAMMPS's ``fix rigid`` refuses a massless site, so rigidmd's four-site water
has no rigid-body peer there; OpenMM (SETTLE, M as a virtual site) is the
peer.  From one equilibrated state of TIP4P-Ew (216 waters at 0.9953 g/cm³,
9 Å, PME/PPPM 1e-5, the long-range Lennard-Jones correction) both codes run
from identical positions and velocities:

- **rigidmd**: :class:`rigidmd.RigidVerlet` (NO_SQUISH velocity Verlet),
  forces from LAMMPS in-process (``lj/cut/coul/long``, PPPM);
  or :class:`rigidmd.RigidBussi` for ``--ensemble nvt``.
- **OpenMM**: its ``VerletIntegrator`` (leapfrog with SETTLE: the positions
  of velocity Verlet with RATTLE).  Leapfrog's velocities lag the positions by
  half a step; the on-step velocity is the mean of the two half steps around
  it, made rigid at the step's positions (the body decomposition below does
  that), which is exactly RATTLE's.  (OpenMM's documented velocity-Verlet
  ``CustomIntegrator`` goes wrong with virtual sites: it lost 7 kJ/mol in 0.1 ps
  here at 0.5 and at 1 fs alike, and parts from ``VerletIntegrator`` by 8e-4 nm
  in 40 steps for TIP4P-Ew, 2e-9 nm for TIP3P; a bare
  ``NoseHooverIntegrator(stepSize)`` crashed OpenMM 8.6.1.)  Its
  ``NoseHooverIntegrator`` (chain of 3, collision frequency 1/``--tau-ps``) for
  ``--ensemble nvt``: with a vanishing collision frequency it does not follow
  velocity Verlet here (1.3e-3 nm from ``VerletIntegrator`` in 40 steps, TIP3P
  too), so its kinetic split is not compared with rigidmd's as a check.

At each time step (``--dt-fs``) each run records, every 10 fs, the
translational and rotational kinetic energies of the bodies, computed from
the atoms' velocities in the same way for both codes (centre-of-mass velocity;
angular momentum about it over O, H, H, inverted with the inertia of the three
massive sites; M carries nothing) and, for rigidmd, also its own accounting.
Temperatures: :math:`T_\mathrm{tr} = 2K_\mathrm{tr}/((3N-3)k_B)` (the total
momentum is zero and conserved), :math:`T_\mathrm{rot} = 2K_\mathrm{rot}/(3Nk_B)`.
Every 100 fs the configuration goes to :func:`configurational_sums`, one
OpenMM context (the same force field for both codes' frames), which gives the
potential energy and the **configurational temperatures** of translation and
rotation of rigid bodies,

.. math::
    k_B T^\mathrm{conf}_\mathrm{tr} = \frac{\langle \sum_b |F_b|^2\rangle}
        {\langle \sum_b \nabla_{X_b}^2 U\rangle},\qquad
    k_B T^\mathrm{conf}_\mathrm{rot} = \frac{\langle \sum_b |\tau_b|^2\rangle}
        {\langle \sum_b \sum_a \mathcal{L}_{b,a}^2 U\rangle},

where :math:`\mathcal L_{b,a}` rotates body :math:`b` about the space axis
:math:`a` through its centre of mass (an invariant vector field on SO(3): the
Haar measure is invariant under it, so the integration by parts that gives
the Cartesian estimator holds for it too; the torque is
:math:`\tau_{b,a} = -\mathcal L_{b,a}U`).  The second derivatives come from
Hutchinson's trace estimator: random ±1 vectors :math:`w` over all
:math:`6N` generalised coordinates, two force calls each at the
configurations displaced by :math:`\pm\epsilon w` (translation ε = 5e-4 nm,
rotation 5e-3 rad; 2e-4 and 1e-3 nm, 2e-3 and 1e-2 rad give the same to 0.2 %),
:math:`w\cdot\Delta G/2\epsilon`, averaged over 4 vectors per frame; the cross
terms average to zero.  :math:`T^\mathrm{conf}` does not depend on the momenta or on how a
code counts degrees of freedom: it is the temperature the configurations were
sampled at.

What velocity Verlet does at a finite step (why the split is measured at
several steps): for a harmonic mode of frequency ω it conserves a shadow
energy, and the step's kinetic energy reads low by :math:`(\omega h)^2/6`
and the configurational temperature high by :math:`(\omega h)^2/12` relative
to the shadow's temperature.  Water's librations (ω ≈ 0.1-0.15 fs⁻¹) are
three times faster than its hindered translations: at 2 fs the rotational
kinetic temperature reads a few kelvin below the translational one in any
velocity-Verlet code; a thermostat that holds the total kinetic energy then
leaves the configurations warmer than its target.  Both codes should show
the same, and all four temperatures must meet as h → 0.

The NVE runs also give the divergence of the two codes' oxygen positions
over the first picoseconds (RMS over molecules, Å, ``--track-ps``) and each
code's energy conservation (rigidmd: its conserved energy, LAMMPS's forces;
OpenMM: kinetic plus its own potential energy; fluctuation = standard
deviation, drift = slope of a straight line, per molecule).

Results go to ``--outdir`` (default ``validation/``):
``water_openmm_nve.json`` (every number), ``water_openmm_nve.txt`` (the
table); the equilibrated start is cached as ``water_openmm_nve.start6.1.npz``
(``--n-side``, ``--seed``).

Run (216 waters, one thread per code, at ``nice 19``; the pace on a loaded
2-core machine is in the results file)::

    python validation/water_openmm_nve.py                        # NVE at 0.5, 1, 2, 3 fs, 10 ps
    python validation/water_openmm_nve.py --ensemble nvt --dt-fs 1 2 --ps 20
    python validation/water_openmm_nve.py --quick                 # seconds: 27 waters
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
MODEL = "tip4pew"
TEMPERATURE_K = 298.0
DENSITY = 0.9953  # g/cm³: the water study's NPT mean for TIP4P-Ew (and the OpenMM run)
CUTOFF = 9.0  # Å
KB_KJ = 0.0083144626  # kJ/mol/K
KE_FS = 10.0  # kinetic energies every 10 fs
FRAME_FS = 100.0  # configurations (U, T_conf) every 100 fs (--frame-fs)
#: Picoseconds each run makes before it records (--skip-ps).
SKIP = {"ps": 0.0}
EPS_NM, EPS_RAD = 5e-4, 5e-3  # Hutchinson displacements (see the module docstring)
PROBES = 4  # Hutchinson vectors per frame


def _units():
    from ase import units

    # ASE velocity (Å per ASE time) to nm/ps; amu nm²/ps² is kJ/mol.
    return units, units.fs * 100.0


# --------------------------------------------------------------------------- the state
#: Long-range electrostatics: LAMMPS's k-space solver and both codes' relative accuracy
#: (the quick mode uses Ewald at 1e-8, so that what separates the codes' trajectories is
#: their integrators, not PPPM against PME).
KSPACE = {"solver": "pppm", "accuracy": 1e-5}


def lammps_calculator(model, cutoff, skin=2.0):
    """LAMMPS's forces for ``model``: ``lj/cut/coul/long`` at ``cutoff`` (Å), the tail
    correction, :data:`KSPACE`; neighbour ``skin`` in Å."""
    from rigidmd.lammps import LAMMPSCalculator

    types = {"O": 1, "H": 2} if model.sites == 3 else {"O": 1, "H": 2, "X": 3}
    return LAMMPSCalculator(model.lammps_commands(cutoff, KSPACE["solver"],
                                                  KSPACE["accuracy"], tail=True),
                            atom_types=types, skin=skin)


def whole(x, cell, sites):
    """Molecules made whole around their O (orthorhombic cell), same shape as x."""
    x = x.reshape(-1, sites, 3)
    box = np.diag(cell)
    d = x - x[:, :1]
    d -= box * np.round(d / box)
    return (x[:, :1] + d).reshape(-1, 3)


def state_atoms(state, model, cutoff):
    """``state``'s atoms with ``model``'s masses and charges, its momenta and
    :func:`lammps_calculator`'s forces."""
    from ase import Atoms

    n = len(state["numbers"]) // model.sites
    atoms = Atoms(numbers=state["numbers"], positions=state["positions"], cell=state["cell"],
                  pbc=True)
    atoms.set_masses(np.tile(model.masses(), n))
    atoms.set_momenta(state["momenta"])
    atoms.set_initial_charges(model.charges(n))
    atoms.calc = lammps_calculator(model, cutoff)
    return atoms


def state_at_rest(atoms, sites):
    """``atoms`` as a state: whole molecules (Å), momenta (ASE) with the total set to zero,
    cell and numbers."""
    p = atoms.get_momenta()
    masses = atoms.get_masses()
    p -= masses[:, None] * (p.sum(axis=0) / masses.sum())
    return {"positions": whole(atoms.positions, atoms.cell.array, sites), "momenta": p,
            "cell": atoms.cell.array.copy(), "numbers": atoms.numbers.copy()}


def equilibrated_state(n_side, seed, eq_ps, cache=None):
    """Positions (whole molecules, Å), momenta (ASE) and cell of liquid TIP4P-Ew at 298 K.

    The lattice of :func:`rigidmd.systems.water_box` scaled to :data:`DENSITY`,
    quenched (Langevin, 0.5 fs, 0.2 ps), then ``eq_ps`` of Bussi (τ 0.1 ps,
    2 fs, the total momentum kept); the total momentum is then set to zero.  Cached in ``cache``.
    """
    if cache is not None and Path(cache).exists():
        with np.load(cache) as data:
            if int(data["n_side"]) == n_side and int(data["seed"]) == seed \
                    and float(data["eq_ps"]) == eq_ps:
                return {k: data[k] for k in ("positions", "momenta", "cell", "numbers")}
    from rigidmd import RigidBussi, RigidLangevin
    from rigidmd.systems import water_box
    from rigidmd.water import water_model

    units, _ = _units()
    model = water_model(MODEL)
    atoms = water_box(n_side, seed=seed, model=MODEL, whole=True)
    n = len(atoms) // model.sites
    grams = n * model.masses().sum() / units.kg * 1e3
    edge = (grams / DENSITY * 1e24) ** (1 / 3)
    x = atoms.positions.reshape(n, model.sites, 3)
    m = model.masses()
    com = np.einsum("s,msk->mk", m, x) / m.sum()
    atoms.positions = (x + (edge / atoms.cell.lengths()[0] - 1) * com[:, None]).reshape(-1, 3)
    atoms.set_cell(np.eye(3) * edge)
    cutoff = min(CUTOFF, 0.49 * edge)
    atoms.set_initial_charges(model.charges(n))
    atoms.calc = lammps_calculator(model, cutoff)
    rng = np.random.default_rng(seed)
    RigidLangevin(atoms, 0.5 * units.fs, temperature_K=TEMPERATURE_K, friction=0.05 / units.fs,
                  rng=rng).run(400 if eq_ps >= 1 else 100)
    RigidBussi(atoms, 2.0 * units.fs, temperature_K=TEMPERATURE_K, taut=100 * units.fs,
               rng=rng, fixcm=True).run(max(int(round(eq_ps * 500)), 1))
    state = state_at_rest(atoms, model.sites)
    if cache is not None:
        np.savez(cache, n_side=n_side, seed=seed, eq_ps=eq_ps, **state)
    return state


# --------------------------------------------------------------------------- observables
def body_kinetic_energies(positions, velocities, masses, sites=4):
    r"""Translational and rotational kinetic energy (sums over bodies) from atom velocities.

    :math:`K_\mathrm{tr} = \sum_b \tfrac12 M_b|V_b|^2`;
    :math:`K_\mathrm{rot} = \sum_b \tfrac12 L_b\cdot I_b^{-1} L_b` with
    :math:`L_b = \sum_i m_i (x_i - X_b)\times(v_i - V_b)` and the inertia tensor of
    the massive sites about the centre of mass (a massless M adds nothing).
    Units: those of ``masses * velocities**2`` (amu nm²/ps² = kJ/mol for
    OpenMM's).  Velocities must be rigid (SETTLE's are): then the sum is the
    total kinetic energy.
    """
    m = masses.reshape(-1, sites)
    x = positions.reshape(-1, sites, 3)
    v = velocities.reshape(-1, sites, 3)
    M = m.sum(axis=1)
    X = np.einsum("bs,bsk->bk", m, x) / M[:, None]
    V = np.einsum("bs,bsk->bk", m, v) / M[:, None]
    r, u = x - X[:, None], v - V[:, None]
    L = np.einsum("bs,bsk->bk", m, np.cross(r, u))
    r2 = np.einsum("bsk,bsk->bs", r, r)
    inertia = (np.einsum("bs,bs->b", m, r2)[:, None, None] * np.eye(3)
               - np.einsum("bs,bsi,bsj->bij", m, r, r))
    omega = np.linalg.solve(inertia, L[..., None])[..., 0]
    return 0.5 * float(np.einsum("b,bk,bk->", M, V, V)), 0.5 * float(np.sum(L * omega))


def _bodies(positions, masses, sites=4):
    m = masses.reshape(-1, sites)
    x = positions.reshape(-1, sites, 3)
    X = np.einsum("bs,bsk->bk", m, x) / m.sum(axis=1)[:, None]
    return x, X


def configurational_sums(context, positions_nm, masses, rng, sites=4):
    r"""One frame's :math:`U`, :math:`\sum|F|^2`, :math:`\sum\nabla^2U` (translation) and
    :math:`\sum|\tau|^2`, :math:`\sum\mathcal L^2U` (rotation), OpenMM's units (kJ/mol, nm).

    ``positions_nm``: whole molecules, (n_atoms, 3); M is placed by OpenMM.
    :data:`PROBES` Hutchinson vectors (see the module docstring), estimated by
    :func:`rigidmd.core.configurational.hutchinson_laplacians` (the package's estimator).
    """
    from openmm import unit
    from scipy.spatial.transform import Rotation

    from rigidmd.core.configurational import hutchinson_laplacians

    massive = masses > 0

    def generalised(pos):
        context.setPositions(pos)
        context.computeVirtualSites()
        st = context.getState(getForces=True, getEnergy=True, getPositions=True)
        f = st.getForces(asNumpy=True).value_in_unit(unit.kilojoule_per_mole / unit.nanometer)
        f = np.where(massive[:, None], f, 0.0)  # OpenMM already spread M's force onto O, H, H
        x = st.getPositions(asNumpy=True).value_in_unit(unit.nanometer)
        xb, X = _bodies(x, masses, sites)
        fb = f.reshape(-1, sites, 3)
        return (st.getPotentialEnergy().value_in_unit(unit.kilojoule_per_mole),
                fb.sum(axis=1), np.cross(xb - X[:, None], fb).sum(axis=1))

    u, F, tau = generalised(positions_nm)
    xb, X = _bodies(positions_nm, masses, sites)
    r = xb - X[:, None]

    def displaced(dX, rotvec):
        rot = Rotation.from_rotvec(rotvec)
        r_new = np.stack([rot.apply(r[:, s]) for s in range(sites)], axis=1)
        _, Fd, td = generalised((X[:, None] + dX[:, None] + r_new).reshape(-1, 3))
        return Fd, td

    lap_t, lap_r = hutchinson_laplacians(displaced, len(F), len(F), rng, PROBES, EPS_NM,
                                         EPS_RAD)
    return u, float(np.sum(F * F)), lap_t, float(np.sum(tau * tau)), lap_r


# --------------------------------------------------------------------------- the two codes
def _steps(dt_fs, every_fs):
    return max(int(round(every_fs / dt_fs)), 1)


def run_rigidmd(state, dt_fs, ps, ensemble, tau_ps, track_ps, seed):
    """rigidmd from ``state``: series of kinetic energies (kJ/mol), frames (nm), O tracks."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from rigidmd import RigidBussi, RigidVerlet
    from rigidmd.water import water_model

    units, _ = _units()
    kj = units.kJ / units.mol
    model = water_model(MODEL)
    atoms = state_atoms(state, model, min(CUTOFF, 0.49 * np.diag(state["cell"]).min()))
    dt = dt_fs * units.fs
    if ensemble == "nve":
        dyn = RigidVerlet(atoms, dt)
    else:
        dyn = RigidBussi(atoms, dt, temperature_K=TEMPERATURE_K, taut=tau_ps * 1000 * units.fs,
                         rng=np.random.default_rng(seed), fixcm=False)
    masses = atoms.get_masses()
    rec = {"K_tr": [], "K_rot": [], "K_tr_atoms": [], "K_rot_atoms": [], "E": [],
           "frames": [], "O": []}
    ke_every, frame_every = _steps(dt_fs, KE_FS), _steps(dt_fs, FRAME_FS)
    track_steps = int(round(track_ps * 1000 / dt_fs))
    if SKIP["ps"] > 0:
        if ensemble == "nve":
            raise ValueError("--skip-ps is for thermostatted runs")
        dyn.run(int(round(SKIP["ps"] * 1000 / dt_fs)))
    start = dyn.nsteps

    def observe():
        s = dyn.nsteps - start
        if s % ke_every == 0:
            rec["K_tr"].append(dyn.get_translational_kinetic_energy() / kj)
            rec["K_rot"].append(dyn.get_rotational_kinetic_energy() / kj)
            v = np.zeros_like(atoms.positions)
            p = atoms.get_momenta()
            v[masses > 0] = p[masses > 0] / masses[masses > 0, None]
            kt, kr = body_kinetic_energies(atoms.positions, v, masses)
            rec["K_tr_atoms"].append(kt / kj)
            rec["K_rot_atoms"].append(kr / kj)
            rec["E"].append(dyn.get_conserved_energy() / kj)
        if s % frame_every == 0:
            rec["frames"].append(whole(atoms.positions, atoms.cell.array, 4) / 10)
        if s <= track_steps and s % ke_every == 0:
            rec["O"].append(atoms.positions[::4].copy())

    dyn.attach(observe, interval=1)
    t0 = time.perf_counter()
    dyn.run(int(round(ps * 1000 / dt_fs)))
    return rec, time.perf_counter() - t0


def openmm_system(state, model=None, cutoff=None, **options):
    """OpenMM's system of ``state`` (:func:`rigidmd.openmm.water_system`, ``model`` TIP4P-Ew
    by default, ``cutoff`` Å, the tail correction, :data:`KSPACE`'s accuracy, ``options``
    passed on) with rigidmd's masses (the file's differ by 3e-5, 5e-5)."""
    from ase import Atoms

    from rigidmd.openmm import water_system
    from rigidmd.water import water_model

    model = model or water_model(MODEL)
    atoms = Atoms(numbers=state["numbers"], positions=state["positions"], cell=state["cell"],
                  pbc=True)
    masses = np.tile(model.masses(), len(atoms) // model.sites)
    atoms.set_masses(masses)
    cutoff = cutoff or min(CUTOFF, 0.49 * atoms.cell.lengths().min())
    system = water_system(atoms, model, cutoff, tail=True,
                          error_tolerance=KSPACE["accuracy"], **options)[1]
    for i, m in enumerate(masses):
        system.setParticleMass(i, float(m))
    return system


def openmm_context(system, integrator, state):
    """A one-thread CPU context at ``state``'s positions: (context, masses in amu, the
    state's velocities in nm/ps, zero on massless sites)."""
    import openmm
    from openmm import unit

    _, to_nm_ps = _units()
    context = openmm.Context(system, integrator, openmm.Platform.getPlatformByName("CPU"),
                             {"Threads": "1"})
    masses = np.array([system.getParticleMass(i).value_in_unit(unit.dalton)
                       for i in range(system.getNumParticles())])
    context.setPositions(state["positions"] / 10)
    context.computeVirtualSites()
    v = np.zeros_like(state["positions"])
    v[masses > 0] = state["momenta"][masses > 0] / masses[masses > 0, None] * to_nm_ps
    return context, masses, v


def run_openmm(state, dt_fs, ps, ensemble, tau_ps, track_ps, seed):
    """OpenMM from ``state``: the same series as :func:`run_rigidmd` (no own accounting)."""
    import openmm
    from openmm import unit

    _, to_nm_ps = _units()
    system = openmm_system(state)
    if ensemble == "nve":
        integrator = openmm.VerletIntegrator(dt_fs * 1e-3)
    else:
        integrator = openmm.NoseHooverIntegrator(TEMPERATURE_K, 1 / tau_ps, dt_fs * 1e-3)
    if ensemble == "langevin":  # velocities half a step off: kinetic columns not on-step
        integrator = openmm.LangevinMiddleIntegrator(TEMPERATURE_K, 1 / tau_ps, dt_fs * 1e-3)
        integrator.setRandomNumberSeed(seed)
    context, masses, v = openmm_context(system, integrator, state)
    rec = {"K_tr": [], "K_rot": [], "E": [], "frames": [], "O": []}
    ke_every, frame_every = _steps(dt_fs, KE_FS), _steps(dt_fs, FRAME_FS)
    track_steps = int(round(track_ps * 1000 / dt_fs))
    n_steps = int(round(ps * 1000 / dt_fs))
    kj_nm = {"positions": unit.nanometer, "velocities": unit.nanometer / unit.picosecond}

    def read():
        st = context.getState(getPositions=True, getVelocities=True, getEnergy=True)
        return (st.getPositions(asNumpy=True).value_in_unit(kj_nm["positions"]),
                st.getVelocities(asNumpy=True).value_in_unit(kj_nm["velocities"]),
                st.getPotentialEnergy().value_in_unit(unit.kilojoule_per_mole))

    if ensemble == "nve":
        # Leapfrog keeps v(t - h/2) beside x(t): start it half a step back so that the
        # on-step velocity (the mean of the two half steps, made rigid at x(t): the
        # rigid-body decomposition below does that) is the state's at t = 0.
        context.setVelocities(v)
        f = context.getState(getForces=True).getForces(asNumpy=True).value_in_unit(
            unit.kilojoule_per_mole / unit.nanometer)
        half = np.where(masses[:, None] > 0, 0.5 * dt_fs * 1e-3 * f
                        / np.where(masses > 0, masses, 1.0)[:, None], 0.0)
        context.setVelocities(v - half)
        context.applyVelocityConstraints(1e-10)
    else:
        context.setVelocities(v)
    if SKIP["ps"] > 0:
        if ensemble == "nve":
            raise ValueError("--skip-ps is for thermostatted runs")
        integrator.step(int(round(SKIP["ps"] * 1000 / dt_fs)))
    t0 = time.perf_counter()
    s = 0
    x, vel, u = read()
    while True:
        if ensemble == "nve":  # v(t) from v(t - h/2) and v(t + h/2)
            integrator.step(1)
            x1, vel1, u1 = read()
            v_now = 0.5 * (vel + vel1)
        else:
            v_now = vel
        if s % ke_every == 0:
            kt, kr = body_kinetic_energies(x, v_now, masses)
            rec["K_tr"].append(kt)
            rec["K_rot"].append(kr)
            # (the chain's energy: OpenMM 8.6.1 crashes when asked before the first step)
            rec["E"].append(u + kt + kr + (integrator.computeHeatBathEnergy().value_in_unit(
                unit.kilojoule_per_mole) if ensemble == "nvt" and (s > 0 or SKIP["ps"] > 0)
                else 0.0))
        if s % frame_every == 0:
            rec["frames"].append(np.array(x))
        if s <= track_steps and s % ke_every == 0:
            rec["O"].append(10 * np.array(x[::4]))
        if s >= n_steps:
            break
        step = min(ke_every, n_steps - s)
        if ensemble == "nve":
            integrator.step(step - 1) if step > 1 else None
            s += step
            x, vel, u = (x1, vel1, u1) if step == 1 else read()
        else:
            integrator.step(step)
            s += step
            x, vel, u = read()
    return rec, time.perf_counter() - t0


# --------------------------------------------------------------------------- analysis
def _block(values, blocks=5):
    values = np.asarray(values, dtype=float)
    if len(values) < 2 * blocks:
        return float(values.mean()), float("nan")
    parts = [p.mean() for p in np.array_split(values, blocks)]
    return float(values.mean()), float(np.std(parts, ddof=1) / np.sqrt(blocks))


def _ratio_block(num, den, blocks=5):
    num, den = np.asarray(num), np.asarray(den)
    if len(num) < 2 * blocks:
        return float(num.mean() / den.mean()), float("nan")
    parts = [a.mean() / b.mean() for a, b in
             zip(np.array_split(num, blocks), np.array_split(den, blocks), strict=True)]
    return float(num.mean() / den.mean()), float(np.std(parts, ddof=1) / np.sqrt(blocks))


def analyse(rec, state, masses, context, rng, dt_fs):
    """Temperatures, ⟨U⟩, T_conf and energy conservation of one run (K, kJ/mol per molecule)."""
    n = len(state["positions"]) // 4
    out = {}
    for key, dof in (("K_tr", 3 * n - 3), ("K_rot", 3 * n)):
        t = 2 * np.asarray(rec[key]) / (dof * KB_KJ)
        out["T" + key[1:]] = _block(t)
        out["T" + key[1:] + "_start"] = float(t[0])
        if key + "_atoms" in rec:
            out["T" + key[1:] + "_atoms_max_dev"] = float(np.max(np.abs(
                2 * np.asarray(rec[key + "_atoms"]) / (dof * KB_KJ) - t)))
    total = (np.asarray(rec["K_tr"]) + np.asarray(rec["K_rot"])) * 2 / ((6 * n - 3) * KB_KJ)
    out["T_6N-3"] = _block(total)
    sums = np.array([configurational_sums(context, f, masses, rng) for f in rec["frames"]])
    out["U_per_molecule"] = _block(sums[:, 0] / n)
    out["Tconf_tr"] = [v / KB_KJ for v in _ratio_block(sums[:, 1], sums[:, 2])]
    out["Tconf_rot"] = [v / KB_KJ for v in _ratio_block(sums[:, 3], sums[:, 4])]
    e = np.asarray(rec["E"]) / n
    t_ps = np.arange(len(e)) * _steps(dt_fs, KE_FS) * dt_fs / 1000
    out["E_fluct_per_molecule"] = float(np.std(e))
    out["E_drift_per_molecule_per_ns"] = float(np.polyfit(t_ps, e, 1)[0] * 1000) \
        if len(e) > 2 else 0.0
    out["frames"] = len(rec["frames"])
    return out


def divergence(a, b, cell):
    """RMS distance (Å) between two codes' oxygens, minimum image, per recorded time."""
    from ase.geometry import find_mic

    n = min(len(a), len(b))
    return [float(np.sqrt(np.mean(find_mic(a[i] - b[i], cell)[1] ** 2))) for i in range(n)]


def divergences(tracks, cell):
    """{dt: RMS O distance series} for every time step both codes ran (``tracks`` by
    ``"<code>_<dt>"``)."""
    out = {}
    for key in tracks:
        code, dt = key.split("_")
        if code == "rigidmd" and f"openmm_{dt}" in tracks and len(tracks[key]):
            out[dt] = divergence(tracks[key], tracks[f"openmm_{dt}"], cell)
    return out


def report(stems, outdir, name):
    """Merge runs made separately (``--codes rigidmd`` and ``--codes openmm``) into one table."""
    runs, tracks, results = [], {}, None
    for stem in stems:
        stem = Path(stem)
        r = json.loads(stem.with_suffix(".json").read_text())
        results = results or r
        runs += [{"ps": r["ps"], "ensemble": r["ensemble"], "tau_ps": r["tau_ps"]} | run
                 for run in r["runs"]]
        if r["ensemble"] == "nve" and stem.with_suffix(".tracks.npz").exists():
            with np.load(stem.with_suffix(".tracks.npz")) as data:
                tracks.update({k: data[k] for k in data.files})
    runs.sort(key=lambda r: (r["ensemble"], r["ps"], r["dt_fs"], r["code"] != "rigidmd"))
    results["runs"] = runs
    cache = next(Path(outdir).glob("water_openmm_nve.start*.npz"), None)
    cell = np.load(cache)["cell"] if cache is not None else None
    results["divergence"] = divergences(tracks, cell) if cell is not None else {}
    return write_results(results, Path(outdir) / name, table(results))


def write_results(results, stem, text):
    """``<stem>.json`` (every number) and ``<stem>.txt`` (``text``, also printed)."""
    stem.with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")
    stem.with_suffix(".txt").write_text(text + "\n")
    print(text)
    return results


def table(results):
    lines = [f"TIP4P-Ew, {results['molecules']} waters, {DENSITY} g/cm³, every run from one "
             f"state (seed {results['seed']}); mean ± standard error of 5 blocks",
             "T_tr: 3N-3 dof, T_rot: 3N; T_conf from forces and torques (OpenMM's force field "
             "for both codes' frames); U: OpenMM's potential energy per molecule; run: "
             "ensemble, ps recorded, thermostat τ (ps; langevin: 1/friction) - langevin's "
             "kinetic columns are half-step velocities",
             "",
             f"{'code':8} {'run':>17} {'dt/fs':>5} {'T_tr':>14} {'T_rot':>14} {'T_6N-3':>14} "
             f"{'Tconf_tr':>14} {'Tconf_rot':>14} {'U kJ/mol':>16} {'E fluct':>8} "
             f"{'E drift/ns':>10}"]
    for r in results["runs"]:
        def f(key, r=r):
            v, e = r[key]
            return f"{v:7.2f} ± {e:4.2f}"
        u, ue = r["U_per_molecule"]
        run = f"{r.get('ensemble', results['ensemble'])} {r.get('ps', results['ps']):g}"
        if run.split()[0] != "nve":
            run += f" τ{r.get('tau_ps', results['tau_ps']):g}"
        lines.append(f"{r['code']:8} {run:>17} {r['dt_fs']:5g} {f('T_tr'):>14} {f('T_rot'):>14} "
                     f"{f('T_6N-3'):>14} {f('Tconf_tr'):>14} {f('Tconf_rot'):>14} "
                     f"{u:9.4f} ± {ue:5.3f} {r['E_fluct_per_molecule']:8.1e} "
                     f"{r['E_drift_per_molecule_per_ns']:10.1e}")
    lines.append("")
    for dt, d in results.get("divergence", {}).items():
        marks = ", ".join(f"{t:g} ps {d[int(round(t * 100))]:.2g}" for t in (0.1, 0.5, 1.0, 2.0)
                          if int(round(t * 100)) < len(d))
        lines.append(f"O positions rigidmd vs OpenMM, dt {dt} fs (RMS Å): {marks}")
    lines.append("")
    for r in results["runs"]:
        lines.append(f"{r['code']} {r.get('ensemble', '')} {r.get('ps', '')} ps at "
                     f"{r['dt_fs']:g} fs: {r['seconds']:.0f} s")
    return "\n".join(lines)


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dt-fs", type=float, nargs="+", default=[0.5, 1.0, 2.0, 3.0])
    p.add_argument("--ps", type=float, default=10.0, help="each run's length (ps)")
    p.add_argument("--ensemble", choices=("nve", "nvt", "langevin"), default="nve",
                   help="langevin: OpenMM's LangevinMiddleIntegrator (friction 1/--tau-ps), "
                        "OpenMM only")
    p.add_argument("--skip-ps", type=float, default=0.0,
                   help="thermostatted runs: ps made before recording")
    p.add_argument("--frame-fs", type=float, default=FRAME_FS,
                   help="fs between configurations (U, T_conf: 9 force calls each)")
    p.add_argument("--tau-ps", type=float, default=0.5,
                   help="NVT: Bussi τ (rigidmd) and Nosé–Hoover 1/collision frequency (OpenMM)")
    p.add_argument("--codes", nargs="+", choices=("rigidmd", "openmm"),
                   default=["rigidmd", "openmm"])
    p.add_argument("--eq-ps", type=float, default=20.0, help="equilibration of the start (ps)")
    p.add_argument("--track-ps", type=float, default=2.0,
                   help="NVE: O positions kept this long for the divergence")
    p.add_argument("--n-side", type=int, default=6)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--outdir", type=Path, default=HERE)
    p.add_argument("--name", default="water_openmm_nve", help="results file stem")
    p.add_argument("--report", nargs="+", metavar="STEM",
                   help="run nothing: merge these results (paths without .json) into "
                        "<outdir>/<name>.json and .txt")
    p.add_argument("--quick", action="store_true",
                   help="27 waters, 0.1 ps runs at 0.5 and 1 fs: checks the pipeline, no results")
    args = p.parse_args(argv)
    if args.quick:
        KSPACE.update(solver="ewald", accuracy=1e-6)
        args.n_side, args.eq_ps, args.ps, args.track_ps = 3, 0.2, 0.1, 0.1
        args.dt_fs = [0.5, 1.0]
        args.name += "_quick"
    return args


def main(argv=None):
    import openmm
    from openmm import unit

    args = parse(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    if args.report:
        return report(args.report, args.outdir, args.name)
    if args.ensemble == "langevin" and args.codes != ["openmm"]:
        raise SystemExit("water_openmm_nve: --ensemble langevin is OpenMM's; add --codes openmm")
    global FRAME_FS
    FRAME_FS = args.frame_fs
    SKIP["ps"] = args.skip_ps
    stem = args.outdir / args.name
    cache = args.outdir / f"water_openmm_nve.start{args.n_side}.{args.seed}.npz"
    state = equilibrated_state(args.n_side, args.seed, args.eq_ps, cache=cache)
    system = openmm_system(state)
    masses = np.array([system.getParticleMass(i).value_in_unit(unit.dalton)
                       for i in range(system.getNumParticles())])
    context = openmm.Context(system, openmm.VerletIntegrator(1e-3),
                             openmm.Platform.getPlatformByName("CPU"), {"Threads": "1"})
    results = {"molecules": len(masses) // 4, "ensemble": args.ensemble, "ps": args.ps,
               "seed": args.seed, "eq_ps": args.eq_ps, "tau_ps": args.tau_ps,
               "openmm": openmm.__version__, "runs": [], "divergence": {}}
    runners = {"rigidmd": run_rigidmd, "openmm": run_openmm}
    tracks = {}
    for dt in args.dt_fs:
        for code in args.codes:
            rec, seconds = runners[code](state, dt, args.ps, args.ensemble, args.tau_ps,
                                         args.track_ps, args.seed)
            r = {"code": code, "dt_fs": dt, "ps": args.ps, "ensemble": args.ensemble,
                 "tau_ps": args.tau_ps, "skip_ps": args.skip_ps, "seconds": seconds,
                 **analyse(rec, state, masses, context, np.random.default_rng(args.seed), dt)}
            results["runs"].append(r)
            tracks[f"{code}_{dt:g}"] = np.asarray(rec["O"])
            np.savez(stem.with_suffix(".tracks.npz"), **tracks)
            print(f"{code} {dt:g} fs: T_tr {r['T_tr'][0]:.2f} T_rot {r['T_rot'][0]:.2f} "
                  f"Tconf_tr {r['Tconf_tr'][0]:.1f} Tconf_rot {r['Tconf_rot'][0]:.1f} "
                  f"U {r['U_per_molecule'][0]:.4f} ({seconds:.0f} s)", flush=True)
            (stem.with_suffix(".json")).write_text(json.dumps(results, indent=1) + "\n")
    results["divergence"] = divergences(tracks, state["cell"])
    return write_results(results, stem, table(results))


if __name__ == "__main__":
    main()
