r"""The operators a rigid-body time step is made of: the readable reference path.

Each function updates a :class:`~rigidmd.core.state.RigidState` in place (or maps
between the state and atom arrays), vectorised over bodies with NumPy.  The
NO_SQUISH step of :class:`~rigidmd.md.verlet.RigidVerlet` is

.. code-block:: text

    translational_kick(dt/2); drift(dt); rotational_kick(dt/2);
    free_rotor(dt); forces; translational_kick(dt/2); rotational_kick(dt/2)

(Miller et al., J. Chem. Phys. 116, 8649 (2002); LAMMPS ``fix rigid/nve``).
:mod:`rigidmd.core._numba` fuses the same operations into two compiled loops.

Units: lengths Å, masses amu, time ASE units, forces eV/Å, torques eV.
"""

import numpy as np

from rigidmd.core import quaternion as quat

__all__ = [
    "translational_kick",
    "remove_centre_velocity",
    "drift",
    "rotational_kick",
    "no_squish_rotate",
    "free_rotor",
    "body_angular_momentum",
    "conjugate_momentum",
    "lab_angular_momentum",
    "momentum_from_lab",
    "angular_velocity",
    "lab_from_omega",
    "place_atoms",
    "reduce_forces",
    "atom_velocities",
    "rigid_projection",
    "fit_bodies",
    "uniform_rescale",
    "euler_acceleration",
    "richardson_rotate",
    "rozmanov_kusalik_rotate",
    "ConvergenceError",
    "pcdm_predict",
    "pcdm_correct",
    "exadem_push_to_quaternion",
    "exadem_angular_acceleration",
    "intramolecular_virial",
    "affine_drift",
]

_PERMUTATIONS = (quat.p1, quat.p2, quat.p3)


def translational_kick(state, F, f, model, h):
    r"""Centre-of-mass and free-atom kick.

    :math:`V \mathrel{+}= h F/M`, :math:`v \mathrel{+}= h f/m`.

    Parameters
    ----------
    state : RigidState
    F : numpy.ndarray, shape (n_bodies, 3)
        Total force on each body (eV/Å).
    f : numpy.ndarray, shape (n_free, 3)
        Forces on the free atoms (eV/Å).
    model : rigidmd.core.model.BodyModel
        Body and free-atom masses (amu).
    h : float
        Time (ASE units).
    """
    state.V += h * F / model.mass[:, None]
    state.v += h * f / model.free_masses[:, None]


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


def no_squish_rotate(q, p, inv_moments, k, h):
    r"""Exact free rotation about body axis ``k`` for a time ``h`` (in place).

    .. math::
        \phi = \frac{p \cdot P_k q}{4 I_k},\quad
        q \leftarrow \cos(\phi h)\, q + \sin(\phi h)\, P_k q,\quad
        p \leftarrow \cos(\phi h)\, p + \sin(\phi h)\, P_k p

    with :math:`\phi = 0` where :math:`I_k = 0`.

    Parameters
    ----------
    q, p : numpy.ndarray, shape (n_bodies, 4)
    inv_moments : numpy.ndarray, shape (n_bodies, 3)
        :math:`1/I_k`, 0 about a zero-moment axis (amu⁻¹ Å⁻²).
    k : int
        Body axis, 0, 1 or 2 (:math:`P_1, P_2, P_3`).
    h : float
    """
    perm = _PERMUTATIONS[k]
    kq = perm(q)
    kp = perm(p)
    phi = np.einsum("ij,ij->i", p, kq) * (0.25 * inv_moments[:, k])
    c = np.cos(phi * h)[:, None]
    s = np.sin(phi * h)[:, None]
    q *= c
    q += s * kq
    p *= c
    p += s * kp


def free_rotor(state, inv_moments, h):
    r"""NO_SQUISH symmetric splitting of a free rotation over ``h``.

    :math:`R_3(h/2)\, R_2(h/2)\, R_1(h)\, R_2(h/2)\, R_3(h/2)`, applied in that
    order; no renormalisation (each sub-step is an exact rotation).
    """
    for k, scale in ((2, 0.5), (1, 0.5), (0, 1.0), (1, 0.5), (2, 0.5)):
        no_squish_rotate(state.q, state.p, inv_moments, k, scale * h)
    state.touched(positions=True, momenta=True)  # written in place


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


