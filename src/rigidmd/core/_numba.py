r"""Compiled NO_SQUISH half-steps: one loop over bodies each, no temporaries.

The same arithmetic as the NumPy reference in :mod:`rigidmd.core.operators`, fused
so that a step touches every body twice (before and after the force call).
Measured on 4096 rigid waters: about 0.1 µs per body per step here against
about 2 µs for the NumPy path, whose cost is dominated by temporaries.

Only compiled when numba is available; :data:`AVAILABLE` says whether it is.
The compiled backend (:class:`rigidmd.core.backend.CompiledBackend`) calls
these; the reference backend (:class:`rigidmd.core.backend.Backend`) calls the
NumPy operations each is named after or documented against.  Naming rule (all
packages): the kernels of a package live in its ``_numba`` module, named as
their NumPy reference (see :mod:`rigidmd.core.backend`).
"""

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None

AVAILABLE = numba is not None

__all__ = ["AVAILABLE", "jit", "pack_model", "first_half", "second_half",
           "place", "momenta", "kick_half_drift", "half_drift_place", "largest_angular_speed",
           "kinetic_tensor", "rotational_energy",
           "intramolecular_virial", "molecular_virial_voigt", "net_force", "congruence",
           "smallest_width", "equal_or_close"]


#: Whether compiled functions are cached on disk (False when numba finds no writable place).
CACHED = True


def jit(func):
    """``numba.njit`` with an on-disk cache, or without one when no cache can be written.

    numba caches next to the package or under the user's home (or
    ``NUMBA_CACHE_DIR``); on a read-only install with no writable home it
    refuses ``cache=True`` with a RuntimeError at decoration.  The functions
    are then compiled at every start (a few seconds) instead.
    """
    global CACHED
    if numba is None:  # pragma: no cover
        return func
    if CACHED:
        try:
            return numba.njit(cache=True, fastmath=False, nogil=True)(func)
        except RuntimeError as err:
            if "cannot cache" not in str(err):
                raise
            CACHED = False
    return numba.njit(cache=False, fastmath=False, nogil=True)(func)


def _inline(func):
    """A helper of the kernels, compiled into each caller (``inline="always"``).

    Inlined in numba's own IR the five free-rotor sub-steps and the kick
    stay in registers: measured 10-12 % off the first loop on 64 and 4096
    waters against LLVM's own (partial) inlining of separately compiled helpers.
    """
    if numba is None:  # pragma: no cover
        return func
    return numba.njit(inline="always", nogil=True)(func)


@_inline
def _matrix(q0, q1, q2, q3):
    """R(q) as nine scalars, row by row."""
    return (1.0 - 2.0 * (q2 * q2 + q3 * q3), 2.0 * (q1 * q2 - q0 * q3), 2.0 * (q1 * q3 + q0 * q2),
            2.0 * (q1 * q2 + q0 * q3), 1.0 - 2.0 * (q1 * q1 + q3 * q3), 2.0 * (q2 * q3 - q0 * q1),
            2.0 * (q1 * q3 - q0 * q2), 2.0 * (q2 * q3 + q0 * q1), 1.0 - 2.0 * (q1 * q1 + q2 * q2))


@_inline
def _kick(q0, q1, q2, q3, p0, p1, p2, p3, t0, t1, t2, h2):
    """p + h2 * q ⊗ (0, R(q)ᵀ t), for a lab torque t."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _matrix(q0, q1, q2, q3)
    b0 = r00 * t0 + r10 * t1 + r20 * t2
    b1 = r01 * t0 + r11 * t1 + r21 * t2
    b2 = r02 * t0 + r12 * t1 + r22 * t2
    return (p0 + h2 * (-q1 * b0 - q2 * b1 - q3 * b2),
            p1 + h2 * (q0 * b0 + q2 * b2 - q3 * b1),
            p2 + h2 * (q0 * b1 - q1 * b2 + q3 * b0),
            p3 + h2 * (q0 * b2 + q1 * b1 - q2 * b0))


@_inline
def _place_body(b, X, q0, q1, q2, q3, d, bounds, order, r, positions):
    """Lab displacements r_j = R(q) d_j and positions X + r_j of body b's atoms."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _matrix(q0, q1, q2, q3)
    for j in range(bounds[b], bounds[b + 1]):
        i = order[j]
        d0, d1, d2 = d[j, 0], d[j, 1], d[j, 2]
        x = r00 * d0 + r01 * d1 + r02 * d2
        y = r10 * d0 + r11 * d1 + r12 * d2
        z = r20 * d0 + r21 * d1 + r22 * d2
        r[j, 0], r[j, 1], r[j, 2] = x, y, z
        positions[i, 0] = X[b, 0] + x
        positions[i, 1] = X[b, 1] + y
        positions[i, 2] = X[b, 2] + z


