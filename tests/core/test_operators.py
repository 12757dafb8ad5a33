"""The six rotational integrators: accuracy, order, reversibility, LAMMPS fix rigid."""

import numpy as np
import pytest
from ase import Atoms, units
from free_top import exact_body_angular_velocity
from helpers import ZeroForce, mixture, waters

from rigidmd import RigidBodies, RigidVerlet
from rigidmd.core import quaternion as quat
from rigidmd.core.operators import ConvergenceError
from rigidmd.lammps import run_rigid_reference, tip3p_charges, tip3p_pair_commands
from rigidmd.systems import R_CO

INTEGRATORS = ["no_squish", "richardson", "rozmanov_kusalik", "pcdm", "exadem"]
OMEGA_B0 = np.array([0.6, 0.3, 0.9])  # rad per ASE time unit, body frame


def free_top_error(integrator, dt, duration=5.0):
    """Largest |ω_b − exact| over the run of a free asymmetric top (moments 1.19, 9.55, 10.05)."""
    atoms = Atoms("OH2C", positions=[[0, 0, 0], [0.9, 0.3, 0.1], [-0.4, 0.8, -0.2],
                                     [0.3, -0.5, 0.9]])
    atoms.calc = ZeroForce()
    geom = RigidBodies.resolve(atoms, [[0, 1, 2, 3]]).geometry(atoms)
    omega = quat.rotate(geom.quaternions[0], OMEGA_B0)
    atoms.set_velocities(np.cross(omega, atoms.positions - geom.com[0]))
    dyn = RigidVerlet(atoms, dt, bodies=[[0, 1, 2, 3]], integrator=integrator)
    omega_body = []
    dyn.attach(lambda: omega_body.append(
        quat.rotate_inverse(dyn.quaternions[0], dyn.angular_velocities[0])), interval=10)
    steps = int(round(duration / dt))
    dyn.run(steps)
    t = np.arange(len(omega_body)) * 10 * dt
    exact = exact_body_angular_velocity(geom.model.moments[0], OMEGA_B0, t)
    return np.abs(np.array(omega_body) - exact).max()


@pytest.mark.parametrize("integrator, order", [("no_squish", 2), ("richardson", 2),
                                               ("rozmanov_kusalik", 2), ("pcdm", 2),
                                               ("exadem", 1), ("baoab", 2)])
def test_free_asymmetric_top_order(integrator, order):
    errors = [free_top_error(integrator, dt) for dt in (0.01, 0.005, 0.0025)]
    measured = np.log2(errors[1] / errors[2])
    # Measured orders on the last halving: 2.00, 1.96, 2.00, 2.00, 1.01, 2.00; the
    # errors at dt = 0.0025 (|ω| = 1.1) are 2.3e-6, 4.5e-6, 9.5e-6, 2.4e-7, 9.1e-3, 5.6e-7
    # (baoab without a part in its middle: two half NO_SQUISH rotations).
    assert measured == pytest.approx(order, abs=0.1)
    assert errors[2] < (1e-4 if order == 2 else 2e-2)


@pytest.mark.parametrize("make", [waters, mixture], ids=["waters", "co2-water-neon"])
def test_rozmanov_kusalik_time_reversal(make):
    """Tightly iterated (NO_SQUISH's reversal is tested in test_dynamics)."""
    atoms = make()
    start = atoms.positions.copy()
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", integrator="rozmanov_kusalik",
                      integrator_options={"tol": 1e-13})
    dyn.run(100)
    atoms.set_momenta(-atoms.get_momenta())
    dyn.run(100)
    # Measured 3e-14 (waters) and 1.5e-13 Å (mixture).
    assert np.abs(atoms.positions - start).max() < 1e-9


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_baoab_scheme_without_a_middle_part_is_reversible(backend):
    """``baoab`` with no part acting in its middle: B A A B, a symmetric splitting."""
    atoms = mixture()
    start = atoms.positions.copy()
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", integrator="baoab", backend=backend)
    dyn.run(100)
    atoms.set_momenta(-atoms.get_momenta())
    dyn.run(100)
    # Measured 6.0e-14 (numpy) and 6.6e-14 Å (numba).
    assert np.abs(atoms.positions - start).max() < 1e-9


def test_rozmanov_kusalik_reversible_only_when_tight():
    atoms = waters()
    start = atoms.positions.copy()
    dyn = RigidVerlet(atoms, units.fs, integrator="rozmanov_kusalik",
                      integrator_options={"tol": 1e-6})
    dyn.run(100)
    atoms.set_momenta(-atoms.get_momenta())
    dyn.run(100)
    # Measured 2.4e-8 Å: the unconverged iteration breaks the symmetry.
    assert 1e-10 < np.abs(atoms.positions - start).max() < 1e-6