def lab_angular_momentum(q, p):
    r"""Lab angular momentum :math:`L = R(q)\, L_b` from the NO_SQUISH momentum.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        amu Å² per ASE time unit.
    """
    return quat.rotate(q, body_angular_momentum(q, p))


def momentum_from_lab(q, L):
    r"""NO_SQUISH momentum :math:`p = 2\, q \otimes (0, R(q)^\mathsf{T} L)` of a lab ``L``."""
    return conjugate_momentum(q, quat.rotate_inverse(q, L))


def angular_velocity(q, L_body, inv_moments):
    r"""Lab-frame angular velocity :math:`\omega = R(q)\,(L_b / I)`.

    The one route from angular momentum to angular velocity: callers holding
    the NO_SQUISH momentum pass :func:`body_angular_momentum`, callers
    holding a lab :math:`L` pass :math:`R(q)^\mathsf{T} L`.  Components about
    an axis with :math:`I_k = 0` are 0.

    Parameters
    ----------
    q : numpy.ndarray, shape (n_bodies, 4)
    L_body : numpy.ndarray, shape (n_bodies, 3)
        Body-frame angular momenta (amu Å² per ASE time unit).
    inv_moments : numpy.ndarray, shape (n_bodies, 3)
        :math:`1/I_k`, 0 about a zero-moment axis.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        rad per ASE time unit.
    """
    return quat.rotate(q, inv_moments * L_body)


def place_atoms(state, model):
    r"""Lab displacements and positions of the body atoms.

    :math:`r_i = R(q_b)\, d_i`, :math:`x_i = X_b + r_i`.

    Parameters
    ----------
    state : RigidState
    model : rigidmd.core.model.BodyModel

    Returns
    -------
    r, x : numpy.ndarray, shape (n_body_atoms, 3)
        In ``model.order``.
    """
    r = quat.rotate(state.q[model.atom_body], model.body_coordinates)
    return r, state.X[model.atom_body] + r


def reduce_forces(forces, r, model):
    r"""Body forces and lab torques about the centres of mass.

    :math:`F_b = \sum_{i\in b} f_i`, :math:`\tau_b = \sum_{i \in b} r_i \times f_i`.

    Parameters
    ----------
    forces : numpy.ndarray, shape (n_atoms, 3)
        Atom forces (eV/Å), in atom order.
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements from :func:`place_atoms`.
    model : rigidmd.core.model.BodyModel

    Returns
    -------
    F : numpy.ndarray, shape (n_bodies, 3)
    tau : numpy.ndarray, shape (n_bodies, 3)
    """
    if model.n_bodies == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    f = forces[model.order]
    return (
        np.add.reduceat(f, model.starts, axis=0),
        np.add.reduceat(np.cross(r, f), model.starts, axis=0),
    )


def atom_velocities(state, r, model):
    r"""Rigid velocities of the body atoms, :math:`v_i = V_b + \omega_b \times r_i`.

    Returns
    -------
    numpy.ndarray, shape (n_body_atoms, 3)
        In ``model.order``.
    """
    omega = angular_velocity(state.q, body_angular_momentum(state.q, state.p),
                             model.inv_moments)
    b = model.atom_body
    return state.V[b] + np.cross(omega[b], r)


def rigid_projection(momenta, r, q, model):
    r"""Project atom momenta of the bodies onto rigid-body motion.

    :math:`V = \sum_i p_i / M`, :math:`L = \sum_i r_i \times p_i`,
    :math:`L_b = R(q)^\mathsf{T} L` with the components about zero-moment axes
    (the axis of a linear body) set to 0.

    Parameters
    ----------
    momenta : numpy.ndarray, shape (n_body_atoms, 3)
        Atom momenta in ``model.order`` (amu Å / ASE time).
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements from the centres of mass (Å), in ``model.order``.
    q : numpy.ndarray, shape (n_bodies, 4)
    geom : rigidmd.core.model.BodyModel

    Returns
    -------
    V : numpy.ndarray, shape (n_bodies, 3)
    L_body : numpy.ndarray, shape (n_bodies, 3)
    """
    if model.n_bodies == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    V = np.add.reduceat(momenta, model.starts, axis=0) / model.mass[:, None]
    L = np.add.reduceat(np.cross(r, momenta), model.starts, axis=0)
    L_body = quat.rotate_inverse(q, L)
    return V, np.where(model.moments > 0, L_body, 0.0)