# Taylor coefficients of sin and cos.  On |x| <= 0.25 the first omitted
# terms, x**13/13! and x**14/14!, are below 3e-18, far below one unit in the
# last place: the polynomials are as exact as the library functions and
# about three times cheaper.  NO_SQUISH sub-step angles are phi*h ~ omega*dt/4
# (0.03 for water at 1 fs), so the library is only called for fast rotors.
_SIN = (1.0, -1.0 / 6, 1.0 / 120, -1.0 / 5040, 1.0 / 362880, -1.0 / 39916800)
_COS = (1.0, -1.0 / 2, 1.0 / 24, -1.0 / 720, 1.0 / 40320, -1.0 / 3628800, 1.0 / 479001600)


@_inline
def _sincos(x):
    """(sin x, cos x); polynomials in Estrin form (short dependency chains)."""
    if abs(x) > 0.25:
        return np.sin(x), np.cos(x)
    y = x * x
    y2 = y * y
    y4 = y2 * y2
    s = ((_SIN[0] + _SIN[1] * y) + y2 * (_SIN[2] + _SIN[3] * y)
         + y4 * (_SIN[4] + _SIN[5] * y))
    c = ((_COS[0] + _COS[1] * y) + y2 * (_COS[2] + _COS[3] * y)
         + y4 * ((_COS[4] + _COS[5] * y) + y2 * _COS[6]))
    return s * x, c


@_inline
def _rotate(q0, q1, q2, q3, p0, p1, p2, p3, inv4i, k, h):
    """NO_SQUISH free rotation about body axis k (0, 1, 2) for time h.

    ``inv4i`` is 1 / (4 I_k), or 0 for a zero moment (no rotation).  Works on
    scalars so the five sub-steps of a body stay in registers.
    """
    if k == 0:
        kq0, kq1, kq2, kq3 = -q1, q0, q3, -q2
        kp0, kp1, kp2, kp3 = -p1, p0, p3, -p2
    elif k == 1:
        kq0, kq1, kq2, kq3 = -q2, -q3, q0, q1
        kp0, kp1, kp2, kp3 = -p2, -p3, p0, p1
    else:
        kq0, kq1, kq2, kq3 = -q3, q2, -q1, q0
        kp0, kp1, kp2, kp3 = -p3, p2, -p1, p0
    phi = (p0 * kq0 + p1 * kq1 + p2 * kq2 + p3 * kq3) * inv4i
    s, c = _sincos(phi * h)
    return (c * q0 + s * kq0, c * q1 + s * kq1, c * q2 + s * kq2, c * q3 + s * kq3,
            c * p0 + s * kp0, c * p1 + s * kp1, c * p2 + s * kp2, c * p3 + s * kp3)


def pack_model(inv_mass, inv_moments, body_coordinates, atom_masses, bounds, order):
    """The body model as the three arrays :func:`first_half` and :func:`second_half` take.

    Returns
    -------
    body : numpy.ndarray, shape (n_bodies, 7)
        Per body: :math:`1/M`, :math:`1/(4 I_k)` (three), :math:`1/I_k` (three),
        0 where :math:`I_k = 0`.
    atom : numpy.ndarray, shape (n_body_atoms, 4)
        Per body atom, in body order: body-frame coordinates (Å) and mass (amu).
    index : numpy.ndarray of int64, shape (n_bodies + 1 + n_body_atoms,)
        ``bounds`` (body ``b``'s atoms are ``bounds[b]:bounds[b + 1]`` in body
        order) followed by ``order`` (their atom indices).
    """
    body = np.column_stack([inv_mass, 0.25 * inv_moments, inv_moments])
    atom = np.column_stack([body_coordinates, atom_masses])
    index = np.concatenate([bounds, order]).astype(np.int64)
    return (np.ascontiguousarray(body, dtype=float), np.ascontiguousarray(atom, dtype=float),
            index)


@_inline
def _unpack(data, n):
    """Views X, V, q, p of the first n bodies' part of a state buffer."""
    X = data[0:3 * n].reshape((n, 3))
    V = data[3 * n:6 * n].reshape((n, 3))
    q = data[6 * n:10 * n].reshape((n, 4))
    p = data[10 * n:14 * n].reshape((n, 4))
    return X, V, q, p


