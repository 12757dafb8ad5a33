r"""The NumPy references of the coupling kernels, each named as its kernel.

Each function here is the NumPy reference of the kernel of the same name in
:mod:`rigidmd.couplings._numba` and takes the same arguments (the state buffer
:attr:`rigidmd.core.state.RigidState.data` with the counts ``n`` of bodies and
``nf`` of point particles, a few 3x3 matrices, a chain's arrays).  Importing
this module makes each pair an operation of the backends
(:func:`rigidmd.core.backend.reference_of`): a coupling part calls
``view.backend.mtk_kick(...)`` and runs this function on the ``"numpy"``
backend, the kernel on ``"numba"``.  ``tests/core/test_backend.py`` runs every pair
on random inputs and compares.

=========================  ==============================================================
operation                  what it does
=========================  ==============================================================
:func:`chain_propagate`    a Nosé–Hoover chain over ``h``; the particles' velocity scale
:func:`chain_scale`        the same, driven by and scaling a momentum (a barostat's chain)
:func:`symmetric_exp_det`  :math:`e^{Gt}`, :math:`\int_0^t e^{Gs}ds` and :math:`\det e^{Gt}`
:func:`mtk_kick`           the MTK barostat's kick of :math:`p_g` by the pressure
:func:`mtk_friction`       the MTK barostat's :math:`V \leftarrow e^{-\kappa h} V`
:func:`scale_velocities`   a thermostat's scaling of ``V, v`` and ``p``
:func:`nose_hoover_scale`  a Nosé–Hoover thermostat's two chains and their scaling
:func:`ornstein_uhlenbeck` BAOAB's O step
=========================  ==============================================================

Also here, the plain functions the references share with the barostats:
:func:`exprel`, :func:`symmetric_exp`, :func:`project`.
"""

import numpy as np

from rigidmd.core import observables as obs
from rigidmd.core import operators as ops
from rigidmd.core.backend import reference_of
from rigidmd.couplings import _numba

__all__ = ["exprel", "symmetric_exp", "project", "chain_propagate", "chain_scale",
           "symmetric_exp_det", "mtk_kick", "mtk_friction", "scale_velocities",
           "nose_hoover_scale", "ornstein_uhlenbeck"]

#: ``couple`` by the code the kernels take (:data:`rigidmd.couplings._numba.COUPLE_CODES`).
_COUPLE_NAMES = {code: name for name, code in _numba.COUPLE_CODES.items()}


