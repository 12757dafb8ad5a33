r"""The operators a rigid-body time step is made of: the readable reference path.

Each function updates a :class:`~rigidmd.state.RigidState` in place (or maps
between the state and atom arrays), vectorised over bodies with NumPy.  The
NO_SQUISH step of :class:`~rigidmd.dynamics.RigidVerlet` is

.. code-block:: text

    translational_kick(dt/2); drift(dt); rotational_kick(dt/2);
    free_rotor(dt); forces; translational_kick(dt/2); rotational_kick(dt/2)

(Miller et al., J. Chem. Phys. 116, 8649 (2002); LAMMPS ``fix rigid/nve``).
:mod:`rigidmd._numba` fuses the same operations into two compiled loops.

Units: lengths Å, masses amu, time ASE units, forces eV/Å, torques eV.
"""

import numpy as np

from rigidmd import quaternion as quat

__all__ = [
    "translational_kick",
    "drift",
    "rotational_kick",
    "no_squish_rotate",
    "free_rotor",
    "body_angular_momentum",
    "conjugate_momentum",
    "angular_velocity",
    "place_atoms",
    "reduce_forces",
    "atom_velocities",
]

_PERMUTATIONS = (quat.p1, quat.p2, quat.p3)


def translational_kick(state, F, f, M, m, h):
    r"""Centre-of-mass and free-atom kick.

    :math:`V \mathrel{+}= h F/M`, :math:`v \mathrel{+}= h f/m`.

    Parameters
    ----------
    state : RigidState
    F : numpy.ndarray, shape (n_bodies, 3)
        Total force on each body (eV/Å).
    f : numpy.ndarray, shape (n_free, 3)
        Forces on the free atoms (eV/Å).
    M : numpy.ndarray, shape (n_bodies,)
        Body masses (amu).
    m : numpy.ndarray, shape (n_free,)
        Free-atom masses (amu).
    h : float
        Time (ASE units).
    """
    state.V += h * F / M[:, None]
    state.v += h * f / m[:, None]


def drift(state, h):
    r"""Move centres of mass and free atoms.

    :math:`X \mathrel{+}= h V`, :math:`x \mathrel{+}= h v`.
    """
    state.X += h * state.V
    state.x += h * state.v


def rotational_kick(state, tau, h):
    r"""Kick the angular momentum by a lab torque for a time ``h``.

    .. math:: p \mathrel{+}= 2h\; q \otimes (0, R(q)^\mathsf{T} \tau)

    which is :math:`L_b \mathrel{+}= h\, R(q)^\mathsf{T}\tau` in the NO_SQUISH
    momentum :math:`p = 2\, q \otimes (0, L_b)`.

    Parameters
    ----------
    state : RigidState
    tau : numpy.ndarray, shape (n_bodies, 3)
        Lab-frame torques about the centres of mass (eV).
    h : float
    """
    state.p += 2.0 * h * quat.vector_product(state.q, quat.rotate_inverse(state.q, tau))


def no_squish_rotate(q, p, moments, k, h):
    r"""Exact free rotation about body axis ``k`` for a time ``h`` (in place).

    .. math::
        \phi = \frac{p \cdot P_k q}{4 I_k},\quad
        q \leftarrow \cos(\phi h)\, q + \sin(\phi h)\, P_k q,\quad
        p \leftarrow \cos(\phi h)\, p + \sin(\phi h)\, P_k p

    with :math:`\phi = 0` where :math:`I_k = 0`.

    Parameters
    ----------
    q, p : numpy.ndarray, shape (n_bodies, 4)
    moments : numpy.ndarray, shape (n_bodies, 3)
        Principal moments (amu Å²).
    k : int
        Body axis, 0, 1 or 2 (:math:`P_1, P_2, P_3`).
    h : float
    """
    perm = _PERMUTATIONS[k]
    kq = perm(q)
    kp = perm(p)
    inertia = moments[:, k]
    safe = np.where(inertia > 0, inertia, 1.0)
    phi = np.where(inertia > 0, np.einsum("ij,ij->i", p, kq) / (4.0 * safe), 0.0)
    c = np.cos(phi * h)[:, None]
    s = np.sin(phi * h)[:, None]
    q *= c
    q += s * kq
    p *= c
    p += s * kp


