r"""Vectorised quaternion algebra.

Every function works on arrays of shape ``(..., 4)`` (quaternions) or
``(..., 3)`` (vectors) and broadcasts over the leading axes.  Quaternions are
stored scalar first, :math:`q = (w, x, y, z)`, and unit quaternions represent
rotations from the body frame to the laboratory frame:

.. math:: \mathbf{r}_\mathrm{lab} = R(q)\, \mathbf{r}_\mathrm{body}
          = \mathrm{vec}\left(q \otimes (0, \mathbf{r}_\mathrm{body})
            \otimes q^*\right).

The permutations :func:`p1`, :func:`p2`, :func:`p3` are those of the NO_SQUISH
free-rotor splitting (Miller et al., J. Chem. Phys. 116, 8649 (2002)).
"""

import numpy as np

__all__ = [
    "multiply",
    "conjugate",
    "normalize",
    "rotate",
    "rotate_inverse",
    "to_matrix",
    "from_matrix",
    "vector_product",
    "conjugate_vector_product",
    "p1",
    "p2",
    "p3",
]


def multiply(q, r):
    r"""Hamilton product :math:`q \otimes r`.

    .. math::
        q \otimes r = (q_w r_w - \mathbf{q}\cdot\mathbf{r},\;
                       q_w \mathbf{r} + r_w \mathbf{q}
                       + \mathbf{q}\times\mathbf{r})

    Parameters
    ----------
    q, r : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    r = np.asarray(r, dtype=float)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    rw, rx, ry, rz = np.moveaxis(r, -1, 0)
    return np.stack(
        [
            qw * rw - qx * rx - qy * ry - qz * rz,
            qw * rx + qx * rw + qy * rz - qz * ry,
            qw * ry - qx * rz + qy * rw + qz * rx,
            qw * rz + qx * ry - qy * rx + qz * rw,
        ],
        axis=-1,
    )


def conjugate(q):
    r"""Conjugate :math:`q^* = (w, -x, -y, -z)`.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.array(q, dtype=float)
    q[..., 1:] *= -1.0
    return q


def normalize(q):
    r"""Unit quaternion :math:`q / |q|`.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def vector_product(q, v):
    r"""Product of a quaternion with a pure quaternion, :math:`q \otimes (0, v)`.

    With :math:`v` a body-frame torque this is the NO_SQUISH momentum kick
    direction; with :math:`v = L_b` it gives :math:`p = 2\, q \otimes (0, L_b)`
    up to the factor 2.

    Parameters
    ----------
    q : array_like, shape (..., 4)
    v : array_like, shape (..., 3)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    v = np.asarray(v, dtype=float)
    zero = np.zeros(v.shape[:-1] + (1,))
    return multiply(q, np.concatenate([zero, v], axis=-1))


def conjugate_vector_product(q, p):
    r"""Vector part of :math:`q^* \otimes p`.

    The inverse of :func:`vector_product` for unit ``q``:
    ``conjugate_vector_product(q, vector_product(q, v)) == v``.  NO_SQUISH
    recovers the body angular momentum as
    :math:`L_b = \tfrac12\,\mathrm{vec}(q^* \otimes p)`.

    Parameters
    ----------
    q, p : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 3)
    """
    return multiply(conjugate(q), p)[..., 1:]


def to_matrix(q):
    r"""Rotation matrix :math:`R(q)` of a unit quaternion (body to lab).

    .. math::
        R = \begin{pmatrix}
        1-2(y^2+z^2) & 2(xy-wz) & 2(xz+wy)\\
        2(xy+wz) & 1-2(x^2+z^2) & 2(yz-wx)\\
        2(xz-wy) & 2(yz+wx) & 1-2(x^2+y^2)
        \end{pmatrix}

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Unit quaternions.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def from_matrix(m):
    r"""Unit quaternion of a proper rotation matrix, with :math:`w \ge 0`.

    Uses the largest of :math:`4w^2, 4x^2, 4y^2, 4z^2` (from the trace and
    the diagonal) as pivot, which is accurate for every rotation angle.

    Parameters
    ----------
    m : array_like, shape (..., 3, 3)
        Rotation matrices (orthogonal, determinant +1).

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    m = np.asarray(m, dtype=float)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # 4 * (w², x², y², z²) from the diagonal.
    sq = np.stack(
        [
            1 + m00 + m11 + m22,
            1 + m00 - m11 - m22,
            1 - m00 + m11 - m22,
            1 - m00 - m11 + m22,
        ],
        axis=-1,
    )
    # Off-diagonal combinations: 4 * (pairwise products of components).
    wx = m[..., 2, 1] - m[..., 1, 2]
    wy = m[..., 0, 2] - m[..., 2, 0]
    wz = m[..., 1, 0] - m[..., 0, 1]
    xy = m[..., 0, 1] + m[..., 1, 0]
    xz = m[..., 0, 2] + m[..., 2, 0]
    yz = m[..., 1, 2] + m[..., 2, 1]
    candidates = np.stack(
        [
            np.stack([sq[..., 0], wx, wy, wz], axis=-1),
            np.stack([wx, sq[..., 1], xy, xz], axis=-1),
            np.stack([wy, xy, sq[..., 2], yz], axis=-1),
            np.stack([wz, xz, yz, sq[..., 3]], axis=-1),
        ],
        axis=-2,
    )
    pivot = np.argmax(sq, axis=-1)
    q = np.take_along_axis(candidates, pivot[..., None, None], axis=-2)[..., 0, :]
    q = normalize(q)
    return np.where(q[..., :1] < 0, -q, q)


def rotate(q, v):
    r"""Rotate body-frame vectors into the lab frame, :math:`R(q)\,v`.

    .. math:: R(q) v = v + 2 w (\mathbf{u}\times v)
                       + 2\,\mathbf{u}\times(\mathbf{u}\times v),
              \quad q = (w, \mathbf{u})

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Unit quaternions.
    v : array_like, shape (..., 3)

    Returns
    -------
    numpy.ndarray, shape (..., 3)
    """
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + q[..., :1] * t + np.cross(u, t)


def rotate_inverse(q, v):
    r"""Rotate lab-frame vectors into the body frame, :math:`R(q)^\mathsf{T} v`.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Unit quaternions.
    v : array_like, shape (..., 3)

    Returns
    -------
    numpy.ndarray, shape (..., 3)
    """
    return rotate(conjugate(q), v)


def p1(q):
    r"""NO_SQUISH permutation :math:`P_1 q = (-q_1, q_0, q_3, -q_2)`.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    return np.stack([-q[..., 1], q[..., 0], q[..., 3], -q[..., 2]], axis=-1)


def p2(q):
    r"""NO_SQUISH permutation :math:`P_2 q = (-q_2, -q_3, q_0, q_1)`.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    return np.stack([-q[..., 2], -q[..., 3], q[..., 0], q[..., 1]], axis=-1)


def p3(q):
    r"""NO_SQUISH permutation :math:`P_3 q = (-q_3, q_2, -q_1, q_0)`.

    Parameters
    ----------
    q : array_like, shape (..., 4)

    Returns
    -------
    numpy.ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=float)
    return np.stack([-q[..., 3], q[..., 2], -q[..., 1], q[..., 0]], axis=-1)