@jit
def first_half(data, n, F, tau, body, atom, index, dt, r, positions, ABS, affine):
    r"""Kick (dt/2), drift (dt), free rotor (dt), and place the body atoms.

    ``data`` is a :attr:`rigidmd.core.state.RigidState.data` buffer with ``n``
    bodies (its ``X, V, q, p`` updated in place); ``body, atom, index`` are
    :func:`pack_model`'s.  Writes the lab displacements ``r`` (in body-atom
    order) and the atom ``positions`` (atom order).  With ``affine`` the
    drift moves the centres of mass with the cell, :math:`X \leftarrow A X + B V`,
    :math:`V \leftarrow S V` (``ABS`` = the three 3x3 matrices from a
    barostat, stacked); otherwise :math:`X \mathrel{+}= dt\, V`.
    """
    X, V, q, p = _unpack(data, n)
    bounds, order = index[:n + 1], index[n + 1:]
    d = atom[:, :3]
    A, B, S = ABS[0], ABS[1], ABS[2]
    half = 0.5 * dt
    for b in range(n):
        hm = half * body[b, 0]
        for a in range(3):
            V[b, a] += hm * F[b, a]
        if affine:
            x0, x1, x2 = X[b, 0], X[b, 1], X[b, 2]
            v0, v1, v2 = V[b, 0], V[b, 1], V[b, 2]
            for a in range(3):
                X[b, a] = (A[a, 0] * x0 + A[a, 1] * x1 + A[a, 2] * x2
                           + B[a, 0] * v0 + B[a, 1] * v1 + B[a, 2] * v2)
                V[b, a] = S[a, 0] * v0 + S[a, 1] * v1 + S[a, 2] * v2
        else:
            for a in range(3):
                X[b, a] += dt * V[b, a]
        q0, q1, q2, q3 = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = _kick(q0, q1, q2, q3, p[b, 0], p[b, 1], p[b, 2], p[b, 3],
                               tau[b, 0], tau[b, 1], tau[b, 2], dt)
        i0, i1, i2 = body[b, 1], body[b, 2], body[b, 3]
        q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i2, 2, half)
        q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i1, 1, half)
        q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i0, 0, dt)
        q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i1, 1, half)
        q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i2, 2, half)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0, q1, q2, q3
        p[b, 0], p[b, 1], p[b, 2], p[b, 3] = p0, p1, p2, p3
        _place_body(b, X, q0, q1, q2, q3, d, bounds, order, r, positions)


@_inline
def _half_rotor(q0, q1, q2, q3, p0, p1, p2, p3, i0, i1, i2, half):
    """NO_SQUISH's free rotor over ``half``: R3(half/2) R2(half/2) R1(half) R2 R3."""
    quarter = 0.5 * half
    q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i2, 2, quarter)
    q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i1, 1, quarter)
    q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i0, 0, half)
    q0, q1, q2, q3, p0, p1, p2, p3 = _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i1, 1, quarter)
    return _rotate(q0, q1, q2, q3, p0, p1, p2, p3, i2, 2, quarter)


@jit
def kick_half_drift(data, n, F, tau, body, dt):
    """BAOAB's B and first A: kick (dt/2), drift (dt/2), free rotor (dt/2); no placement.

    Arguments as in :func:`first_half`.
    """
    X, V, q, p = _unpack(data, n)
    half = 0.5 * dt
    for b in range(n):
        hm = half * body[b, 0]
        for a in range(3):
            V[b, a] += hm * F[b, a]
            X[b, a] += half * V[b, a]
        q0, q1, q2, q3 = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = _kick(q0, q1, q2, q3, p[b, 0], p[b, 1], p[b, 2], p[b, 3],
                               tau[b, 0], tau[b, 1], tau[b, 2], dt)
        q0, q1, q2, q3, p0, p1, p2, p3 = _half_rotor(q0, q1, q2, q3, p0, p1, p2, p3,
                                                     body[b, 1], body[b, 2], body[b, 3], half)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0, q1, q2, q3
        p[b, 0], p[b, 1], p[b, 2], p[b, 3] = p0, p1, p2, p3


