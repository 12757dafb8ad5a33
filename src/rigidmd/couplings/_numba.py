r"""Compiled coupling half-steps: the arithmetic of the chains, the barostats and the scalings.

Each kernel does what its NumPy reference does, expression by expression, in one
compiled call on the state buffer and a few 3x3 matrices.  The references are
the functions of the same names and arguments in :mod:`rigidmd.couplings._numpy`
(the naming rule of :mod:`rigidmd.core.backend`); each pair is an operation of
the backends, so a part calls ``view.backend.mtk_kick(...)``: the ``"numba"``
backend runs the kernel, ``"numpy"`` the reference.  :func:`crescale_move` and
:func:`crescale_work` are called by ``CRescaleBarostat``'s compiled methods, whose
references are its NumPy methods (the operations ``crescale_drift`` and
``crescale_bookkeeping``); :func:`mtk_momentum_scale` and :func:`scale_translation`
are parts of :func:`mtk_friction`.  The two agree to roundoff
(``tests/core/test_backend.py``, ``tests/couplings/test_numba.py``, operator by
operator).  A Python step of a barostat was about a thousand small NumPy calls;
with the kernels it is a few dozen calls (``benchmarks/barostat_step.py``).

The state buffer is :attr:`rigidmd.core.state.RigidState.data`: ``X, V, q, p``
of ``n`` bodies, then ``x, v`` of ``nf`` point particles, then the cell.
"""

import numpy as np

from rigidmd.core._numba import congruence, jit

__all__ = ["COUPLE_CODES", "chain_propagate", "chain_scale", "symmetric_exp_det", "mtk_kick",
           "mtk_momentum_scale", "mtk_friction", "scale_translation", "scale_velocities",
           "nose_hoover_scale", "crescale_move", "crescale_work", "ornstein_uhlenbeck"]

#: ``couple`` as the kernels take it.
COUPLE_CODES = {"iso": 0, "aniso": 1, "tri": 2}


@jit
def _chain_force(j, K2, xi, ndof, kT, Q0, Q):
    """The force on chain element ``j`` (``Q0`` the first mass, ``Q`` the others)."""
    if j == 0:
        return (K2 - ndof * kT) / Q0
    previous = Q0 if j == 1 else Q
    return (previous * xi[j - 1] ** 2 - kT) / Q


@jit
def chain_propagate(xi, eta, ndof, unit_mass, K, kT, h, tloop):
    r"""Advance a Nosé–Hoover chain over ``h``; returns the particles' velocity scale.

    ``xi, eta`` (the chain's velocities and positions) change in place;
    ``unit_mass`` is :math:`k_BT\tau^2` (the masses are :math:`N_f` times it,
    then it); ``K`` the group's kinetic energy (eV).
    """
    if ndof == 0:
        return 1.0
    M = xi.shape[0]
    Q = unit_mass
    Q0 = unit_mass * ndof
    scale = 1.0
    delta = h / tloop
    for _ in range(tloop):
        K2 = 2.0 * K * scale**2
        xi[M - 1] += 0.5 * delta * _chain_force(M - 1, K2, xi, ndof, kT, Q0, Q)
        for j in range(M - 2, -1, -1):
            damp = np.exp(-0.25 * delta * xi[j + 1])
            xi[j] = (xi[j] * damp + 0.5 * delta * _chain_force(j, K2, xi, ndof, kT, Q0, Q)) \
                * damp
        scale *= np.exp(-delta * xi[0])
        for j in range(M):
            eta[j] += delta * xi[j]
        K2 = 2.0 * K * scale**2
        for j in range(M - 1):
            damp = np.exp(-0.25 * delta * xi[j + 1])
            xi[j] = (xi[j] * damp + 0.5 * delta * _chain_force(j, K2, xi, ndof, kT, Q0, Q)) \
                * damp
        xi[M - 1] += 0.5 * delta * _chain_force(M - 1, K2, xi, ndof, kT, Q0, Q)
    return scale


@jit
def chain_scale(p, mass, xi, eta, ndof, unit_mass, kT, h, tloop):
    r""":func:`chain_propagate` driven by the kinetic energy :math:`\sum p^2/2m` of a
    momentum ``p`` (2-D, mass ``mass``), which it scales in place."""
    K = 0.0
    for i in range(p.shape[0]):
        for j in range(p.shape[1]):
            K += p[i, j] * p[i, j]
    scale = chain_propagate(xi, eta, ndof, unit_mass, K / (2 * mass), kT, h, tloop)
    for i in range(p.shape[0]):
        for j in range(p.shape[1]):
            p[i, j] *= scale


