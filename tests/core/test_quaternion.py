import numpy as np
import pytest

from rigidmd.core import quaternion as quat
from rigidmd.systems import random_quaternions


@pytest.fixture
def qs(rng):
    return random_quaternions(200, rng)


def test_product_identity_associativity_and_norm(qs, rng):
    one = np.array([1.0, 0, 0, 0])
    np.testing.assert_allclose(quat.multiply(qs, one), qs, atol=1e-15)
    a, b, c = qs[:50], qs[50:100], qs[100:150]
    np.testing.assert_allclose(
        quat.multiply(quat.multiply(a, b), c), quat.multiply(a, quat.multiply(b, c)), atol=1e-14
    )
    np.testing.assert_allclose(np.linalg.norm(quat.multiply(a, b), axis=1), 1.0, atol=1e-14)
    # i j = k in the Hamilton convention.
    i, j = np.array([0.0, 1, 0, 0]), np.array([0.0, 0, 1, 0])
    np.testing.assert_array_equal(quat.multiply(i, j), [0, 0, 0, 1])


def test_rotation_matches_matrix_and_inverse(qs, rng):
    v = rng.normal(size=(200, 3))
    R = quat.to_matrix(qs)
    np.testing.assert_allclose(quat.rotate(qs, v), np.einsum("nij,nj->ni", R, v), atol=1e-13)
    np.testing.assert_allclose(quat.rotate_inverse(qs, quat.rotate(qs, v)), v, atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-13)
    # Rotation as q ⊗ (0, v) ⊗ q*.
    pure = np.concatenate([np.zeros((200, 1)), v], axis=1)
    sandwich = quat.multiply(quat.multiply(qs, pure), quat.conjugate(qs))
    np.testing.assert_allclose(sandwich[:, 1:], quat.rotate(qs, v), atol=1e-13)


def test_from_matrix_round_trip_all_angles(qs):
    # Include half-turns, where the trace pivot alone would fail.
    half_turns = np.array([[0.0, 1, 0, 0], [0.0, 0, 1, 0], [0.0, 0, 0, 1],
                           [0.0, 1, 1, 0] / np.sqrt(2), [1e-9, 0, 0, 1]])
    q = quat.normalize(np.concatenate([qs, half_turns]))
    back = quat.from_matrix(quat.to_matrix(q))
    # Same rotation: q and -q are equivalent.
    sign = np.sign(np.einsum("ij,ij->i", q, back))
    np.testing.assert_allclose(back * sign[:, None], q, atol=1e-12)
    assert np.all(back[:, 0] >= 0)


def test_no_squish_permutations_are_right_products(qs):
    basis = np.eye(4)[1:]
    for perm, unit in zip((quat.p1, quat.p2, quat.p3), basis, strict=True):
        np.testing.assert_array_equal(perm(qs), quat.multiply(qs, unit))
        np.testing.assert_allclose(np.einsum("ij,ij->i", perm(qs), qs), 0.0, atol=1e-15)


def test_vector_product_inverse(qs, rng):
    v = rng.normal(size=(200, 3))
    np.testing.assert_allclose(
        quat.conjugate_vector_product(qs, quat.vector_product(qs, v)), v, atol=1e-13
    )