def free_rotor(state, moments, h):
    r"""NO_SQUISH symmetric splitting of a free rotation over ``h``.

    :math:`R_3(h/2)\, R_2(h/2)\, R_1(h)\, R_2(h/2)\, R_3(h/2)`, applied in that
    order; no renormalisation (each sub-step is an exact rotation).
    """
    for k, scale in ((2, 0.5), (1, 0.5), (0, 1.0), (1, 0.5), (2, 0.5)):
        no_squish_rotate(state.q, state.p, moments, k, scale * h)


def body_angular_momentum(q, p):
    r"""Body-frame angular momentum :math:`L_b = \tfrac12\,\mathrm{vec}(q^* \otimes p)`.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        amu Å² per ASE time unit.
    """
    return 0.5 * quat.conjugate_vector_product(q, p)


def conjugate_momentum(q, L_body):
    r"""NO_SQUISH momentum :math:`p = 2\, q \otimes (0, L_b)`, shape (n_bodies, 4)."""
    return 2.0 * quat.vector_product(q, L_body)


def angular_velocity(q, p, moments):
    r"""Lab-frame angular velocity :math:`\omega = R(q)\,(L_b / I)`.

    Components about an axis with :math:`I_k = 0` are 0.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        rad per ASE time unit.
    """
    L_body = body_angular_momentum(q, p)
    safe = np.where(moments > 0, moments, 1.0)
    omega_body = np.where(moments > 0, L_body / safe, 0.0)
    return quat.rotate(q, omega_body)


def place_atoms(state, geom):
    r"""Lab displacements and positions of the body atoms.

    :math:`r_i = R(q_b)\, d_i`, :math:`x_i = X_b + r_i`.

    Parameters
    ----------
    state : RigidState
    geom : rigidmd.bodies.BodyGeometry

    Returns
    -------
    r, x : numpy.ndarray, shape (n_body_atoms, 3)
        In ``geom.order``.
    """
    r = quat.rotate(state.q[geom.atom_body], geom.body_coordinates)
    return r, state.X[geom.atom_body] + r


def reduce_forces(forces, r, geom):
    r"""Body forces and lab torques about the centres of mass.

    :math:`F_b = \sum_{i\in b} f_i`, :math:`\tau_b = \sum_{i \in b} r_i \times f_i`.

    Parameters
    ----------
    forces : numpy.ndarray, shape (n_atoms, 3)
        Atom forces (eV/Å), in atom order.
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements from :func:`place_atoms`.
    geom : rigidmd.bodies.BodyGeometry

    Returns
    -------
    F : numpy.ndarray, shape (n_bodies, 3)
    tau : numpy.ndarray, shape (n_bodies, 3)
    """
    if geom.n_bodies == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    f = forces[geom.order]
    return (
        np.add.reduceat(f, geom.starts, axis=0),
        np.add.reduceat(np.cross(r, f), geom.starts, axis=0),
    )


def atom_velocities(state, r, geom):
    r"""Rigid velocities of the body atoms, :math:`v_i = V_b + \omega_b \times r_i`.

    Returns
    -------
    numpy.ndarray, shape (n_body_atoms, 3)
        In ``geom.order``.
    """
    omega = angular_velocity(state.q, state.p, geom.moments)
    b = geom.atom_body
    return state.V[b] + np.cross(omega[b], r)