def fit_bodies(x, model):
    r"""Best rigid placement of each body's reference onto given positions.

    Minimises :math:`\sum_i m_i |X + R d_i - x_i|^2` over :math:`X` and
    proper rotations :math:`R` (Kabsch): :math:`X` is the centre of mass of
    :math:`x`, and with :math:`B = \sum_i m_i (x_i - X) d_i^\mathsf{T} = U S
    W^\mathsf{T}`, :math:`R = U\,\mathrm{diag}(1, 1, \det(U W^\mathsf{T}))\,W^\mathsf{T}`.

    Parameters
    ----------
    x : numpy.ndarray, shape (n_body_atoms, 3)
        Unwrapped positions (Å) in ``model.order``.
    geom : rigidmd.core.model.BodyModel

    Returns
    -------
    X : numpy.ndarray, shape (n_bodies, 3)
    q : numpy.ndarray, shape (n_bodies, 4)
    residual : numpy.ndarray, shape (n_bodies,)
        Largest distance of an atom from its fitted place (Å).
    """
    m, b, d = model.atom_masses, model.atom_body, model.body_coordinates
    X = np.add.reduceat(m[:, None] * x, model.starts, axis=0) / model.mass[:, None]
    r = x - X[b]
    B = np.add.reduceat(m[:, None, None] * r[:, :, None] * d[:, None, :], model.starts, axis=0)
    U, _, Wt = np.linalg.svd(B)
    sign = np.sign(np.linalg.det(U @ Wt))
    sign[sign == 0] = 1.0
    U[:, :, 2] *= sign[:, None]
    q = quat.from_matrix(U @ Wt)
    misfit = np.linalg.norm(quat.rotate(q[b], d) - r, axis=1)
    residual = np.maximum.reduceat(misfit, model.starts)
    return X, q, residual


def uniform_rescale(new, old, model, rtol=1e-12):
    r"""Which bodies' atom momenta were scaled by one factor, and the factor.

    For each body, :math:`\lambda = \sum_i p'_i \cdot p_i / \sum_i |p_i|^2`;
    the body counts as uniformly rescaled when
    :math:`\sum_i |p'_i - \lambda p_i|^2 \le \mathrm{rtol}^2 \sum_i |p_i|^2`
    (a flip of all velocities has :math:`\lambda = -1`).

    Parameters
    ----------
    new, old : numpy.ndarray, shape (n_body_atoms, 3)
        Atom momenta in ``model.order``.
    geom : rigidmd.core.model.BodyModel
    rtol : float

    Returns
    -------
    scale : numpy.ndarray, shape (n_bodies,)
    uniform : numpy.ndarray of bool, shape (n_bodies,)
    """
    if model.n_bodies == 0:
        return np.zeros(0), np.zeros(0, dtype=bool)
    dot = np.add.reduceat(np.einsum("ij,ij->i", new, old), model.starts)
    norm2 = np.add.reduceat(np.einsum("ij,ij->i", old, old), model.starts)
    scale = np.where(norm2 > 0, dot / np.where(norm2 > 0, norm2, 1.0), 0.0)
    diff = new - scale[model.atom_body, None] * old
    misfit = np.add.reduceat(np.einsum("ij,ij->i", diff, diff), model.starts)
    return scale, misfit <= rtol**2 * norm2


# ---------------------------------------------------------------- conversions
def lab_from_omega(q, omega, moments):
    r"""Lab angular momentum :math:`L = R\, I\, R^\mathsf{T} \omega` of a lab angular velocity.

    The inverse of :func:`angular_velocity` (for the exaDEM and PCDM
    operators, which carry :math:`\omega`).
    """
    return quat.rotate(q, moments * quat.rotate_inverse(q, omega))


