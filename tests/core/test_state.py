"""The dynamical state in one buffer (rigidmd.core.state)."""

import numpy as np
import pytest

from rigidmd.core.state import STATE_FIELDS, RigidState


def make(n_bodies=2, n_free=1, seed=0):
    rng = np.random.default_rng(seed)
    return RigidState(rng.normal(size=(n_bodies, 3)), rng.normal(size=(n_bodies, 3)),
                      rng.normal(size=(n_bodies, 4)), rng.normal(size=(n_bodies, 4)),
                      rng.normal(size=(n_free, 3)), rng.normal(size=(n_free, 3)),
                      np.eye(3) * 10)


def test_the_fields_are_views_of_one_buffer_in_order():
    state = make()
    assert state.data.shape == (14 * 2 + 6 * 1 + 9,)
    flat = np.concatenate([getattr(state, name).ravel() for name in STATE_FIELDS])
    assert np.array_equal(flat, state.data)
    for name in STATE_FIELDS:
        assert getattr(state, name).base is state.data
    state.data[:3] = 7.0
    assert np.array_equal(state.X[0], [7.0, 7.0, 7.0])
    assert repr(state) == ("RigidState(n_bodies=2, n_free=1, cell=[[10.0, 0.0, 0.0], "
                           "[0.0, 10.0, 0.0], [0.0, 0.0, 10.0]])")


def test_assignment_copies_into_the_view():
    state = make()
    view = state.V
    state.V = np.ones((2, 3))
    assert state.V is view and np.array_equal(view, np.ones((2, 3)))
    with pytest.raises(ValueError, match=r"RigidState.V has shape \(2, 3\); cannot assign an "
                                         r"array of shape \(3, 3\)"):
        state.V = np.ones((3, 3))
    with pytest.raises(AttributeError, match="RigidState.data cannot be assigned"):
        state.data = np.zeros(3)
    with pytest.raises(AttributeError, match="RigidState.energy cannot be assigned"):
        state.energy = 1.0


def test_wrong_shapes_are_refused_at_construction():
    state = make()
    with pytest.raises(ValueError, match=r"RigidState.q must have shape \(2, 4\), got \(2, 3\)"):
        RigidState(state.X, state.V, state.X, state.p, state.x, state.v, state.cell)
    empty = RigidState(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 4)),
                       np.zeros((4, 3)), np.zeros((4, 3)), np.eye(3))
    assert empty.data.shape == (6 * 4 + 9,)


def test_copies_are_independent_and_copy_into_overwrites():
    state, other = make(seed=0), make(seed=1)
    copy = state.copy()
    assert np.array_equal(copy.data, state.data) and copy.data is not state.data
    copy.X[0, 0] += 1.0
    assert copy.X[0, 0] != state.X[0, 0]
    buffer = other.data
    state.copy_into(other)
    assert other.data is buffer and np.array_equal(other.data, state.data)
