"""Exact torque-free motion of an asymmetric rigid top in the body frame.

The body-frame angular velocity of a free rigid body obeys Euler's equations

.. math::

    I_1 \\dot\\omega_1 = (I_2 - I_3)\\,\\omega_2\\omega_3

and cyclic permutations.  For three distinct principal moments the solution
is given by Jacobi elliptic functions: the component along the middle axis
``q`` follows ``sn``, the component along the extreme axis ``p`` about which
the body rotates (largest axis if ``L**2 > 2*E*I_mid``, smallest axis
otherwise) follows ``dn`` and the remaining extreme axis ``r`` follows ``cn``:

.. math::

    \\omega_q = a_q\\,\\mathrm{sn}(u), \\quad
    \\omega_r = a_r\\,\\mathrm{cn}(u), \\quad
    \\omega_p = \\sigma_p a_p\\,\\mathrm{dn}(u), \\quad
    u = u_0 + \\lambda t.

Rather than evaluating the elliptic functions at ``u0 + lambda*t`` (which
would require inverting ``sn``/``cn`` to obtain ``u0``), the functions here
use the addition theorems with ``sn(u0)``, ``cn(u0)`` and ``dn(u0)`` taken
directly from the initial angular velocity.  The initial condition is
therefore reproduced to rounding precision, signs included, and the sign of
``lambda`` (fixed by Euler's equations) gives the direction of time
evolution.  The module is a reference for tests; it is not part of the
``rigidmd`` package.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc

__all__ = [
    "FreeTopParameters",
    "energy_and_L2",
    "euler_rhs",
    "exact_body_angular_velocity",
    "free_top_parameters",
]

#: Relative tolerance used to flag the separatrix and non-distinct moments.
SEPARATRIX_RTOL = 1e-12


class FreeTopParameters(NamedTuple):
    """Elliptic-function parameters of a torque-free asymmetric top.

    Attributes
    ----------
    p, q, r : int
        Body axes (0, 1 or 2) carrying ``dn``, ``sn`` and ``cn``
        respectively.  ``q`` is always the intermediate axis and ``p`` the
        extreme axis about which the body rotates.
    amp_p, amp_q, amp_r : float
        Non-negative amplitudes of the three components.
    sign_p : float
        Constant sign (+1 or -1) of ``omega[p]``.
    m : float
        Parameter ``m = k**2`` of the elliptic functions, ``0 <= m < 1``.
    rate : float
        Signed rate ``lambda`` with ``u = u0 + lambda * t``.
    sn0, cn0, dn0 : float
        ``sn(u0)``, ``cn(u0)`` and ``dn(u0)`` taken from the initial data.
    u0 : float
        Initial elliptic argument in ``(-2K, 2K]``.
    quarter_period : float
        Complete elliptic integral ``K(m)``.
    period : float
        Period of the body-frame motion in time units, ``4K/|lambda|``
        (``inf`` for a steady rotation).
    """

    p: int
    q: int
    r: int
    amp_p: float
    amp_q: float
    amp_r: float
    sign_p: float
    m: float
    rate: float
    sn0: float
    cn0: float
    dn0: float
    u0: float
    quarter_period: float
    period: float


def _check_moments(moments):
    """Validate principal moments and return them as a float array.

    Parameters
    ----------
    moments : array_like, shape (3,)
        Principal moments of inertia.

    Returns
    -------
    numpy.ndarray, shape (3,)
        The moments as floats.

    Raises
    ------
    ValueError
        If the moments are not three positive, finite and distinct values.
    """
    inertia = np.asarray(moments, dtype=float)
    if inertia.shape != (3,):
        raise ValueError(f"moments must have shape (3,), got {inertia.shape}")
    if not np.all(np.isfinite(inertia)) or np.any(inertia <= 0.0):
        raise ValueError(f"moments must be positive and finite, got {inertia}")
    scale = inertia.max()
    for i, j in ((0, 1), (1, 2), (2, 0)):
        if abs(inertia[i] - inertia[j]) <= SEPARATRIX_RTOL * scale:
            raise ValueError(f"moments must be distinct (asymmetric top), got {inertia}")
    return inertia


def energy_and_L2(moments, omega_b):
    """Return twice the kinetic energy and the squared angular momentum.

    Parameters
    ----------
    moments : array_like, shape (3,)
        Principal moments of inertia ``(I1, I2, I3)``.
    omega_b : array_like, shape (..., 3)
        Body-frame angular velocity.

    Returns
    -------
    two_energy : numpy.ndarray or float
        ``2 E = sum(I * omega**2)``.
    L2 : numpy.ndarray or float
        ``L**2 = sum((I * omega)**2)``.
    """
    inertia = np.asarray(moments, dtype=float)
    omega = np.asarray(omega_b, dtype=float)
    two_energy = np.sum(inertia * omega**2, axis=-1)
    L2 = np.sum((inertia * omega) ** 2, axis=-1)
    return two_energy, L2


def euler_rhs(moments):
    """Build the right-hand side of Euler's equations for a free rigid body.

    Parameters
    ----------
    moments : array_like, shape (3,)
        Principal moments of inertia ``(I1, I2, I3)``.

    Returns
    -------
    callable
        ``f(t, omega)`` returning ``d omega / dt`` with
        ``I1 * domega1/dt = (I2 - I3) * omega2 * omega3`` and cyclic, in the
        form expected by :func:`scipy.integrate.solve_ivp`.
    """
    i1, i2, i3 = (float(x) for x in np.asarray(moments, dtype=float))

    def rhs(_t, omega):
        w1, w2, w3 = omega
        return np.array(
            [
                (i2 - i3) * w2 * w3 / i1,
                (i3 - i1) * w3 * w1 / i2,
                (i1 - i2) * w1 * w2 / i3,
            ]
        )

    return rhs


def _incomplete_f(phi, m, k_complete):
    """Incomplete elliptic integral ``F(phi | m)`` for ``phi`` in ``[-pi, pi]``.

    Parameters
    ----------
    phi : float
        Amplitude in ``[-pi, pi]``.
    m : float
        Parameter, ``0 <= m < 1``.
    k_complete : float
        ``K(m)``.

    Returns
    -------
    float
        ``F(phi | m)``, odd in ``phi`` and equal to ``2K - F(pi - phi)``
        for ``phi > pi/2``.
    """
    sign = -1.0 if phi < 0.0 else 1.0
    phi = abs(phi)
    if phi <= 0.5 * np.pi:
        return sign * float(ellipkinc(phi, m))
    return sign * (2.0 * k_complete - float(ellipkinc(np.pi - phi, m)))


def free_top_parameters(moments, omega_b0):
    """Compute the elliptic-function description of a torque-free top.

    Parameters
    ----------
    moments : array_like, shape (3,)
        Principal moments of inertia ``(I1, I2, I3)``; positive and distinct,
        in any order.
    omega_b0 : array_like, shape (3,)
        Initial body-frame angular velocity, not identically zero.

    Returns
    -------
    FreeTopParameters
        Axes, amplitudes, parameter ``m``, signed rate and initial phase.

    Raises
    ------
    ValueError
        If the moments are invalid or not distinct, if ``omega_b0`` is zero,
        or if the motion lies on the separatrix
        ``|L**2 - 2 E I_mid| <= 1e-12 * L**2``.
    """
    inertia = _check_moments(moments)
    omega = np.asarray(omega_b0, dtype=float)
    if omega.shape != (3,) or not np.all(np.isfinite(omega)):
        raise ValueError(f"omega_b0 must be a finite vector of shape (3,), got {omega}")

    order = np.argsort(inertia)
    small, mid, large = (int(i) for i in order)
    two_energy, L2 = energy_and_L2(inertia, omega)
    if L2 == 0.0:
        raise ValueError("omega_b0 is zero; there is no elliptic motion")

    # L**2 - 2 E I_x = sum_{i != x} I_i (I_i - I_x) omega_i**2, evaluated without
    # the vanishing i == x term to reduce cancellation.
    dist_mid = (
        inertia[small] * (inertia[small] - inertia[mid]) * omega[small] ** 2
        + inertia[large] * (inertia[large] - inertia[mid]) * omega[large] ** 2
    )
    if abs(dist_mid) <= SEPARATRIX_RTOL * L2:
        raise ValueError(
            "motion lies on the separatrix (L**2 == 2 E I_mid within relative "
            f"{SEPARATRIX_RTOL:g}); the elliptic solution degenerates"
        )

    # dn axis p: the extreme axis about which the body rotates.
    if dist_mid > 0.0:
        p, r = large, small
    else:
        p, r = small, large
    q = mid
    ip, iq, ir = inertia[p], inertia[q], inertia[r]
    wp, wq, wr = omega[p], omega[q], omega[r]

    # Squared amplitudes, each a sum of non-negative terms.
    amp_q2 = wq**2 + ir * (ir - ip) / (iq * (iq - ip)) * wr**2
    amp_r2 = wr**2 + iq * (iq - ip) / (ir * (ir - ip)) * wq**2
    amp_p2 = wp**2 + iq * (iq - ir) / (ip * (ip - ir)) * wq**2
    # amp_p2 - min(omega_p**2) over the motion, also a sum of non-negative terms.
    spread = (iq - ir) / ip * (iq * wq**2 / (ip - ir) + ir * wr**2 / (ip - iq))
    m = float(spread / amp_p2)
    amp_q, amp_r, amp_p = (float(np.sqrt(x)) for x in (amp_q2, amp_r2, amp_p2))
    sign_p = 1.0 if wp > 0.0 else -1.0

    if amp_q > 0.0:
        sn0 = float(wq / amp_q)
        cn0 = float(wr / amp_r)
    else:  # steady rotation about the extreme axis p
        sn0, cn0 = 0.0, 1.0
    dn0 = float(abs(wp) / amp_p)

    # Euler's equation for the middle axis, I_q d(omega_q)/dt = c_q omega_p omega_r,
    # with (q, j, k) cyclic, fixes the signed rate lambda.
    j, k = (q + 1) % 3, (q + 2) % 3
    c_q = inertia[j] - inertia[k]
    rate = float(c_q * sign_p * amp_p * np.sqrt((iq - ip) / (iq * ir * (ir - ip))))

    k_complete = float(ellipk(m))
    u0 = _incomplete_f(float(np.arctan2(sn0, cn0)), m, k_complete)
    period = 4.0 * k_complete / abs(rate) if amp_q > 0.0 else np.inf
    return FreeTopParameters(
        p=p,
        q=q,
        r=r,
        amp_p=amp_p,
        amp_q=amp_q,
        amp_r=amp_r,
        sign_p=sign_p,
        m=m,
        rate=rate,
        sn0=sn0,
        cn0=cn0,
        dn0=dn0,
        u0=u0,
        quarter_period=k_complete,
        period=float(period),
    )


def exact_body_angular_velocity(moments, omega_b0, t):
    """Exact body-frame angular velocity of a torque-free asymmetric top.

    Parameters
    ----------
    moments : array_like, shape (3,)
        Principal moments of inertia ``(I1, I2, I3)``; positive and distinct,
        in any order.
    omega_b0 : array_like, shape (3,)
        Body-frame angular velocity at ``t = 0``; any signs.
    t : array_like, shape (n,)
        Times (any sign) in units consistent with ``omega_b0``.  A scalar is
        treated as a length-1 array.

    Returns
    -------
    numpy.ndarray, shape (n, 3)
        ``omega_b(t)`` solving ``I1 * domega1/dt = (I2 - I3) * omega2 * omega3``
        and cyclic, with ``omega_b(0) == omega_b0`` to rounding precision.  A
        zero ``omega_b0`` gives zeros.

    Raises
    ------
    ValueError
        If the moments are invalid or not distinct, or if the motion lies on
        the separatrix (``|L**2 - 2 E I_mid| <= 1e-12 * L**2``).

    Notes
    -----
    With ``v = lambda * t`` and ``s0, c0, d0 = sn, cn, dn (u0)`` the addition
    theorems give ``sn(u0 + v) = (s0 cn(v) dn(v) + c0 d0 sn(v)) / D``,
    ``cn(u0 + v) = (c0 cn(v) - s0 d0 sn(v) dn(v)) / D`` and
    ``dn(u0 + v) = (d0 dn(v) - m s0 c0 sn(v) cn(v)) / D`` with
    ``D = 1 - m s0**2 sn(v)**2``.
    """
    times = np.asarray(t, dtype=float).reshape(-1)
    omega0 = np.asarray(omega_b0, dtype=float)
    _check_moments(moments)
    if omega0.shape == (3,) and not np.any(omega0):
        return np.zeros((times.size, 3))

    par = free_top_parameters(moments, omega0)
    v = par.rate * times
    sv, cv, dv, _ = ellipj(np.abs(v), par.m)
    sv = np.where(v < 0.0, -sv, sv)  # sn is odd; cn and dn are even

    s0, c0, d0, m = par.sn0, par.cn0, par.dn0, par.m
    denom = 1.0 - m * s0**2 * sv**2
    sn_u = (s0 * cv * dv + c0 * d0 * sv) / denom
    cn_u = (c0 * cv - s0 * d0 * sv * dv) / denom
    dn_u = (d0 * dv - m * s0 * c0 * sv * cv) / denom

    out = np.empty((times.size, 3))
    out[:, par.q] = par.amp_q * sn_u
    out[:, par.r] = par.amp_r * cn_u
    out[:, par.p] = par.sign_p * par.amp_p * dn_u
    return out