@jit
def half_drift_place(data, n, body, atom, index, dt, r, positions):
    """BAOAB's second A: drift (dt/2), free rotor (dt/2), and place the body atoms.

    Arguments as in :func:`first_half`.
    """
    X, V, q, p = _unpack(data, n)
    bounds, order = index[:n + 1], index[n + 1:]
    d = atom[:, :3]
    half = 0.5 * dt
    for b in range(n):
        for a in range(3):
            X[b, a] += half * V[b, a]
        q0, q1, q2, q3, p0, p1, p2, p3 = _half_rotor(
            q[b, 0], q[b, 1], q[b, 2], q[b, 3], p[b, 0], p[b, 1], p[b, 2], p[b, 3],
            body[b, 1], body[b, 2], body[b, 3], half)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0, q1, q2, q3
        p[b, 0], p[b, 1], p[b, 2], p[b, 3] = p0, p1, p2, p3
        _place_body(b, X, q0, q1, q2, q3, d, bounds, order, r, positions)


@jit
def second_half(data, n, F, tau, body, atom, index, dt, forces, r, momenta, write_momenta):
    """Reduce forces to bodies, kick (dt/2), and (optionally) write rigid atom momenta.

    Arguments as in :func:`first_half`.  First checks that the body atoms'
    ``forces`` are finite: if any is not, returns False having written
    nothing.  Otherwise overwrites ``F, tau`` with the new body forces and
    lab torques, updates ``V, p`` in place and, if ``write_momenta``, writes
    ``momenta`` (atom order) of the body atoms, and returns True.  (A coupled
    dynamics changes ``V, p`` after this and writes the momenta once, with
    :func:`momenta`.)
    """
    X, V, q, p = _unpack(data, n)
    bounds, order = index[:n + 1], index[n + 1:]
    inv_moments = body[:, 4:7]
    m = atom[:, 3]
    # One reduction: a NaN or an infinity anywhere makes the sum non-finite.
    total = 0.0
    for j in range(order.shape[0]):
        i = order[j]
        total += forces[i, 0] + forces[i, 1] + forces[i, 2]
    if not np.isfinite(total):
        return False
    half = 0.5 * dt
    for b in range(n):
        fx = fy = fz = 0.0
        tx = ty = tz = 0.0
        for j in range(bounds[b], bounds[b + 1]):
            i = order[j]
            f0, f1, f2 = forces[i, 0], forces[i, 1], forces[i, 2]
            r0, r1, r2 = r[j, 0], r[j, 1], r[j, 2]
            fx += f0
            fy += f1
            fz += f2
            tx += r1 * f2 - r2 * f1
            ty += r2 * f0 - r0 * f2
            tz += r0 * f1 - r1 * f0
        F[b, 0], F[b, 1], F[b, 2] = fx, fy, fz
        tau[b, 0], tau[b, 1], tau[b, 2] = tx, ty, tz
        hm = half * body[b, 0]
        vx = V[b, 0] + hm * fx
        vy = V[b, 1] + hm * fy
        vz = V[b, 2] + hm * fz
        V[b, 0], V[b, 1], V[b, 2] = vx, vy, vz
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = _kick(w, x, y, z, p[b, 0], p[b, 1], p[b, 2], p[b, 3], tx, ty, tz, dt)
        p[b, 0], p[b, 1], p[b, 2], p[b, 3] = p0, p1, p2, p3
        if write_momenta:
            _body_momenta(b, vx, vy, vz, w, x, y, z, p0, p1, p2, p3, inv_moments, bounds, order,
                          m, r, momenta)
    return True


@_inline
def _body_momenta(b, vx, vy, vz, w, x, y, z, p0, p1, p2, p3, inv_moments, bounds, order, m, r,
                  momenta):
    """Rigid momenta m_j (V + ω × r_j) of body b's atoms."""
    # L_b = ½ vec(q* ⊗ p); ω_b = L_b / I (0 about a zero-moment axis); ω = R ω_b.
    l0 = 0.5 * (w * p1 - x * p0 - y * p3 + z * p2)
    l1 = 0.5 * (w * p2 + x * p3 - y * p0 - z * p1)
    l2 = 0.5 * (w * p3 - x * p2 + y * p1 - z * p0)
    w0 = l0 * inv_moments[b, 0]
    w1 = l1 * inv_moments[b, 1]
    w2 = l2 * inv_moments[b, 2]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _matrix(w, x, y, z)
    ox = r00 * w0 + r01 * w1 + r02 * w2
    oy = r10 * w0 + r11 * w1 + r12 * w2
    oz = r20 * w0 + r21 * w1 + r22 * w2
    for j in range(bounds[b], bounds[b + 1]):
        i = order[j]
        mj = m[j]
        r0, r1, r2 = r[j, 0], r[j, 1], r[j, 2]
        momenta[i, 0] = mj * (vx + oy * r2 - oz * r1)
        momenta[i, 1] = mj * (vy + oz * r0 - ox * r2)
        momenta[i, 2] = mj * (vz + ox * r1 - oy * r0)


