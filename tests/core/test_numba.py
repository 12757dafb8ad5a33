"""The compiled kernels' small helpers against the NumPy they replace (rigidmd.core._numba).

The fused half-steps are checked against the operator lists in ``test_dynamics.py`` and
``tests/project/test_trajectory_identity.py``; here the backend choice and the helpers."""

import numpy as np
import pytest

from rigidmd.core import _numba
from rigidmd.core import operators as ops


def test_the_backend_is_chosen_once():
    assert _numba.resolve_backend() == "numba"
    assert _numba.resolve_backend("numpy") == "numpy"
    with pytest.raises(ValueError, match="backend must be 'numba' or 'numpy', got 'jax'"):
        _numba.resolve_backend("jax")


def test_congruence_and_net_force(rng):
    F, K = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    assert np.allclose(_numba.congruence(F, K), F @ K @ F.T, rtol=1e-14, atol=1e-14)
    bodies, free = rng.normal(size=(5, 3)), rng.normal(size=(2, 3))
    net, size = _numba.net_force(bodies, free)
    assert net == pytest.approx(np.linalg.norm(bodies.sum(0) + free.sum(0)), rel=1e-13)
    assert size == pytest.approx(np.abs(bodies).sum() + np.abs(free).sum(), rel=1e-14)
    assert _numba.net_force(np.zeros((0, 3)), np.zeros((0, 3))) == (0.0, 0.0)


def test_the_virials_equal_numpys(rng):
    order = np.array([3, 0, 2])
    r, forces = rng.normal(size=(3, 3)), rng.normal(size=(4, 3))
    w = _numba.intramolecular_virial(r, forces, order)
    outer = np.einsum("ja,jc->ac", r, forces[order])
    assert np.allclose(w, 0.5 * (outer + outer.T), rtol=1e-14, atol=1e-15)
    stress = rng.normal(size=6)
    full = np.array([[stress[0], stress[5], stress[4]], [stress[5], stress[1], stress[3]],
                     [stress[4], stress[3], stress[2]]])
    assert np.allclose(_numba.molecular_virial_voigt(stress, 7.0, r, forces, order),
                       -7.0 * full - w, rtol=1e-14, atol=1e-14)


def test_equal_or_close_is_allclose():
    a = np.array([1.0, 2.0, np.inf])
    assert _numba.equal_or_close(a, a.copy(), 1e-12)
    assert _numba.equal_or_close(a, a + [1e-13, 0, 0], 1e-12)
    assert not _numba.equal_or_close(a, a + [1e-9, 0, 0], 1e-12)
    assert not _numba.equal_or_close(np.array([np.nan]), np.array([np.nan]), 1.0)
    assert not _numba.equal_or_close(np.array([np.inf]), np.array([1e308]), 1.0)


def test_smallest_width_of_a_cell():
    cell = np.array([[10.0, 0, 0], [5.0, 8.0, 0], [0, 0, 12.0]])
    assert _numba.smallest_width(cell, np.array([True, True, True])) == pytest.approx(8.0)
    assert _numba.smallest_width(cell, np.array([True, False, True])) == pytest.approx(
        10.0 * 8.0 / np.hypot(5.0, 8.0))
    assert _numba.smallest_width(cell, np.array([False, False, False])) == np.inf


def test_energy_kernels_equal_the_operators(rng):
    q = rng.normal(size=(4, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p, inv_moments = rng.normal(size=(4, 4)), rng.uniform(0.1, 1.0, size=(4, 3))
    L = ops.body_angular_momentum(q, p)
    expected = 0.5 * np.sum(L * L * inv_moments)
    assert _numba.rotational_energy(q, p, inv_moments) == pytest.approx(expected, rel=1e-13)
    body, speed = _numba.largest_angular_speed(q, p, inv_moments)
    omega = np.linalg.norm(L * inv_moments, axis=1)
    assert (body, speed) == (int(np.argmax(omega)), pytest.approx(omega.max(), rel=1e-13))