def exprel(x):
    r""":math:`(e^x - 1)/x`, 1 at 0, accurate for small :math:`|x|`."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-5
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 + x / 2 + x * x / 6, np.expm1(safe) / safe)


def symmetric_exp(G, t):
    r""":math:`e^{G t}` and :math:`\int_0^t e^{G s}\,ds` of a symmetric 3x3 matrix :math:`G`.

    Returns
    -------
    A, B : numpy.ndarray, shape (3, 3)
        Both symmetric; ``B`` has units of ``t``.
    """
    eigenvalues, U = np.linalg.eigh(G)
    A = (U * np.exp(eigenvalues * t)) @ U.T
    B = (U * (t * exprel(eigenvalues * t))) @ U.T
    return A, B


def project(G, couple):
    """The part of a 3x3 tensor that a ``couple`` mode moves (iso: mean trace; aniso: diagonal)."""
    if couple == "iso":
        return np.trace(G) / 3.0 * np.eye(3)
    if couple == "aniso":
        return np.diag(np.diag(G))
    return 0.5 * (G + G.T)


def _velocities(data, n, nf):
    """Views of ``V`` (n, 3) and ``v`` (nf, 3) in the state buffer."""
    return (data[3 * n:6 * n].reshape(n, 3),
            data[14 * n + 3 * nf:14 * n + 6 * nf].reshape(nf, 3))


@reference_of(_numba.chain_propagate)
def chain_propagate(xi, eta, ndof, unit_mass, K, kT, h, tloop):
    r"""Advance a Nosé–Hoover chain over ``h``; returns the particles' velocity scale.

    ``xi, eta`` (the chain's velocities and positions) change in place;
    ``unit_mass`` is :math:`k_BT\tau^2` (the masses are :math:`N_f` times it,
    then it); ``K`` the group's kinetic energy (eV).
    """
    if ndof == 0:
        return 1.0
    M = len(xi)
    Q = np.full(M, unit_mass)
    Q[0] *= ndof
    scale = 1.0
    delta = h / tloop

    def force(j, K2):
        if j == 0:
            return (K2 - ndof * kT) / Q[0]
        return (Q[j - 1] * xi[j - 1] ** 2 - kT) / Q[j]

    for _ in range(tloop):
        # Half kick of the chain over delta/2, from the end of the chain ...
        K2 = 2.0 * K * scale**2
        xi[M - 1] += 0.5 * delta * force(M - 1, K2)
        for j in range(M - 2, -1, -1):
            damp = np.exp(-0.25 * delta * xi[j + 1])
            xi[j] = (xi[j] * damp + 0.5 * delta * force(j, K2)) * damp
        # ... the particles' scaling and the positions of the chain ...
        scale *= np.exp(-delta * xi[0])
        eta += delta * xi
        # ... and the other half kick, back to the end of the chain.
        K2 = 2.0 * K * scale**2
        for j in range(M - 1):
            damp = np.exp(-0.25 * delta * xi[j + 1])
            xi[j] = (xi[j] * damp + 0.5 * delta * force(j, K2)) * damp
        xi[M - 1] += 0.5 * delta * force(M - 1, K2)
    return scale


@reference_of(_numba.chain_scale)
def chain_scale(p, mass, xi, eta, ndof, unit_mass, kT, h, tloop):
    r""":func:`chain_propagate` driven by the kinetic energy :math:`\sum p^2/2m` of a
    momentum ``p`` (2-D, mass ``mass``), which it scales in place."""
    flat = p.ravel()
    p *= chain_propagate(xi, eta, ndof, unit_mass, float(flat @ flat) / (2 * mass), kT, h,
                         tloop)


@reference_of(_numba.symmetric_exp_det)
def symmetric_exp_det(G, t):
    r""":func:`symmetric_exp` and :math:`\det e^{Gt}`: ``(A, B, det)``."""
    A, B = symmetric_exp(G, t)
    return A, B, np.linalg.det(A)


@reference_of(_numba.mtk_kick)
def mtk_kick(p_g, virial, kinetic, volume, pressure_au, n_f, h, couple):
    r""":math:`p_g \mathrel{+}= h\,\Pi[V(\mathsf P - P_0) + (2K_t/N_f)\mathbb 1]` in place.

    :math:`\mathsf P = (\mathsf W + \mathsf K)/V` from the molecular ``virial`` and
    the translational ``kinetic`` tensor (eV), :math:`\Pi` the projection of
    ``couple`` (a code of :data:`rigidmd.couplings._numba.COUPLE_CODES`).
    """
    ke = 2.0 * (0.5 * float(kinetic[0, 0] + kinetic[1, 1] + kinetic[2, 2])) / n_f
    G = volume * (-obs.stress_tensor(virial, kinetic, volume) - pressure_au * np.eye(3))
    p_g += h * project(G + ke * np.eye(3), _COUPLE_NAMES[couple])


@reference_of(_numba.mtk_friction)
def mtk_friction(data, n, nf, p_g, W, n_f, h):
    r""":math:`V \leftarrow e^{-\kappa h} V` (and ``v``), :math:`\kappa = (p_g +
    \mathrm{Tr}(p_g)/N_f)/W`; returns the factor :math:`e^{-\kappa h}`."""
    kappa = (p_g + np.trace(p_g) / n_f * np.eye(3)) / W
    factor, _ = symmetric_exp(-kappa, h)
    V, v = _velocities(data, n, nf)
    V[...] = V @ factor.T
    v[...] = v @ factor.T
    return factor


@reference_of(_numba.scale_velocities)
def scale_velocities(data, n, nf, translational, rotational):
    """``V, v`` times ``translational`` and ``p`` times ``rotational`` in the state buffer."""
    V, v = _velocities(data, n, nf)
    V *= translational
    v *= translational
    data[10 * n:14 * n] *= rotational


@reference_of(_numba.nose_hoover_scale)
def nose_hoover_scale(data, n, nf, xi_t, eta_t, ndof_t, xi_r, eta_r, ndof_r, unit_mass, K_t,
                      K_r, kT, h, tloop):
    """Both chains of a Nosé–Hoover thermostat over ``h`` (the translational, then the
    rotational) and their scalings; returns the two scales."""
    translational = chain_propagate(xi_t, eta_t, ndof_t, unit_mass, K_t, kT, h, tloop)
    rotational = chain_propagate(xi_r, eta_r, ndof_r, unit_mass, K_r, kT, h, tloop)
    scale_velocities(data, n, nf, translational, rotational)
    return translational, rotational


@reference_of(_numba.ornstein_uhlenbeck)
def ornstein_uhlenbeck(data, n, nf, c, sigma, inv_sqrt_mass, inv_sqrt_free, sqrt_moments,
                       noise):
    r"""BAOAB's O step on the state buffer, with the normal deviates ``noise`` drawn before.

    :math:`V \leftarrow cV + \sigma\xi/\sqrt M`, :math:`v \leftarrow cv + \sigma\xi/\sqrt m`,
    :math:`L_b \leftarrow cL_b + \sigma\sqrt{I}\,\xi` in the body frame; ``noise`` holds
    ``3n`` deviates for ``V``, then ``3 nf`` for ``v``, then ``3n`` for ``L_b``.
    """
    V, v = _velocities(data, n, nf)
    q = data[6 * n:10 * n].reshape(n, 4)
    p = data[10 * n:14 * n].reshape(n, 4)
    V[...] = c * V + sigma * noise[:3 * n].reshape(n, 3) * inv_sqrt_mass[:, None]
    v[...] = c * v + sigma * noise[3 * n:3 * n + 3 * nf].reshape(nf, 3) * inv_sqrt_free[:, None]
    L = ops.body_angular_momentum(q, p)
    L = c * L + sigma * sqrt_moments * noise[3 * n + 3 * nf:].reshape(n, 3)
    p[...] = ops.conjugate_momentum(q, L)
