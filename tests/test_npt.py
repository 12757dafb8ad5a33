"""Molecular pressure and the barostats (RigidNPT: MTK; RigidCRescale: stochastic cell rescaling).

Systems: a liquid of 64 rigid LJ dimers (N2-like, linear bodies, molecules
across the boundaries; :func:`helpers.dimer_fluid`) and an fcc LJ argon
crystal of free atoms (:func:`helpers.argon_crystal`), both with the
compiled :class:`helpers.PeriodicLJ`, which has stress.
"""

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from helpers import PeriodicLJ, argon_crystal, dimer_fluid, waters

from rigidmd import RigidCRescale, RigidNPT, RigidVerlet
from rigidmd import quaternion as quat
from rigidmd.coupling.barostats import BarostatError

T = 80.0


def strained_energy(atoms, dyn, strain):
    """Energy with centres of mass and cell strained by (1 + strain), orientations fixed."""
    m, s = dyn.model, dyn.state
    deformation = np.eye(3) + strain
    X = s.X @ deformation.T
    copy = atoms.copy()
    copy.set_cell(s.cell @ deformation.T)
    copy.positions[m.order] = X[m.atom_body] + quat.rotate(s.q[m.atom_body],
                                                            m.body_coordinates)
    copy.positions[m.free] = s.x @ deformation.T
    copy.calc = PeriodicLJ(**{k: getattr(atoms.calc, k) for k in ("sigma", "epsilon", "rc")})
    return copy.get_potential_energy()


def test_stress_is_the_strain_derivative_of_the_energy():
    """σ = (1/V) ∂E/∂ε with the centres of mass strained and the orientations fixed."""
    atoms = dimer_fluid(n_side=4, rc=7.0)
    dyn = RigidVerlet(atoms, units.fs, bodies="tags")
    sigma = dyn.get_stress(include_ideal_gas=False, voigt=False)
    volume, delta = dyn.get_volume(), 1e-5
    numeric = np.zeros((3, 3))
    for i in range(3):
        for j in range(i, 3):
            strain = np.zeros((3, 3))
            strain[i, j] = strain[j, i] = delta if i == j else 0.5 * delta
            e_plus = strained_energy(atoms, dyn, strain)
            e_minus = strained_energy(atoms, dyn, -strain)
            numeric[i, j] = numeric[j, i] = (e_plus - e_minus) / (2 * delta * volume)
    # Central differences with a strain of 1e-5 on a smooth (shifted-force)
    # potential: measured agreement 2e-10 of the largest component.
    np.testing.assert_allclose(sigma, numeric, atol=1e-8 * np.abs(numeric).max())
    # The atomic stress of the calculator differs: it includes the intramolecular virial.
    atomic = atoms.get_stress(include_ideal_gas=False, voigt=False)
    assert np.abs(atomic - sigma).max() > 1e-3 * np.abs(sigma).max()


def test_atomic_pressure_with_constraint_forces_equals_molecular_pressure():
    """The instantaneous atomic pressure, constraint forces included, is the molecular one.

    The forces g_i that keep the bodies rigid make m_i a_i = f_i + g_i with
    a_i the rigid-body acceleration; the atomic pressure
    (Σ m v² + Σ x·(f + g)) / 3V then equals the molecular pressure exactly.
    """
    atoms = dimer_fluid(n_side=4, rc=7.0)
    dyn = RigidVerlet(atoms, units.fs, bodies="tags")
    dyn.run(20)
    m, s = dyn.model, dyn.state
    forces = atoms.get_forces()
    r = quat.rotate(s.q[m.atom_body], m.body_coordinates)
    F = np.add.reduceat(forces[m.order], m.starts)
    tau = np.add.reduceat(np.cross(r, forces[m.order]), m.starts)
    omega = dyn.angular_velocities
    L = dyn.angular_momenta
    # Euler's equations in the lab frame: I dω/dt = τ - ω × L, I = R diag(I_b) Rᵀ
    # (about the axis of these linear bodies there is no rotation).
    torque_body = quat.rotate_inverse(s.q, tau - np.cross(omega, L))
    alpha = quat.rotate(s.q, m.inv_moments * torque_body)
    b = m.atom_body
    accel = (F / m.mass[:, None])[b] + np.cross(alpha[b], r) + np.cross(omega[b],
                                                                       np.cross(omega[b], r))
    constraint = m.atom_masses[:, None] * accel - forces[m.order]
    # The constraint forces are internal: no net force or torque on any body.
    assert np.abs(np.add.reduceat(constraint, m.starts)).max() < 1e-12
    virial_atoms = -dyn.get_volume() * np.trace(atoms.get_stress(voigt=False,
                                                                 include_ideal_gas=False))
    virial_constraint = np.sum(r * constraint)  # Σ d_i·g_i (forces internal to each body)
    p = atoms.get_momenta()
    kinetic = np.sum(p**2 / atoms.get_masses()[:, None])
    atomic_pressure = (kinetic + virial_atoms + virial_constraint) / (3 * dyn.get_volume())
    # Measured: equal to 4e-16 of the pressure's magnitude (roundoff).
    assert dyn.get_pressure() == pytest.approx(atomic_pressure, rel=1e-10, abs=1e-12)


