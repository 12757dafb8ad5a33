"""Issue 36: the relaxation's compiled loops give what the NumPy formulas they replace give."""

from types import SimpleNamespace

import numpy as np

from rigidmd.core import operators as ops
from rigidmd.core import quaternion as quat
from rigidmd.relax import _numba
from rigidmd.relax.rotationvector import right_jacobian_transpose, rotation_quaternion


def _rows(rng, n):
    """Rotation rows of ``n`` bodies: large angles, below the two series' thresholds
    (1e-4 and 1e-3 rad) and zero; the first two bodies linear."""
    lengths = rng.uniform(0.5, 1.5, n)
    phi = rng.normal(scale=0.8, size=(n, 3))
    phi[2] *= 1e-5  # sin(θ/2)/θ and J_r's coefficients by their series
    phi[3] *= 5e-4  # J_r's by its series, the quaternion's not
    phi[4] = 0.0
    linear = np.zeros(n, dtype=bool)
    linear[:2] = True
    return phi * lengths[:, None], lengths, linear


def test_the_compiled_placement_is_the_numpy_formula_bit_for_bit():
    """kernels.orientations is q_ref ⊗ exp(φ) as rotation_quaternion and quat.multiply
    compute it (the rotation vector's first component 0 for a linear body), bit for bit:
    RigidFilter's placement changed no bit when it moved into the compiled loop."""
    rng = np.random.default_rng(0)
    n = 40
    x, lengths, linear = _rows(rng, n)
    q_ref = quat.normalize(rng.normal(size=(n, 4)))
    phi = np.where(linear[:, None] & (np.arange(3) == 0), 0.0, x / lengths[:, None])
    expected = quat.multiply(q_ref, rotation_quaternion(phi))
    q = np.empty((n, 4))
    _numba.orientations(q_ref, x, lengths, linear, q)
    np.testing.assert_array_equal(q, expected)
    assert _numba.largest_angle(x, lengths, linear) == np.linalg.norm(phi, axis=1).max()


def test_the_compiled_reduction_is_the_numpy_formula():
    """kernels.body_gradient: body forces and torques as operators.reduce_forces sums them,
    and the rotation rows' gradient J_r(φ)ᵀ R(q)ᵀ τ / ℓ as right_jacobian_transpose and
    quaternion.rotate_inverse compute it, 0 about a linear body's axis and 0 for a fixed
    body (its force and torque kept).  Bit for bit when measured (the loop sums a segment
    as NumPy's add.reduceat does, its first term plus the sum of the rest); 1e-14 allowed,
    as NumPy's order of a reduction is its own to change."""
    rng = np.random.default_rng(1)
    n, sizes = 40, rng.integers(1, 5, 40)  # bodies of 1 to 4 atoms
    n_atoms = int(sizes.sum()) + 3  # and three free atoms
    order = rng.permutation(n_atoms)[:sizes.sum()]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    bounds = np.append(starts, len(order)).astype(np.int64)
    forces = rng.normal(size=(n_atoms, 3))
    r = rng.normal(size=(len(order), 3))
    x, lengths, linear = _rows(rng, n)
    q = quat.normalize(rng.normal(size=(n, 4)))
    fixed = np.zeros(n, dtype=bool)
    fixed[5] = True
    F, tau, g = (np.empty((n, 3)) for _ in range(3))
    _numba.body_gradient(forces, r, order, bounds, q, x, lengths, linear, fixed, F, tau, g)

    model = SimpleNamespace(n_bodies=n, order=order, starts=starts)  # what it reads
    F_numpy, tau_numpy = ops.reduce_forces(forces, r, model)
    np.testing.assert_allclose(F, F_numpy, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(tau, tau_numpy, rtol=1e-14, atol=1e-14)
    phi = np.where(linear[:, None] & (np.arange(3) == 0), 0.0, x / lengths[:, None])
    expected = right_jacobian_transpose(phi, quat.rotate_inverse(q, tau)) / lengths[:, None]
    expected[linear, 0] = 0.0
    expected[fixed] = 0.0
    np.testing.assert_allclose(g, expected, rtol=1e-14, atol=1e-14)
    assert np.all(g[linear, 0] == 0.0) and np.all(g[fixed] == 0.0)
