"""What the state says about itself: kinetic energies, momenta, virial, temperatures
(rigidmd.core.observables)."""

import numpy as np
import pytest
from ase import units
from helpers import mixture

from rigidmd import RigidVerlet
from rigidmd.core import observables as obs


@pytest.fixture
def dyn():
    return RigidVerlet(mixture(), 1 * units.fs)


def test_kinetic_energies_equal_the_atoms(dyn):
    state, model, atoms = dyn.state, dyn.model, dyn.atoms
    K = obs.kinetic_tensor(state, model)
    assert np.allclose(K, K.T)
    total = 0.5 * np.trace(K) + obs.rotational_kinetic_energy(state, model)
    assert total == pytest.approx(atoms.get_kinetic_energy(), rel=1e-10)
    assert obs.translational_kinetic_energies(state, model).shape == (model.n_bodies,)
    assert obs.rotational_kinetic_energies(state, model).sum() == pytest.approx(
        obs.rotational_kinetic_energy(state, model))
    m = model.free_masses[:, None]
    assert obs.free_kinetic_energy(state, model) == pytest.approx(
        0.5 * np.sum(m * state.v**2))


def test_angular_momenta_and_velocities(dyn):
    state, model, atoms = dyn.state, dyn.model, dyn.atoms
    L = obs.angular_momenta(state, model)
    omega = obs.angular_velocities(state, model)
    body, speed = obs.largest_angular_speed(state, model)
    assert speed == pytest.approx(np.linalg.norm(omega, axis=1).max())
    assert body == int(np.argmax(np.linalg.norm(omega, axis=1)))
    assert L.shape == omega.shape == (model.n_bodies, 3)
    p, x = atoms.get_momenta(), atoms.positions
    expected = np.cross(x, p).sum(axis=0)
    assert np.allclose(obs.total_angular_momentum(state, model), expected, atol=1e-8)


def test_temperatures_and_degrees_of_freedom(dyn):
    model = dyn.model
    assert obs.kinetic_dof(model, holds_momentum=False) == (30, 20)
    assert obs.kinetic_dof(model, holds_momentum=True) == (27, 20)
    T_tr, T_rot = obs.kinetic_temperatures(1.0, 2.0, (30, 20))
    assert T_tr == pytest.approx(2 * 1.0 / (30 * units.kB))
    assert T_rot == pytest.approx(2 * 2.0 / (20 * units.kB))


def test_stress_from_virial_and_voigt():
    assert obs.volume(np.diag([2.0, 3.0, 4.0])) == pytest.approx(24.0)
    virial = np.array([[1.0, 0.2, 0.3], [0.2, 2.0, 0.5], [0.3, 0.5, 3.0]])
    kinetic = np.eye(3)
    sigma = obs.stress_tensor(virial, kinetic, 10.0)
    assert np.allclose(sigma, obs.stress_tensor(virial + kinetic, None, 10.0))
    assert np.allclose(obs.voigt(sigma), [sigma[0, 0], sigma[1, 1], sigma[2, 2],
                                          sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    assert np.allclose(obs.torque_virial(np.zeros((2, 3))), 0.0)