@jit
def _exprel(x):
    if abs(x) < 1e-5:
        return 1.0 + x / 2 + x * x / 6
    return np.expm1(x) / x


@jit
def symmetric_exp_det(G, t):
    r""":math:`e^{Gt}`, :math:`\int_0^t e^{Gs}ds` of a symmetric 3x3 ``G`` and :math:`\det e^{Gt}`.

    A diagonal ``G`` (``iso`` and ``aniso`` barostats) takes no eigensolver:
    the eigenvectors are then a permutation, and the result is the one the
    eigensolver gives, bit for bit.
    """
    A = np.zeros((3, 3))
    B = np.zeros((3, 3))
    if G[0, 1] == 0.0 and G[0, 2] == 0.0 and G[1, 2] == 0.0 \
            and G[1, 0] == 0.0 and G[2, 0] == 0.0 and G[2, 1] == 0.0:
        for k in range(3):
            x = G[k, k] * t
            A[k, k] = np.exp(x)
            B[k, k] = t * _exprel(x)
    else:
        w, U = np.linalg.eigh(G)
        e = np.empty(3)
        r = np.empty(3)
        for k in range(3):
            e[k] = np.exp(w[k] * t)
            r[k] = t * _exprel(w[k] * t)
        for i in range(3):
            for j in range(3):
                a = 0.0
                b = 0.0
                for k in range(3):
                    a += U[i, k] * e[k] * U[j, k]
                    b += U[i, k] * r[k] * U[j, k]
                A[i, j] = a
                B[i, j] = b
    det = (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
           - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
           + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))
    return A, B, det


@jit
def mtk_kick(p_g, virial, kinetic, volume, pressure_au, n_f, h, couple):
    r""":math:`p_g \mathrel{+}= h\,\Pi[V(\mathsf P - P_0) + (2K_t/N_f)\mathbb 1]` in place.

    :math:`\mathsf P = (\mathsf W + \mathsf K)/V` from the molecular
    ``virial`` and the translational ``kinetic`` tensor (eV), :math:`\Pi` the
    projection of ``couple`` (:data:`COUPLE_CODES`).
    """
    ke = 2.0 * (0.5 * (kinetic[0, 0] + kinetic[1, 1] + kinetic[2, 2])) / n_f
    G = np.empty((3, 3))
    for a in range(3):
        for c in range(3):
            P = -(-(virial[a, c] + kinetic[a, c]) / volume)
            if a == c:
                G[a, c] = volume * (P - pressure_au) + ke
            else:
                G[a, c] = volume * P
    if couple == 0:
        mean = (G[0, 0] + G[1, 1] + G[2, 2]) / 3.0
        for k in range(3):
            p_g[k, k] += h * mean
    elif couple == 1:
        for k in range(3):
            p_g[k, k] += h * G[k, k]
    else:
        for a in range(3):
            for c in range(3):
                p_g[a, c] += h * (0.5 * (G[a, c] + G[c, a]))


@jit
def mtk_momentum_scale(p_g, W, n_f, h):
    r""":math:`e^{-\kappa h}` with :math:`\kappa = (p_g + \mathrm{Tr}(p_g)/N_f)/W` (3x3)."""
    trace = p_g[0, 0] + p_g[1, 1] + p_g[2, 2]
    G = np.empty((3, 3))
    for a in range(3):
        for c in range(3):
            G[a, c] = -((p_g[a, c] + (trace / n_f if a == c else 0.0)) / W)
    return symmetric_exp_det(G, h)[0]


@jit
def scale_translation(data, n, nf, F):
    r""":math:`V \leftarrow V F^\mathsf{T}` and :math:`v \leftarrow v F^\mathsf{T}`, in place."""
    for start, count in ((3 * n, n), (14 * n + 3 * nf, nf)):
        for i in range(count):
            k = start + 3 * i
            v0, v1, v2 = data[k], data[k + 1], data[k + 2]
            for a in range(3):
                data[k + a] = v0 * F[a, 0] + v1 * F[a, 1] + v2 * F[a, 2]


@jit
def mtk_friction(data, n, nf, p_g, W, n_f, h):
    r""":func:`mtk_momentum_scale` applied by :func:`scale_translation`; returns the factor."""
    F = mtk_momentum_scale(p_g, W, n_f, h)
    scale_translation(data, n, nf, F)
    return F


