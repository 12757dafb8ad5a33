"""Rotation vectors for the relaxation's coordinates (rigidmd.relax.rotationvector)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rigidmd.core import quaternion as quat
from rigidmd.relax.rotationvector import cross, right_jacobian_transpose, rotation_quaternion


def test_the_quaternion_of_a_rotation_vector(rng):
    phi = rng.normal(size=(6, 3))
    phi[0] = 0.0
    phi[1] *= 1e-6  # the series
    q = rotation_quaternion(phi)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    xyzw = Rotation.from_rotvec(phi).as_quat()
    expected = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    expected *= np.sign(expected[:, :1])
    assert np.allclose(q, expected, atol=1e-15)
    assert np.array_equal(rotation_quaternion(np.zeros(3)), [1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("scale", [1.0, 1e-4])
def test_the_right_jacobian_is_the_derivative_of_exp(rng, scale):
    """exp(φ + εδ) = exp(φ) exp(ε J_r δ) + O(ε²): J_r^T v by central differences of
    v·log(exp(-φ)exp(φ + εδ))/ε over δ the unit vectors (error ~ε² = 1e-12)."""
    phi, v = scale * rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    eps = 1e-6
    jacobian = np.empty((3, 3, 3))
    for k in range(3):
        delta = np.zeros(3)
        delta[k] = eps
        plus = quat.multiply(quat.conjugate(rotation_quaternion(phi)),
                             rotation_quaternion(phi + delta))
        minus = quat.multiply(quat.conjugate(rotation_quaternion(phi)),
                              rotation_quaternion(phi - delta))
        jacobian[:, :, k] = (Rotation.from_quat(plus[:, [1, 2, 3, 0]]).as_rotvec()
                             - Rotation.from_quat(minus[:, [1, 2, 3, 0]]).as_rotvec()) / (2 * eps)
    expected = np.einsum("nik,ni->nk", jacobian, v)
    assert np.allclose(right_jacobian_transpose(phi, v), expected, atol=1e-8)


def test_cross_is_numpys(rng):
    u, v = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    assert np.allclose(cross(u, v), np.cross(u, v), rtol=1e-15, atol=1e-15)
    assert cross(u[:1], v).shape == (5, 3)
