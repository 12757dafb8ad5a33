"""Atoms ↔ rigid state, on the backend chosen once (rigidmd.core.link).

The atoms' sync between steps, as a dynamics uses it, is checked in ``test_stepper.py``
and ``test_dynamics.py``; here the link's own conversions."""

import numpy as np
import pytest
from ase import units
from helpers import mixture

from rigidmd import RigidVerlet
from rigidmd.core.link import BodyLink


@pytest.fixture(params=["numpy", "numba"])
def dyn(request):
    return RigidVerlet(mixture(), 1 * units.fs, backend=request.param)


def test_place_and_momenta_reproduce_the_atoms(dyn):
    link, state, atoms = dyn.link, dyn.state, dyn.atoms
    assert link.backend.name == dyn.backend
    positions, momenta = atoms.positions.copy(), atoms.get_momenta().copy()
    atoms.arrays["positions"][:] = 0.0
    atoms.arrays["momenta"][:] = 0.0
    r = link.place(state)
    link.write_momenta(state, r)
    assert np.allclose(atoms.positions, positions, atol=1e-12)
    assert np.allclose(atoms.get_momenta(), momenta, atol=1e-12)
    body, speed = link.largest_angular_speed(state)
    assert 0 <= body < dyn.model.n_bodies and speed > 0


def test_reading_back_projects_onto_rigid_motion(dyn):
    link, state, atoms = dyn.link, dyn.state, dyn.atoms
    copy = state.copy()
    assert link.read_momenta(state) == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(state.data, copy.data, atol=1e-12)
    momenta = atoms.get_momenta()
    momenta[0] += [0.5, 0.0, 0.0]  # not a rigid motion of body 0
    atoms.set_momenta(momenta, apply_constraint=False)
    with pytest.warns(UserWarning, match="Owner: projecting the atoms' velocities onto "
                                         "rigid-body motion removed"):
        removed = link.read_momenta(state, owner="Owner")
    assert removed > 0 and link.removed_kinetic_energy == removed
    atoms.positions[:] += [0.1, 0.2, 0.3]
    link.read_positions(state)
    assert np.allclose(state.X, copy.X + [0.1, 0.2, 0.3], atol=1e-10)
    assert np.allclose(state.x, copy.x + [0.1, 0.2, 0.3], atol=1e-12)


def test_changes_between_steps_are_noticed(dyn):
    link, atoms = dyn.link, dyn.atoms
    written = link.snapshot()
    assert not link.differs(written)
    assert link.changes_since(written, "before step 1") == (False, False)
    atoms.positions[3, 0] += 0.01
    assert link.differs(written)
    assert link.changes_since(written, "before step 1") == (True, False)
    momenta = atoms.get_momenta()
    momenta[2, 1] = np.nan
    atoms.set_momenta(momenta, apply_constraint=False)
    with pytest.raises(ValueError, match="atom 2 has a non-finite momentum .* before step 1"):
        link.changes_since(written, "before step 1")
    link.check_unchanged_system()
    atoms.set_masses(np.r_[atoms.get_masses()[:-1], 30.0])
    with pytest.raises(ValueError, match="the atoms' masses changed; create a new dynamics"):
        link.check_unchanged_system()
    atoms.constraints = []
    del atoms[-1]
    with pytest.raises(ValueError, match="the atoms changed from 26 to 25"):
        link.check_unchanged_system()


def test_an_unknown_backend_is_refused():
    dyn = RigidVerlet(mixture(), 1 * units.fs)
    with pytest.raises(ValueError, match="backend must be 'numba' or 'numpy', got 'cuda'"):
        BodyLink(dyn.atoms, dyn.model, "cuda")