def rigid_projection(momenta, r, q, geom):
    r"""Project atom momenta of the bodies onto rigid-body motion.

    :math:`V = \sum_i p_i / M`, :math:`L = \sum_i r_i \times p_i`,
    :math:`L_b = R(q)^\mathsf{T} L` with the components about zero-moment axes
    (the axis of a linear body) set to 0.

    Parameters
    ----------
    momenta : numpy.ndarray, shape (n_body_atoms, 3)
        Atom momenta in ``geom.order`` (amu Å / ASE time).
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements from the centres of mass (Å), in ``geom.order``.
    q : numpy.ndarray, shape (n_bodies, 4)
    geom : rigidmd.bodies.BodyGeometry

    Returns
    -------
    V : numpy.ndarray, shape (n_bodies, 3)
    L_body : numpy.ndarray, shape (n_bodies, 3)
    """
    if geom.n_bodies == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    V = np.add.reduceat(momenta, geom.starts, axis=0) / geom.mass[:, None]
    L = np.add.reduceat(np.cross(r, momenta), geom.starts, axis=0)
    L_body = quat.rotate_inverse(q, L)
    return V, np.where(geom.moments > 0, L_body, 0.0)


def fit_bodies(x, geom):
    r"""Best rigid placement of each body's reference onto given positions.

    Minimises :math:`\sum_i m_i |X + R d_i - x_i|^2` over :math:`X` and
    proper rotations :math:`R` (Kabsch): :math:`X` is the centre of mass of
    :math:`x`, and with :math:`B = \sum_i m_i (x_i - X) d_i^\mathsf{T} = U S
    W^\mathsf{T}`, :math:`R = U\,\mathrm{diag}(1, 1, \det(U W^\mathsf{T}))\,W^\mathsf{T}`.

    Parameters
    ----------
    x : numpy.ndarray, shape (n_body_atoms, 3)
        Unwrapped positions (Å) in ``geom.order``.
    geom : rigidmd.bodies.BodyGeometry

    Returns
    -------
    X : numpy.ndarray, shape (n_bodies, 3)
    q : numpy.ndarray, shape (n_bodies, 4)
    residual : numpy.ndarray, shape (n_bodies,)
        Largest distance of an atom from its fitted place (Å).
    """
    m, b, d = geom.atom_masses, geom.atom_body, geom.body_coordinates
    X = np.add.reduceat(m[:, None] * x, geom.starts, axis=0) / geom.mass[:, None]
    r = x - X[b]
    B = np.add.reduceat(m[:, None, None] * r[:, :, None] * d[:, None, :], geom.starts, axis=0)
    U, _, Wt = np.linalg.svd(B)
    sign = np.sign(np.linalg.det(U @ Wt))
    sign[sign == 0] = 1.0
    U[:, :, 2] *= sign[:, None]
    q = quat.from_matrix(U @ Wt)
    misfit = np.linalg.norm(quat.rotate(q[b], d) - r, axis=1)
    residual = np.maximum.reduceat(misfit, geom.starts)
    return X, q, residual


def uniform_rescale(new, old, geom, rtol=1e-12):
    r"""Which bodies' atom momenta were scaled by one factor, and the factor.

    For each body, :math:`\lambda = \sum_i p'_i \cdot p_i / \sum_i |p_i|^2`;
    the body counts as uniformly rescaled when
    :math:`\sum_i |p'_i - \lambda p_i|^2 \le \mathrm{rtol}^2 \sum_i |p_i|^2`
    (a flip of all velocities has :math:`\lambda = -1`).

    Parameters
    ----------
    new, old : numpy.ndarray, shape (n_body_atoms, 3)
        Atom momenta in ``geom.order``.
    geom : rigidmd.bodies.BodyGeometry
    rtol : float

    Returns
    -------
    scale : numpy.ndarray, shape (n_bodies,)
    uniform : numpy.ndarray of bool, shape (n_bodies,)
    """
    if geom.n_bodies == 0:
        return np.zeros(0), np.zeros(0, dtype=bool)
    dot = np.add.reduceat(np.einsum("ij,ij->i", new, old), geom.starts)
    norm2 = np.add.reduceat(np.einsum("ij,ij->i", old, old), geom.starts)
    scale = np.where(norm2 > 0, dot / np.where(norm2 > 0, norm2, 1.0), 0.0)
    diff = new - scale[geom.atom_body, None] * old
    misfit = np.add.reduceat(np.einsum("ij,ij->i", diff, diff), geom.starts)
    return scale, misfit <= rtol**2 * norm2