def test_stress_of_a_calculator_without_stress_is_a_clear_error():
    atoms = waters(2)
    atoms.set_cell([100, 100, 100])  # ASE's TIP3P(rc=40) needs rc < half the box
    atoms.pbc = True
    dyn = RigidVerlet(atoms, units.fs)
    with pytest.raises(Exception, match="calculator TIP3P provides no stress"):
        dyn.get_stress()
    cluster = RigidVerlet(waters(2), units.fs)
    with pytest.raises(ValueError, match="periodic in all three directions"):
        cluster.get_pressure()


def npt(atoms, kind, dt=5 * units.fs, couple="iso", pressure=units.bar, **kwargs):
    if kind == "mtk":
        return RigidNPT(atoms, dt, T, pressure, 100 * units.fs, 1000 * units.fs, couple=couple,
                        bodies=kwargs.pop("bodies", "tags"), **kwargs)
    return RigidCRescale(atoms, dt, T, pressure, 100 * units.fs, 500 * units.fs,
                         1e-4 / units.bar, couple=couple, bodies=kwargs.pop("bodies", "tags"),
                         rng=np.random.default_rng(7), **kwargs)


@pytest.mark.parametrize("couple", ["iso", "aniso", "tri"])
def test_mtk_conserved_energy_is_second_order(couple):
    """The MTK conserved energy's error falls as dt², on a sheared crystal (a hard case)."""
    errors = []
    for dt in (4, 2):
        atoms = argon_crystal(shear=0.06)
        dyn = RigidNPT(atoms, dt * units.fs, 20, units.bar, 100 * units.fs, 1000 * units.fs,
                       couple=couple, bodies=[])
        energy = []
        dyn.attach(lambda dyn=dyn, energy=energy: energy.append(dyn.get_conserved_energy()),
                   interval=int(20 / dt))
        dyn.run(int(1500 / dt))
        errors.append(np.abs(np.array(energy) - energy[0]).max())
    # Measured (tri, 3 ps): 2.0e-4, 5.1e-5, 1.3e-5 eV at 4, 2, 1 fs: ratio 4.0.
    assert 3.0 < errors[0] / errors[1] < 5.0
    assert errors[0] < 5e-4


def test_crescale_effective_energy_tracks_the_integration_error():
    drifts = []
    for dt in (10, 5):
        atoms = dimer_fluid(n_side=4, rc=7.0)
        dyn = npt(atoms, "crescale", dt=dt * units.fs)
        energy = []
        dyn.attach(lambda dyn=dyn, energy=energy: energy.append(dyn.get_conserved_energy()),
                   interval=int(50 / dt))
        dyn.run(int(5000 / dt))
        energy = np.array(energy)
        drifts.append(np.abs(energy - energy[0]).max())
    # Measured largest |H - H0| over 5 ps: 2.3e-3, 9.5e-4, 3.2e-4 eV at 10, 5,
    # 2.5 fs (ratios 2.5, 3.0): the effective energy measures the integration
    # error, as Bernetti & Bussi's scheme intends.  Without the barostat's
    # bookkeeping it would wander by 0.18 eV (measured) in the same run.
    assert drifts[0] / drifts[1] > 1.8
    assert drifts[1] < 2e-3


