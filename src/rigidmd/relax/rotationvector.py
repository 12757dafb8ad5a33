r"""Rotation vectors: the orientation rows of :class:`rigidmd.relax.filter.RigidFilter`.

:func:`rotation_quaternion` maps a rotation vector to its unit quaternion and
:func:`right_jacobian_transpose` carries a body-frame torque into the
gradient of the rotation vector's row.
"""

import numpy as np

__all__ = ["rotation_quaternion", "right_jacobian_transpose", "cross"]


def rotation_quaternion(phi):
    r"""Unit quaternion of a rotation vector, :math:`\exp(\varphi)`.

    :math:`(\cos\tfrac{\theta}2, \hat\varphi\sin\tfrac{\theta}2)`, :math:`\theta = |\varphi|`.

    Parameters
    ----------
    phi : numpy.ndarray, shape (..., 3)
        Rotation vectors (rad).

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    angle = np.linalg.norm(phi, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(θ/2)/θ, with its series below 1e-4 rad.
    small = angle < 1e-4
    factor = np.where(small, 0.5 - angle**2 / 48.0,
                      np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), factor * phi], axis=-1)


def right_jacobian_transpose(phi, v):
    r""":math:`J_r(\varphi)^\mathsf{T} v` for the rotation vector :math:`\varphi`.

    :math:`\exp(\varphi + \delta) = \exp(\varphi)\exp(J_r(\varphi)\,\delta) + O(\delta^2)`,
    :math:`J_r = 1 - a[\varphi]_\times + b[\varphi]_\times^2`, so
    :math:`J_r^\mathsf{T} v = v + a\,\varphi\times v + b\,\varphi\times(\varphi\times v)`
    with :math:`a = (1-\cos\theta)/\theta^2`, :math:`b = (\theta-\sin\theta)/\theta^3`,
    :math:`\theta = |\varphi|` (series below 1e-3 rad).

    Parameters
    ----------
    phi, v : numpy.ndarray, shape (n, 3)

    Returns
    -------
    numpy.ndarray, shape (n, 3)
    """
    t = np.linalg.norm(phi, axis=-1, keepdims=True)
    small = t < 1e-3
    ts = np.where(small, 1.0, t)
    a = np.where(small, 0.5 - t**2 / 24.0, (1.0 - np.cos(ts)) / ts**2)
    b = np.where(small, 1.0 / 6.0 - t**2 / 120.0, (ts - np.sin(ts)) / (ts * ts * ts))
    c = cross(phi, v)
    return v + a * c + b * cross(phi, c)


def cross(u, v):
    """Row-wise cross product of (n, 3) arrays (numpy's ``cross`` without its axis handling)."""
    out = np.empty(np.broadcast_shapes(u.shape, v.shape))
    out[..., 0] = u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1]
    out[..., 1] = u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2]
    out[..., 2] = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    return out