@jit
def scale_velocities(data, n, nf, translational, rotational):
    """``V, v`` times ``translational`` and ``p`` times ``rotational`` in the state buffer."""
    for k in range(3 * n, 6 * n):
        data[k] *= translational
    for k in range(10 * n, 14 * n):
        data[k] *= rotational
    for k in range(14 * n + 3 * nf, 14 * n + 6 * nf):
        data[k] *= translational


@jit
def nose_hoover_scale(data, n, nf, xi_t, eta_t, ndof_t, xi_r, eta_r, ndof_r, unit_mass, K_t,
                      K_r, kT, h, tloop):
    """Both chains of a Nosé–Hoover thermostat over ``h`` (:func:`chain_propagate`, the
    translational then the rotational) and their scalings (:func:`scale_velocities`);
    returns the two scales."""
    translational = chain_propagate(xi_t, eta_t, ndof_t, unit_mass, K_t, kT, h, tloop)
    rotational = chain_propagate(xi_r, eta_r, ndof_r, unit_mass, K_r, kT, h, tloop)
    scale_velocities(data, n, nf, translational, rotational)
    return translational, rotational


@jit
def _crescale_forces(pressure, volume, pressure_au, kT, basis):
    mean = (pressure[0, 0] + pressure[1, 1] + pressure[2, 2]) / 3.0
    f_lambda = 2.0 * np.sqrt(volume) * (mean - pressure_au + 0.5 * kT / volume)
    f_eta = np.zeros(basis.shape[0])
    for k in range(basis.shape[0]):
        for i in range(3):
            for j in range(3):
                f_eta[k] += basis[k, i, j] * pressure[i, j]
        f_eta[k] *= volume
    return f_lambda, f_eta


@jit
def _inverse(A, det):
    """The inverse of a 3x3 matrix of determinant ``det``; of a diagonal one, ``1 / A_kk``
    (what LAPACK's solve gives for it, bit for bit)."""
    out = np.zeros((3, 3))
    if A[0, 1] == 0.0 and A[0, 2] == 0.0 and A[1, 2] == 0.0 \
            and A[1, 0] == 0.0 and A[2, 0] == 0.0 and A[2, 1] == 0.0:
        for k in range(3):
            out[k, k] = 1.0 / A[k, k]
        return out
    for i in range(3):
        for j in range(3):
            a, b = (j + 1) % 3, (j + 2) % 3
            c, d = (i + 1) % 3, (i + 2) % 3
            out[i, j] = (A[a, c] * A[b, d] - A[a, d] * A[b, c]) / det
    return out


@jit
def crescale_move(virial, kinetic, volume, pressure_au, kT, beta, taup, dt, xi_lambda, xi_eta,
                  basis, h):
    r"""Stochastic cell rescaling's move of one step (Bernetti & Bussi's "T" scheme).

    The pressure is :math:`(\mathsf W + \mathsf K)/V` of the molecular ``virial``
    and the kinetic tensor ``kinetic`` (eV) at the ``volume``.  Returns
    ``(mu, B, inverse, det, step_lambda, step_eta, d_lambda, d_eta, first, moved)``:
    the cell strain :math:`\mu`, the drift's :math:`B = \tfrac h2(\mu + \mu^{-1})`,
    :math:`\mu^{-1}`, :math:`\det\mu`, the steps of :math:`\lambda = \sqrt V` and of
    the shape components, the two mobilities, the bookkeeping of the first half and
    the kinetic tensor of the velocities as the drift leaves them,
    :math:`\mu^{-1}\mathsf K\mu^{-\mathsf T}`.  A collapsing volume gives ``det = 0``
    (the caller refuses it).
    """
    pressure = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            pressure[i, j] = (virial[i, j] + kinetic[i, j]) / volume
    f_lambda, f_eta = _crescale_forces(pressure, volume, pressure_au, kT, basis)
    d_lambda = 0.25 * kT * beta / taup
    d_eta = kT * beta / (3.0 * taup * volume)
    lam = np.sqrt(volume)
    step_lambda = d_lambda / kT * f_lambda * dt + np.sqrt(2.0 * d_lambda * dt) * xi_lambda
    m = basis.shape[0]
    step_eta = np.empty(m)
    for k in range(m):
        step_eta[k] = d_eta / kT * f_eta[k] * dt + np.sqrt(2.0 * d_eta * dt) * xi_eta[k]
    identity = np.eye(3)
    if not step_lambda / lam > -1.0:
        return (identity, identity, identity, 0.0, step_lambda, step_eta, d_lambda, d_eta, 0.0,
                identity)
    strain = (2.0 / 3.0) * np.log1p(step_lambda / lam) * identity
    for k in range(m):
        for i in range(3):
            for j in range(3):
                strain[i, j] += step_eta[k] * basis[k, i, j]
    mu, _, det = symmetric_exp_det(strain, 1.0)
    inverse = _inverse(mu, det)
    eta_f = 0.0
    eta_ff = 0.0
    for k in range(m):
        eta_f += step_eta[k] * f_eta[k]
        eta_ff += f_eta[k] * f_eta[k]
    first = (0.5 * step_lambda * f_lambda
             - 0.25 * d_lambda / kT * dt * f_lambda**2 + 0.5 * kT * np.log(volume)
             + 0.5 * eta_f - 0.25 * d_eta / kT * dt * eta_ff)
    B = 0.5 * h * (mu + inverse)
    moved = congruence(inverse, kinetic)
    return mu, B, inverse, det, step_lambda, step_eta, d_lambda, d_eta, first, moved