@jit
def momenta(V, q, p, inv_moments, bounds, order, m, r, out):
    """Rigid momenta of all body atoms from the state, as :func:`second_half` writes them."""
    for b in range(V.shape[0]):
        _body_momenta(b, V[b, 0], V[b, 1], V[b, 2], q[b, 0], q[b, 1], q[b, 2], q[b, 3],
                      p[b, 0], p[b, 1], p[b, 2], p[b, 3], inv_moments, bounds, order, m, r, out)


@jit
def place(X, q, d, bounds, order, r, positions):
    """Lab displacements ``r`` and ``positions`` of the body atoms, as in :func:`first_half`."""
    for b in range(X.shape[0]):
        _place_body(b, X, q[b, 0], q[b, 1], q[b, 2], q[b, 3], d, bounds, order, r, positions)


@jit
def largest_angular_speed(q, p, inv_moments):
    """The body turning fastest and its |ω| (rad / ASE time).

    As :func:`rigidmd.core.observables.largest_angular_speed` computes them; (-1, 0.0)
    without bodies."""
    best, best2 = -1, -1.0
    for b in range(q.shape[0]):
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        o1 = 0.5 * (w * p1 - x * p0 - y * p3 + z * p2) * inv_moments[b, 0]
        o2 = 0.5 * (w * p2 - y * p0 - z * p1 + x * p3) * inv_moments[b, 1]
        o3 = 0.5 * (w * p3 - z * p0 - x * p2 + y * p1) * inv_moments[b, 2]
        speed2 = o1 * o1 + o2 * o2 + o3 * o3
        if speed2 > best2:
            best, best2 = b, speed2
    return best, np.sqrt(best2) if best >= 0 else 0.0


@_inline
def _add_mass_outer(out, velocities, masses):
    """``out += sum_i m_i v_i v_i^T`` over the rows, upper triangle only."""
    for i in range(velocities.shape[0]):
        m, v0, v1, v2 = masses[i], velocities[i, 0], velocities[i, 1], velocities[i, 2]
        out[0, 0] += m * v0 * v0
        out[0, 1] += m * v0 * v1
        out[0, 2] += m * v0 * v2
        out[1, 1] += m * v1 * v1
        out[1, 2] += m * v1 * v2
        out[2, 2] += m * v2 * v2


@jit
def kinetic_tensor(V, v, mass, free_masses):
    r""":func:`rigidmd.core.observables.kinetic_tensor_of` in one pass (eV, 3x3).

    :math:`\sum_b M_b V_b\otimes V_b + \sum_\mathrm{free} m\,v\otimes v`."""
    out = np.zeros((3, 3))
    _add_mass_outer(out, V, mass)
    _add_mass_outer(out, v, free_masses)
    out[1, 0], out[2, 0], out[2, 1] = out[0, 1], out[0, 2], out[1, 2]
    return out


@jit
def rotational_energy(q, p, inv_moments):
    r""":func:`rigidmd.core.observables.rotational_kinetic_energy`: :math:`\sum_b \tfrac12 \sum_k
    L_{b,k}^2 / I_k` with :math:`L_b = \tfrac12\,\mathrm{vec}(q^*\otimes p)` (eV)."""
    total = 0.0
    for b in range(q.shape[0]):
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        p0, p1, p2, p3 = p[b, 0], p[b, 1], p[b, 2], p[b, 3]
        l0 = 0.5 * (w * p1 - x * p0 - y * p3 + z * p2)
        l1 = 0.5 * (w * p2 + x * p3 - y * p0 - z * p1)
        l2 = 0.5 * (w * p3 - x * p2 + y * p1 - z * p0)
        total += l0 * l0 * inv_moments[b, 0] + l1 * l1 * inv_moments[b, 1] \
            + l2 * l2 * inv_moments[b, 2]
    return 0.5 * total