def test_richardson_is_not_reversible():
    """LAMMPS's Richardson update is not symmetric: 50 fs out and back misses by ~dt³."""
    misses = []
    for dt in (1.0, 0.5):
        atoms = waters()
        start = atoms.positions.copy()
        dyn = RigidVerlet(atoms, dt * units.fs, integrator="richardson")
        dyn.run(int(50 / dt))
        atoms.set_momenta(-atoms.get_momenta())
        dyn.run(int(50 / dt))
        misses.append(np.abs(atoms.positions - start).max())
    # Measured 9.3e-6 and 1.2e-6 Å: order 3.0, far above roundoff.
    assert misses[1] > 1e-8
    assert np.log2(misses[0] / misses[1]) == pytest.approx(3.0, abs=0.3)


@pytest.mark.lammps
@pytest.mark.parametrize("n", [8, 27])
def test_richardson_against_lammps_fix_rigid(n):
    atoms = waters(n, seed=n)
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    ref = run_rigid_reference(atoms, body_ids, tip3p_pair_commands(40.0), units.fs, 500,
                              every=100, fix="rigid", charges=tip3p_charges(atoms))
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", integrator="richardson")
    positions, energies = [], []
    dyn.attach(lambda: (positions.append(atoms.positions.copy()),
                        energies.append(atoms.get_total_energy())), interval=100)
    dyn.run(500)
    gap = np.abs(np.array(positions) - ref.positions).max(axis=(1, 2))
    # Measured (8, 27 waters): 2e-14, 4e-14 Å at step 100; 2e-11, 4e-11 Å at
    # step 500; energies 1e-13, 3e-13 eV.
    assert gap[1] < 1e-6
    assert gap[5] < 1e-4
    assert np.abs(np.array(energies) - ref.total_energy).max() < 1e-6


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_linear_bodies_and_free_atoms(integrator):
    atoms = mixture()
    P0 = atoms.get_momenta().sum(axis=0)
    e0 = atoms.get_total_energy()
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", integrator=integrator)
    dyn.run(300)
    # Translation is velocity Verlet in every scheme: momentum to roundoff.
    np.testing.assert_allclose(atoms.get_momenta().sum(axis=0), P0, atol=1e-11)
    # Linear bodies stay straight and rigid: C-O distances and collinearity.
    for b in np.flatnonzero(dyn.model.linear):
        c, o1, o2 = atoms.positions[dyn.bodies.atoms_of(b)]
        np.testing.assert_allclose(np.linalg.norm([o1 - c, o2 - c], axis=1), R_CO, rtol=1e-12)
        np.testing.assert_allclose(np.cross(o1 - c, o2 - c), 0.0, atol=1e-11)
    # Their atoms carry no kinetic energy beyond the 5 rigid degrees of freedom:
    # all of it is translation of the centre plus rotation about the 2 axes.
    v = atoms.get_velocities()
    for b in np.flatnonzero(dyn.model.linear):
        idx = dyn.bodies.atoms_of(b)
        m = atoms.get_masses()[idx]
        ke = 0.5 * np.sum(m[:, None] * v[idx] ** 2)
        assert ke == pytest.approx(dyn.translational_kinetic_energies[b]
                                   + dyn.rotational_kinetic_energies[b], rel=1e-10)
    # Energy errors measured over 300 fs: 8e-4 eV for the second-order
    # schemes, 0.2 eV of heating for exaDEM.
    error = abs(atoms.get_total_energy() - e0)
    assert error < (0.5 if integrator == "exadem" else 5e-3)


def test_pcdm_calls_the_calculator_twice_per_step():
    atoms = waters(4)
    calls = []
    original = atoms.calc.calculate

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    atoms.calc.calculate = counting
    dyn = RigidVerlet(atoms, units.fs, integrator="pcdm")
    dyn.run(0)
    before = len(calls)
    dyn.run(10)
    assert len(calls) - before == 20


def test_rozmanov_kusalik_iteration_cap_names_the_body(tmp_path):
    atoms = waters(4)
    traj = tmp_path / "rk.traj"
    dyn = RigidVerlet(atoms, 2 * units.fs, integrator="rozmanov_kusalik",
                      integrator_options={"tol": 1e-15, "max_iter": 2}, trajectory=str(traj))
    start = atoms.positions.copy()
    with pytest.raises(ConvergenceError, match=r"body \d+ did not converge in 2 iterations"):
        dyn.run(5)
    # Nothing of the failed step remains.
    np.testing.assert_array_equal(atoms.positions, start)