@pytest.mark.parametrize("integrator", ["no_squish", "richardson", "rozmanov_kusalik", "pcdm"])
@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_barostats_work_with_every_scheme_and_backend(kind, integrator):
    runs = []
    for backend in ("numba", "numpy"):
        atoms = dimer_fluid(n_side=4, rc=7.0)
        dyn = npt(atoms, kind, integrator=integrator, backend=backend)
        dyn.run(40)
        runs.append((atoms.positions.copy(), atoms.cell.array.copy()))
        # The molecules stay whole and rigid as the cell moves.
        bonds = np.linalg.norm(atoms.positions[0::2] - atoms.positions[1::2], axis=1)
        np.testing.assert_allclose(bonds, 1.1, rtol=1e-12)
    # The compiled drift with the cell's motion is the operators' (measured 2e-14 Å).
    np.testing.assert_allclose(runs[0][0], runs[1][0], atol=1e-11)
    np.testing.assert_allclose(runs[0][1], runs[1][1], atol=1e-11)


@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_failed_step_is_rolled_back_with_the_cell(kind):
    """A calculator failing mid-run: state, cell and barostat are as before the step."""

    class Flaky(PeriodicLJ):
        calls = 0

        def calculate(self, *args, **kwargs):
            Flaky.calls += 1
            if Flaky.calls == 30:
                raise RuntimeError("calculator failed")
            super().calculate(*args, **kwargs)

    reference = dimer_fluid(n_side=4, rc=7.0)
    npt(reference, kind).run(40)
    atoms = dimer_fluid(n_side=4, rc=7.0)
    atoms.calc = Flaky(rc=7.0)
    dyn = npt(atoms, kind)
    with pytest.raises(RuntimeError, match="calculator failed"):
        dyn.run(40)
    before = dyn.nsteps
    np.testing.assert_array_equal(atoms.cell.array, dyn.state.cell)
    dyn.run(40 - before)
    # Continuing after the failure gives the uninterrupted run, bit for bit.
    np.testing.assert_array_equal(atoms.positions, reference.positions)
    np.testing.assert_array_equal(atoms.cell.array, reference.cell.array)


def test_bad_barostat_input_is_refused_before_anything_changes():
    atoms = dimer_fluid(n_side=4, rc=7.0)
    before = atoms.positions.copy()
    with pytest.raises(ValueError, match="pdamp = .* is under 10 time steps"):
        RigidNPT(atoms, 5 * units.fs, T, units.bar, 100 * units.fs, 40 * units.fs, bodies="tags")
    with pytest.raises(ValueError, match="couple must be one of iso, aniso, tri"):
        npt(atoms, "mtk", couple="xyz")
    with pytest.raises(ValueError, match="pressure_au is in eV/Å³"):
        npt(atoms, "mtk", pressure=1.01325)  # 1 atm given in bar
    cluster = dimer_fluid(n_side=4, rc=7.0)
    cluster.pbc = False
    with pytest.raises(ValueError, match="periodic cell in all three directions"):
        npt(cluster, "crescale")
    tip3p = waters(2)
    tip3p.set_cell([20, 20, 20])
    tip3p.pbc = True
    tip3p.calc = TIP3P(rc=9.0)
    with pytest.raises(ValueError, match="calculator TIP3P provides no stress"):
        npt(tip3p, "mtk", bodies=None)

    class Orthorhombic(PeriodicLJ):
        orthorhombic_only = True

    atoms.calc = Orthorhombic(rc=7.0)
    with pytest.raises(ValueError, match="couple='tri' shears the cell, but the calculator"):
        npt(atoms, "mtk", couple="tri")
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def test_volume_jump_stops_and_rolls_back():
    # A compressibility far too large (3e-3 and 0.1 per bar against 1e-4 for
    # this liquid): the first step would change the volume by tens of percent,
    # or collapse the cell.
    for compressibility, message in ((3e-3, "volume would change by .*% in one step"),
                                     (0.1, "volume would collapse in one step")):
        atoms = dimer_fluid(n_side=4, rc=7.0)
        cell = atoms.cell.array.copy()
        dyn = RigidCRescale(atoms, 5 * units.fs, T, 1000 * units.bar, 100 * units.fs,
                            50 * units.fs, compressibility / units.bar, bodies="tags",
                            rng=np.random.default_rng(0))
        with pytest.raises(BarostatError, match=message):
            dyn.run(5)
        assert dyn.nsteps == 0
        np.testing.assert_array_equal(atoms.cell.array, cell)
        np.testing.assert_array_equal(dyn.state.cell, cell)
