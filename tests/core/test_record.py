"""The per-step record: quantities derived from the state, computed once
(rigidmd.core.record).  How the record follows the couplings' changes during steps is
checked in ``test_stepper.py``; here, its own arithmetic on both backends."""

import numpy as np
import pytest
from ase import units
from helpers import mixture

from rigidmd import RigidVerlet
from rigidmd.core import observables as obs


@pytest.fixture(params=["numpy", "numba"])
def dyn(request):
    dyn = RigidVerlet(mixture(), 1 * units.fs, backend=request.param)
    dyn.run(1)
    return dyn


def test_derived_quantities_equal_the_observables(dyn):
    record, state, model = dyn.record, dyn.state, dyn.model
    assert record.backend is dyn.link.backend and record.backend.name == dyn.backend
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model), rtol=1e-14)
    assert record.translational_energy == pytest.approx(
        obs.translational_kinetic_energies(state, model).sum()
        + obs.free_kinetic_energy(state, model), rel=1e-13)
    assert record.rotational_energy == pytest.approx(
        obs.rotational_kinetic_energy(state, model), rel=1e-13)
    assert record.volume == pytest.approx(abs(np.linalg.det(state.cell)))
    net, size = record.net_force()
    assert net == pytest.approx(np.linalg.norm(record.F.sum(0) + record.f.sum(0)), abs=1e-12)
    assert size == pytest.approx(np.abs(record.F).sum() + np.abs(record.f).sum())


def test_scaling_follows_without_a_new_sum(dyn):
    record, state, model = dyn.record, dyn.state, dyn.model
    assert record.kinetic_tensor is not None and record.rotational_energy > 0  # computed once
    scale = np.array([[1.1, 0.02, 0.0], [0.0, 0.9, 0.0], [0.01, 0.0, 1.0]])
    state.V[...] = state.V @ scale.T  # written in place: the record is told
    state.v[...] = state.v @ scale.T
    record.scaled(scale)
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model), rtol=1e-12)
    state.V[...] *= 0.5
    state.v[...] *= 0.5
    state.p[...] *= 2.0
    record.scaled(0.5, 2.0)
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model), rtol=1e-12)
    assert record.rotational_energy == pytest.approx(
        obs.rotational_kinetic_energy(state, model), rel=1e-12)
    masses = np.concatenate([model.mass, model.free_masses])
    velocities = np.concatenate([state.V, state.v])
    centre = masses @ velocities / masses.sum()
    state.V[...] = centre + 0.3 * (state.V - centre)
    state.v[...] = centre + 0.3 * (state.v - centre)
    record.scaled(0.3, about=(centre, masses.sum()))
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model), rtol=1e-10)
    state.V *= 3.0  # an assignment the record cannot follow: its version moves, recomputed
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model), rtol=1e-12)


def test_state_round_trip_and_backup(dyn):
    record = dyn.record
    saved = record.get_state()
    forces = record.F.copy()
    record.F[:] = 0.0
    record.energy = 123.0
    record.scratch["x"] = 1
    record.set_state(saved)
    assert np.array_equal(record.F, forces) and record.energy == saved["energy"]
    assert "x" not in record.scratch
    record.set_state({"F": None})  # absent keys: recomputed when asked
    assert record.energy is None and np.array_equal(record.F, forces)
    assert np.allclose(record.kinetic_tensor, obs.kinetic_tensor(dyn.state, dyn.model))
