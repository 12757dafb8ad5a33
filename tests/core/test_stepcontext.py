"""What operators read and write during a step, and the operators themselves
(rigidmd.core.stepcontext)."""

import numpy as np
import pytest
from ase import units
from helpers import mixture

from rigidmd import RigidVerlet
from rigidmd.core import observables as obs
from rigidmd.core import stepcontext as sc


@pytest.fixture
def ctx():
    dyn = RigidVerlet(mixture(), 1 * units.fs, backend="numpy")
    dyn.run(1)  # forces in the record
    return dyn.stepper.context


def test_the_context_holds_the_dynamics_parts(ctx):
    assert (ctx.n_bodies, ctx.n_free) == (8, 2)
    assert ctx.packed_model is ctx.model.packed
    assert ctx.write_momenta and ctx.cell_motion is None and ctx.middle == ()


def test_kick_and_drift(ctx):
    s, m, h = ctx.state, ctx.model, 0.3
    V, v, X, x = s.V.copy(), s.v.copy(), s.X.copy(), s.x.copy()
    sc.apply_translational_kick(ctx, h)
    assert np.allclose(s.V, V + h * ctx.record.F / m.mass[:, None], rtol=1e-14)
    assert np.allclose(s.v, v + h * ctx.record.f / m.free_masses[:, None], rtol=1e-14)
    sc.apply_drift(ctx, h)
    assert np.allclose(s.X, X + h * s.V, rtol=1e-14)
    assert np.allclose(s.x, x + h * s.v, rtol=1e-14)


def test_angular_velocities_round_trip(ctx):
    omega = ctx.omega()
    assert np.allclose(omega, obs.angular_velocities(ctx.state, ctx.model))
    ctx.set_omega(2 * omega)
    assert np.allclose(ctx.omega(), 2 * omega, rtol=1e-12, atol=1e-14)


def test_a_free_rotation_is_reversible_and_keeps_unit_quaternions(ctx):
    """NO_SQUISH's free rotor over h then -h returns the orientations (to roundoff)."""
    q, p = ctx.state.q.copy(), ctx.state.p.copy()
    sc.apply_no_squish_rotate(ctx, 1.0)
    assert np.allclose(np.linalg.norm(ctx.state.q, axis=1), 1.0, atol=1e-14)
    assert not np.allclose(ctx.state.q, q)
    sc.apply_no_squish_rotate(ctx, -1.0)
    assert np.allclose(ctx.state.q, q, atol=1e-12) and np.allclose(ctx.state.p, p, atol=1e-12)


def test_pcdm_correct_needs_its_predict(ctx):
    with pytest.raises(RuntimeError, match="pcdm_correct needs a pcdm_predict earlier in the "
                                           "step"):
        sc.apply_pcdm_correct(ctx, 0.1)
    sc.apply_pcdm_predict(ctx, 0.1)
    assert "pcdm" in ctx.record.scratch
    sc.apply_pcdm_correct(ctx, 0.1)
    assert "pcdm" not in ctx.record.scratch


def test_the_middle_parts_run_on_the_view_and_the_record_follows_their_change(ctx):
    seen = []

    class Part:
        def middle(self, view, h):
            seen.append((view, h))
            ctx.state.V *= 2.0  # an assignment: the momenta's version moves

    ctx.middle, ctx.view = (Part(), Part()), "view"
    K = ctx.record.kinetic_tensor.copy()
    sc.apply_middle(ctx, 0.5)
    assert seen == [("view", 0.5), ("view", 0.5)]
    # No stale value: the bodies' part of the tensor is 16 times as large, the free atoms'
    # (whose velocities stayed) as it was.
    fresh = obs.kinetic_tensor(ctx.state, ctx.model)
    assert np.allclose(ctx.record.kinetic_tensor, fresh) and not np.allclose(fresh, K)


def test_a_cell_move_keeps_the_barostats_note(ctx):
    class Mover:
        def drift_matrices(self, view, h):
            return np.eye(3), np.eye(3) * h, np.eye(3), ("note", h)

    ctx.cell_motion = Mover()
    A, B, S = ctx.cell_move(0.25)
    assert np.array_equal(B, np.eye(3) * 0.25)
    assert ctx.cell_note == ("note", 0.25)  # kept on the view, not on the record