@jit
def crescale_work(virial, kinetic, volume, pressure_au, kT, dt, basis, step_lambda, step_eta,
                  d_lambda, d_eta):
    """The bookkeeping of the scheme's second half (eV), from the pressure after the move."""
    pressure = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            pressure[i, j] = virial[i, j] / volume + kinetic[i, j] / volume
    f_lambda, f_eta = _crescale_forces(pressure, volume, pressure_au, kT, basis)
    eta_f = 0.0
    eta_ff = 0.0
    for k in range(basis.shape[0]):
        eta_f += step_eta[k] * f_eta[k]
        eta_ff += f_eta[k] * f_eta[k]
    return (0.5 * step_lambda * f_lambda
            + 0.25 * d_lambda / kT * dt * f_lambda**2 - 0.5 * kT * np.log(volume)
            + 0.5 * eta_f + 0.25 * d_eta / kT * dt * eta_ff)


@jit
def ornstein_uhlenbeck(data, n, nf, c, sigma, inv_sqrt_mass, inv_sqrt_free, sqrt_moments,
                       noise):
    r"""BAOAB's O step on the state buffer, with the normal deviates ``noise`` drawn before.

    :math:`V \leftarrow cV + \sigma\xi/\sqrt M`, :math:`v \leftarrow cv + \sigma\xi/\sqrt m`,
    :math:`L_{b,k} \leftarrow cL_{b,k} + \sigma\sqrt{I_k}\,\xi` with
    :math:`L_b = \tfrac12\mathrm{vec}(q^*\otimes p)` and :math:`p = 2q\otimes(0, L_b)`;
    :math:`\sigma = \sqrt{(1-c^2)k_BT}`.  ``noise`` holds ``3n`` deviates for ``V``, then
    ``3 nf`` for ``v``, then ``3n`` for ``L_b`` (row by row).
    """
    V = data[3 * n:6 * n].reshape((n, 3))
    q = data[6 * n:10 * n].reshape((n, 4))
    p = data[10 * n:14 * n].reshape((n, 4))
    v = data[14 * n + 3 * nf:14 * n + 6 * nf].reshape((nf, 3))
    for b in range(n):
        for a in range(3):
            V[b, a] = c * V[b, a] + sigma * noise[3 * b + a] * inv_sqrt_mass[b]
    for i in range(nf):
        for a in range(3):
            v[i, a] = c * v[i, a] + sigma * noise[3 * n + 3 * i + a] * inv_sqrt_free[i]
    start = 3 * n + 3 * nf
    for b in range(n):
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        l0 = 0.5 * (w * p1 - x * p0 - y * p3 + z * p2)
        l1 = 0.5 * (w * p2 + x * p3 - y * p0 - z * p1)
        l2 = 0.5 * (w * p3 - x * p2 + y * p1 - z * p0)
        j = start + 3 * b
        l0 = c * l0 + sigma * sqrt_moments[b, 0] * noise[j]
        l1 = c * l1 + sigma * sqrt_moments[b, 1] * noise[j + 1]
        l2 = c * l2 + sigma * sqrt_moments[b, 2] * noise[j + 2]
        p[b, 0] = 2.0 * (-x * l0 - y * l1 - z * l2)
        p[b, 1] = 2.0 * (w * l0 + y * l2 - z * l1)
        p[b, 2] = 2.0 * (w * l1 - x * l2 + z * l0)
        p[b, 3] = 2.0 * (w * l2 + x * l1 - y * l0)