def euler_acceleration(omega_body, torque_body, moments, inv_moments):
    r"""Body-frame angular acceleration from Euler's equations.

    .. math:: \dot\omega_{b} = I^{-1}\left(\tau_b - \omega_b \times I \omega_b\right)

    componentwise :math:`\dot\omega_i = (\tau_i - (I_k - I_j)\,\omega_j \omega_k) / I_i`
    for cyclic :math:`(i, j, k)`; 0 about a zero-moment axis.

    Parameters
    ----------
    omega_body, torque_body : numpy.ndarray, shape (n_bodies, 3)
    moments, inv_moments : numpy.ndarray, shape (n_bodies, 3)
        :math:`I_k` and :math:`1/I_k` (0 about a zero-moment axis).

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        rad per ASE time unit squared.
    """
    rhs = torque_body - np.cross(omega_body, moments * omega_body)
    return inv_moments * rhs


def _advance_quaternion(q, omega_lab, h):
    r""":math:`\mathrm{normalize}(q + h \cdot \tfrac12 (0, \omega) \otimes q)`, one Euler step."""
    w = np.concatenate([np.zeros(omega_lab.shape[:-1] + (1,)), omega_lab], axis=-1)
    return quat.normalize(q + 0.5 * h * quat.multiply(w, q))


def _exact_rotation(q, omega_lab, h):
    r"""Rotate ``q`` by the angle :math:`|\omega| h` about :math:`\hat\omega` (lab frame).

    :math:`(\cos(|\omega| h/2), \sin(|\omega| h/2)\,\hat\omega) \otimes q`.

    The identity where :math:`\omega = 0`.
    """
    norm = np.linalg.norm(omega_lab, axis=-1, keepdims=True)
    half = 0.5 * h * norm
    axis = np.divide(omega_lab, norm, out=np.zeros_like(omega_lab), where=norm > 0)
    dq = np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)
    return quat.multiply(dq, q)


# ---------------------------------------------------------------- Richardson
def richardson_rotate(state, inv_moments, h):
    r"""Richardson-iterated orientation update at fixed lab :math:`L` (LAMMPS ``fix rigid``).

    With :math:`\delta = h/2`, :math:`W(\omega, q) = (0, \omega) \otimes q` and
    :math:`\omega` from :math:`L, q`:

    .. math::
        q_\mathrm{full} = \mathrm{n}(q + \delta W(\omega, q)),\quad
        q_\frac12 = \mathrm{n}(q + \tfrac{\delta}{2} W(\omega, q)),\quad
        q_\frac12 \leftarrow \mathrm{n}(q_\frac12
            + \tfrac{\delta}{2} W(\omega_\frac12, q_\frac12)),\quad
        q \leftarrow \mathrm{n}(2 q_\frac12 - q_\mathrm{full})

    where :math:`\omega_\frac12` is computed from :math:`L` and :math:`q_\frac12`
    and :math:`\mathrm n` normalises.  The momentum ``p`` is rebuilt so that
    the lab :math:`L` is unchanged.
    """
    L = lab_angular_momentum(state.q, state.p)
    q = state.q
    omega = angular_velocity(q, quat.rotate_inverse(q, L), inv_moments)
    delta = 0.5 * h
    q_full = _advance_quaternion(q, omega, 2 * delta)
    q_half = _advance_quaternion(q, omega, delta)
    q_half = _advance_quaternion(
        q_half, angular_velocity(q_half, quat.rotate_inverse(q_half, L), inv_moments), delta)
    state.q = quat.normalize(2.0 * q_half - q_full)
    state.p = momentum_from_lab(state.q, L)


# ---------------------------------------------------------------- Rozmanov–Kusalik
class ConvergenceError(ValueError):
    """An iterative orientation update did not converge within its cap."""