@jit
def congruence(F, K):
    r""":math:`F K F^\mathsf{T}` of 3x3 matrices: a kinetic tensor after :math:`V \leftarrow FV`."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            total = 0.0
            for a in range(3):
                row = F[i, a]
                for b in range(3):
                    total += row * K[a, b] * F[j, b]
            out[i, j] = total
    return out


@jit
def net_force(F, f):
    r""":math:`|\sum F + \sum f|` and :math:`\sum |F_{ik}| + \sum |f_{ik}|` (eV/Å): the net
    force of bodies and point particles and the size of the forces, in one pass."""
    s0 = s1 = s2 = size = 0.0
    for forces in (F, f):
        for i in range(forces.shape[0]):
            a, b, c = forces[i, 0], forces[i, 1], forces[i, 2]
            s0 += a
            s1 += b
            s2 += c
            size += abs(a) + abs(b) + abs(c)
    return np.sqrt(s0 * s0 + s1 * s1 + s2 * s2), size


@jit
def intramolecular_virial(r, forces, order):
    r""":func:`rigidmd.core.operators.intramolecular_virial`: the symmetric part of
    :math:`\sum_j r_j\otimes f_{\mathrm{order}[j]}` (eV, 3x3)."""
    w = np.zeros((3, 3))
    for j in range(order.shape[0]):
        i = order[j]
        r0, r1, r2 = r[j, 0], r[j, 1], r[j, 2]
        f0, f1, f2 = forces[i, 0], forces[i, 1], forces[i, 2]
        w[0, 0] += r0 * f0
        w[0, 1] += r0 * f1
        w[0, 2] += r0 * f2
        w[1, 0] += r1 * f0
        w[1, 1] += r1 * f1
        w[1, 2] += r1 * f2
        w[2, 0] += r2 * f0
        w[2, 1] += r2 * f1
        w[2, 2] += r2 * f2
    out = np.empty((3, 3))
    for a in range(3):
        for c in range(3):
            out[a, c] = 0.5 * (w[a, c] + w[c, a])
    return out


@jit
def molecular_virial_voigt(stress, volume, r, forces, order):
    r""":func:`rigidmd.core.observables.molecular_virial` from a stress in Voigt order
    (``xx yy zz yz xz xy``, eV/Å³): :math:`-V\sigma - \mathrm{sym}(R)` (eV, 3x3), the
    same arithmetic as ``-volume * voigt_6_to_full_3x3_stress(stress) -
    intramolecular_virial(r, forces, order)``."""
    w = intramolecular_virial(r, forces, order)
    full = ((0, 5, 4), (5, 1, 3), (4, 3, 2))
    out = np.empty((3, 3))
    for a in range(3):
        for c in range(3):
            out[a, c] = -volume * stress[full[a][c]] - w[a, c]
    return out


@jit
def equal_or_close(a, b, tol):
    """Whether 1-d float arrays ``a`` and ``b`` are close everywhere, as
    ``numpy.allclose(a, b, rtol=tol, atol=tol)`` finds them: each pair equal, or both
    finite and within ``tol`` absolute plus ``tol`` relative to ``b`` (an infinity is
    close only to itself, a NaN to nothing); stops at the first pair that is not
    (:func:`rigidmd.core.checks.changed_properties`)."""
    for i in range(a.shape[0]):
        x, y = a[i], b[i]
        if x != y and not (abs(x - y) <= tol * (1.0 + abs(y))
                           and np.isfinite(x) and np.isfinite(y)):
            return False
    return True


@jit
def smallest_width(cell, pbc):
    """The smallest distance between opposite faces across a periodic cell vector (Å; inf
    without one): :func:`rigidmd.core.bodies.cell_widths`' arithmetic."""
    volume = abs(cell[0, 0] * (cell[1, 1] * cell[2, 2] - cell[1, 2] * cell[2, 1])
                 - cell[0, 1] * (cell[1, 0] * cell[2, 2] - cell[1, 2] * cell[2, 0])
                 + cell[0, 2] * (cell[1, 0] * cell[2, 1] - cell[1, 1] * cell[2, 0]))
    best = np.inf
    for k in range(3):
        if not pbc[k]:
            continue
        a, b = (k + 1) % 3, (k + 2) % 3
        c0 = cell[a, 1] * cell[b, 2] - cell[a, 2] * cell[b, 1]
        c1 = cell[a, 2] * cell[b, 0] - cell[a, 0] * cell[b, 2]
        c2 = cell[a, 0] * cell[b, 1] - cell[a, 1] * cell[b, 0]
        best = min(best, volume / np.sqrt(c0 * c0 + c1 * c1 + c2 * c2))
    return best