def rozmanov_kusalik_rotate(state, torque, inv_moments, h, tol=1e-13, max_iter=100):
    r"""Rozmanov–Kusalik half kick and iterated orientation update over ``h``.

    Phys. Rev. E 81, 056706 (2010), sec. IV.A (RMPCDMD ``rigid_body_vv1``),
    with :math:`T` the lab torque at the start:

    1. :math:`L_b = R(q_0)^\mathsf{T} L`, :math:`T_b = R(q_0)^\mathsf{T} T`,
       :math:`\dot L_b = T_b - \omega_b \times L_b`;
    2. predictor :math:`\dot q = \tfrac12 q_0 \otimes (0, (L_b + \tfrac h2 \dot L_b)/I)`,
       :math:`q_\frac12 = \mathrm n(q_0 + \tfrac h2 \dot q)`;
    3. :math:`L_\frac12 = L + \tfrac h2 T`;
    4. repeat
       :math:`\dot q = \tfrac12 q_\frac12 \otimes (0, R(q_\frac12)^\mathsf{T} L_\frac12 / I)`,
       :math:`q_\frac12 = \mathrm n(q_0 + \tfrac h2 \dot q)` until no component of
       :math:`q_\frac12` moves by ``tol`` or more;
    5. :math:`q = \mathrm n(q_0 + h \dot q)`.

    Afterwards the state's lab angular momentum is :math:`L_\frac12`.

    Raises
    ------
    ConvergenceError
        After ``max_iter`` iterations, naming the worst body.
    """
    q0 = state.q
    inv = inv_moments
    L = lab_angular_momentum(q0, state.p)
    L_body = quat.rotate_inverse(q0, L)
    dL_body = quat.rotate_inverse(q0, torque) - np.cross(inv * L_body, L_body)
    qdot = 0.5 * quat.vector_product(q0, inv * (L_body + 0.5 * h * dL_body))
    q_half = quat.normalize(q0 + 0.5 * h * qdot)
    L_half = L + 0.5 * h * torque
    for _ in range(max_iter):
        qdot = 0.5 * quat.vector_product(q_half, inv * quat.rotate_inverse(q_half, L_half))
        new = quat.normalize(q0 + 0.5 * h * qdot)
        change = np.abs(new - q_half).max(axis=1) if len(new) else np.zeros(0)
        q_half = new
        if not np.any(change >= tol):
            break
    else:
        worst = int(np.argmax(change))
        raise ConvergenceError(
            f"rozmanov_kusalik: body {worst} did not converge in {max_iter} iterations "
            f"(last change {change[worst]:.3g} > tol {tol:.3g}); "
            "use a smaller time step or a larger max_iter"
        )
    state.q = quat.normalize(q0 + h * qdot)
    state.p = momentum_from_lab(state.q, L_half)


# ---------------------------------------------------------------- PCDM
def pcdm_predict(q0, omega0, torque0, moments, inv_moments, h):
    r"""PCDM predictor (Zhao & van Wachem, Acta Mech. 224, 3091 (2013)).

    .. math::
        \omega_{b0} = R(q_0)^\mathsf{T}\omega_0,\quad
        \dot\omega_{b0} = I^{-1}(\tau_{b0} - \omega_{b0}\times I\omega_{b0}),\quad
        \omega_{\frac14} = R(q_0)(\omega_{b0} + \tfrac14 \dot\omega_{b0} h),\quad
        q'_\frac12 = (\cos(|\omega_\frac14| h/4),
                     \sin(|\omega_\frac14| h/4)\,\hat\omega_\frac14)
                     \otimes q_0

    Returns
    -------
    q_half : numpy.ndarray, shape (n_bodies, 4)
        Predicted midpoint orientation, where the torque is to be evaluated.
    omega_body0, domega_body0 : numpy.ndarray, shape (n_bodies, 3)
        :math:`\omega_{b0}` and :math:`\dot\omega_{b0}`, for :func:`pcdm_correct`.
    """
    omega_body0 = quat.rotate_inverse(q0, omega0)
    domega_body0 = euler_acceleration(omega_body0, quat.rotate_inverse(q0, torque0), moments,
                                      inv_moments)
    omega_quarter = quat.rotate(q0, omega_body0 + 0.25 * h * domega_body0)
    return _exact_rotation(q0, omega_quarter, 0.5 * h), omega_body0, domega_body0


def pcdm_correct(q0, q_half, omega_body0, domega_body0, torque_half, moments, inv_moments, h):
    r"""PCDM corrector, with the torque evaluated at the predicted midpoint.

    .. math::
        \omega_{b\frac12} = \omega_{b0} + \tfrac12\dot\omega_{b0} h,\quad
        \dot\omega_{b\frac12} = I^{-1}(\tau_{b\frac12}
            - \omega_{b\frac12}\times I\omega_{b\frac12}),\\
        q_1 = (\cos(|\omega_\frac12| h/2), \sin(|\omega_\frac12| h/2)\,\hat\omega_\frac12)
              \otimes q_0,\quad \omega_\frac12 = R(q'_\frac12)\,\omega_{b\frac12},\quad
        \omega_1 = R(q_1)(\omega_{b0} + \dot\omega_{b\frac12} h)

    with :math:`\tau_{b\frac12} = R(q'_\frac12)^\mathsf{T} \tau(q'_\frac12)`.

    Returns
    -------
    q1 : numpy.ndarray, shape (n_bodies, 4)
    omega1 : numpy.ndarray, shape (n_bodies, 3)
        Lab angular velocity at the end of the step.
    """
    omega_body_half = omega_body0 + 0.5 * h * domega_body0
    domega_half = euler_acceleration(
        omega_body_half, quat.rotate_inverse(q_half, torque_half), moments, inv_moments)
    q1 = _exact_rotation(q0, quat.rotate(q_half, omega_body_half), h)
    return q1, quat.rotate(q1, omega_body0 + h * domega_half)


# ---------------------------------------------------------------- exaDEM
def exadem_push_to_quaternion(q, omega, alpha, h):
    r"""exaDEM ``push_to_quaternion`` (lab frame).

    :math:`Q \leftarrow \mathrm n(Q + h\,\tfrac12 (0, \omega) \otimes Q)`, then
    :math:`\omega \mathrel{+}= \tfrac h2 \alpha`.

    Returns
    -------
    q, omega : numpy.ndarray
    """
    return _advance_quaternion(q, omega, h), omega + 0.5 * h * alpha


def exadem_angular_acceleration(q, omega, torque, moments, inv_moments):
    r"""exaDEM ``push_to_angular_acceleration``: :math:`\alpha = R(Q)\,\dot\omega_b`
    with :math:`\dot\omega_b` from Euler's equations at :math:`\omega_b = R(Q)^\mathsf{T}\omega`,
    :math:`M_b = R(Q)^\mathsf{T} M`."""
    omega_body = quat.rotate_inverse(q, omega)
    return quat.rotate(q, euler_acceleration(omega_body, quat.rotate_inverse(q, torque), moments,
                                             inv_moments))


# ---------------------------------------------------------------- pressure
def intramolecular_virial(r, forces, model):
    r"""The intramolecular part of the atomic virial, :math:`\sum_b \sum_{i\in b} d_i \otimes f_i`.

    With :math:`d_i = r_i` the atom's lab displacement from its body's centre
    of mass, subtracting this from the atomic virial :math:`\sum_i x_i \otimes
    f_i` leaves the molecular virial :math:`\sum_b X_b \otimes F_b`.  Its
    antisymmetric part is the bodies' total torque; the symmetric part is
    returned.

    Parameters
    ----------
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements (Å), in ``model.order``.
    forces : numpy.ndarray, shape (n_atoms, 3)
        Atom forces (eV/Å), in atom order.
    model : rigidmd.core.model.BodyModel

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        eV, symmetric.
    """
    w = r.T @ forces[model.order]
    return 0.5 * (w + w.T)


def affine_drift(state, A, B, S):
    r"""Drift with the cell's motion: :math:`X \leftarrow A X + B V`, :math:`V \leftarrow S V`.

    For centres of mass and point particles (row vectors here, so
    :math:`X \leftarrow X A^\mathsf{T} + V B^\mathsf{T}`), and
    :math:`h \leftarrow A h` for the cell vectors.  Orientations do not
    change.  A barostat supplies the matrices; a plain drift over ``t`` is
    :math:`A = S = 1`, :math:`B = t`.

    Parameters
    ----------
    state : RigidState
    A, B, S : numpy.ndarray, shape (3, 3)
    """
    state.X = state.X @ A.T + state.V @ B.T
    state.x = state.x @ A.T + state.v @ B.T
    state.V = state.V @ S.T
    state.v = state.v @ S.T
    state.cell = state.cell @ A.T


def remove_centre_velocity(state, model) -> None:
    r"""Make the total momentum zero: :math:`V, v \mathrel{-}= U` with :math:`U = P/M`."""
    total = model.mass.sum() + model.free_masses.sum()
    U = (model.mass @ state.V + model.free_masses @ state.v) / total
    state.V -= U
    state.v -= U
