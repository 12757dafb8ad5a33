r"""Compiled loops of the default relaxation, every sum in one fixed order.

The preconditioner :class:`rigidmd.relax.precon.RigidPrecon` and the optimizer
:class:`rigidmd.relax.lbfgs.RigidLBFGS` spend their time here: the weights of
the centres' pair graph from a list of candidate pairs (:func:`pair_graph`),
conjugate gradients on :math:`\mu(L + c\mathbb{1})` (:func:`conjugate_gradient`,
several right-hand sides at once), dot products and updates of vectors
(:func:`dot`, :func:`axpy`).  Each loop
is sequential, with a fixed number of partial sums combined in a fixed
order, and numba compiles it without ``fastmath`` (no reassociation): the
results do not depend on the number of BLAS or OpenMP threads, nor on how
many right-hand sides are solved together.  Measured (CPU time, 1728
centres of SPC/E water, 27 pairs per row): a product with the matrix in
41 µs for three columns and 58 µs for six, against 90 µs for scipy's CSR
product of three; the conjugate gradients of one step of
:class:`~rigidmd.relax.lbfgs.RigidLBFGS` (six columns, 6.3 iterations) in
0.64-0.67 ms (``benchmarks/relax.txt``, the conjugate gradients' tolerances).

The package's compiled loops live here, as every package's do in its ``_numba``
module (the naming rule of :mod:`rigidmd.core.backend`).  Unlike the dynamics'
kernels they have no NumPy reference backend: they are the one implementation
(without numba the same functions run as Python).
"""

import numpy as np

from rigidmd.core._numba import jit

__all__ = ["dot", "axpy", "pair_graph", "cell_list_pairs", "laplacian_product",
           "conjugate_gradient", "orientations", "body_gradient", "largest_angle"]


@jit
def dot(a, b):
    """:math:`a \\cdot b` of two flat float arrays of equal length, four partial sums."""
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for i in range(0, m, 4):
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
    for i in range(m, n):
        s0 += a[i] * b[i]
    return (s0 + s1) + (s2 + s3)


@jit
def axpy(alpha, x, y):
    """``y += alpha * x`` in place, flat float arrays (no temporary)."""
    for i in range(x.shape[0]):
        y[i] += alpha * x[i]


@jit
def pair_graph(centres, cell, first, second, shifts, r_cut, r_nn, decay):
    r"""The weighted graph of the pairs of ``centres`` closer than ``r_cut``, as CSR rows.

    Parameters
    ----------
    centres : numpy.ndarray, shape (m, 3)
        Å.
    cell : numpy.ndarray, shape (3, 3)
        The cell's rows (Å), for the shifts.
    first, second : numpy.ndarray of int, shape (p,)
        Candidate pairs, each once (either order).
    shifts : numpy.ndarray, shape (p, 3)
        Cell shifts of each pair: its vector is ``centres[second] - centres[first] +
        shifts @ cell``.
    r_cut, r_nn, decay : float
        Cut-off and nearest-neighbour distance (Å), :math:`A`:
        :math:`w = \exp(-A\,(r/r_\mathrm{NN} - 1))` for :math:`r < r_\mathrm{cut}`.

    Returns
    -------
    indptr : numpy.ndarray of int, shape (m + 1,)
    indices : numpy.ndarray of int, shape (nnz,)
        Both orders of each pair within ``r_cut``, in the order of the candidates.
    weights : numpy.ndarray, shape (nnz,)
    degree : numpy.ndarray, shape (m,)
        :math:`\sum_j w_{ij}`, summed in row order.
    """
    m, p = centres.shape[0], first.shape[0]
    w = np.zeros(p)
    indptr = np.zeros(m + 1, np.int64)
    for k in range(p):
        i, j = first[k], second[k]
        d2 = 0.0
        s0, s1, s2 = shifts[k, 0], shifts[k, 1], shifts[k, 2]
        if s0 == 0.0 and s1 == 0.0 and s2 == 0.0:  # most pairs: the same sums, less work
            for c in range(3):
                v = centres[j, c] - centres[i, c]
                d2 += v * v
        else:
            for c in range(3):
                v = (centres[j, c] - centres[i, c] + s0 * cell[0, c] + s1 * cell[1, c]
                     + s2 * cell[2, c])
                d2 += v * v
        r = np.sqrt(d2)
        if r < r_cut:
            w[k] = np.exp(-decay * (r / r_nn - 1.0))
            indptr[i + 1] += 1
            indptr[j + 1] += 1
    for i in range(m):
        indptr[i + 1] += indptr[i]
    fill = indptr[:m].copy()
    indices = np.empty(indptr[m], np.int32)
    weights = np.empty(indptr[m])
    for k in range(p):
        if w[k] > 0.0:
            i, j = first[k], second[k]
            indices[fill[i]], weights[fill[i]] = j, w[k]
            fill[i] += 1
            indices[fill[j]], weights[fill[j]] = i, w[k]
            fill[j] += 1
    degree = np.zeros(m)
    for i in range(m):
        for n in range(indptr[i], indptr[i + 1]):
            degree[i] += weights[n]
    return indptr, indices, weights, degree


@jit
def cell_list_pairs(fractional, whole, cell, nbin, periodic, r_list):
    """Pairs of points closer than ``r_list``, each once, with their cell shifts: a cell list.

    The points are sorted by bin; each bin is paired with itself and with 13 of
    its 26 neighbours (the other 13 pair with it from their side), so every pair
    of bins, and so every pair of points, is visited once, over contiguous runs.

    Parameters
    ----------
    fractional : numpy.ndarray, shape (m, 3)
        The points in the cell's coordinates, in ``[0, 1)`` (``[0, 1]`` along an open axis).
    whole : numpy.ndarray, shape (m, 3)
        Whole numbers: the points as given are at ``(fractional + whole) @ cell``.
    cell : numpy.ndarray, shape (3, 3)
        The cell's rows (Å; along an open axis, a box around the points).
    nbin : numpy.ndarray of int, shape (3,)
        Bins per axis, each at least ``r_list`` thick (the planes' spacing over ``nbin``);
        at least 3 along a periodic axis (the 27 bins around a point distinct, one image
        per pair).
    periodic : numpy.ndarray of bool, shape (3,)
    r_list : float
        Å.

    Returns
    -------
    first, second : numpy.ndarray of int, shape (p,)
    shifts : numpy.ndarray, shape (p, 3)
        Whole numbers: ``(fractional[second] + whole[second] - fractional[first]
        - whole[first] + shifts) @ cell`` is the pair's vector.
    """
    m = fractional.shape[0]
    n0, n1, n2 = nbin[0], nbin[1], nbin[2]
    flat = np.empty(m, np.int64)
    for i in range(m):
        b0 = min(max(int(fractional[i, 0] * n0), 0), n0 - 1)
        b1 = min(max(int(fractional[i, 1] * n1), 0), n1 - 1)
        b2 = min(max(int(fractional[i, 2] * n2), 0), n2 - 1)
        flat[i] = (b0 * n1 + b1) * n2 + b2
    order = np.argsort(flat, kind="mergesort")
    start = np.zeros(n0 * n1 * n2 + 1, np.int64)
    for i in range(m):
        start[flat[i] + 1] += 1
    for c in range(len(start) - 1):
        start[c + 1] += start[c]
    x = np.empty((m, 3))  # Cartesian, inside the cell, sorted by bin
    for n in range(m):
        i = order[n]
        for c in range(3):
            x[n, c] = (fractional[i, 0] * cell[0, c] + fractional[i, 1] * cell[1, c]
                       + fractional[i, 2] * cell[2, c])
    # Counted first, then written: no growing arrays in the loop.
    p = _bin_pairs(x, order, whole, start, nbin, periodic, cell, r_list * r_list, None, None,
                   None)
    first, second = np.empty(p, np.int64), np.empty(p, np.int64)
    shifts = np.empty((p, 3))
    _bin_pairs(x, order, whole, start, nbin, periodic, cell, r_list * r_list, first, second,
               shifts)
    return first, second, shifts


@jit
def _bin_pairs(x, order, whole, start, nbin, periodic, cell, r2, first, second, shifts):
    """The pairs of :func:`cell_list_pairs` written to ``first, second, shifts`` (or, with
    None, only counted); returns how many."""
    n0, n1, n2 = nbin[0], nbin[1], nbin[2]
    p = 0
    for home in range(n0 * n1 * n2):
        h0, h1, h2 = home // (n1 * n2), (home // n2) % n1, home % n2
        for d in range(13, 27):  # (0, 0, 0), then the 13 offsets after it in (d0, d1, d2) order
            t0, t1, t2 = h0 + d // 9 - 1, h1 + (d // 3) % 3 - 1, h2 + d % 3 - 1
            w0 = -1.0 if t0 < 0 else (1.0 if t0 >= n0 else 0.0)
            w1 = -1.0 if t1 < 0 else (1.0 if t1 >= n1 else 0.0)
            w2 = -1.0 if t2 < 0 else (1.0 if t2 >= n2 else 0.0)
            if ((w0 != 0.0 and not periodic[0]) or (w1 != 0.0 and not periodic[1])
                    or (w2 != 0.0 and not periodic[2])):
                continue
            target = ((t0 % n0) * n1 + t1 % n1) * n2 + t2 % n2
            o0 = w0 * cell[0, 0] + w1 * cell[1, 0] + w2 * cell[2, 0]
            o1 = w0 * cell[0, 1] + w1 * cell[1, 1] + w2 * cell[2, 1]
            o2 = w0 * cell[0, 2] + w1 * cell[1, 2] + w2 * cell[2, 2]
            for a in range(start[home], start[home + 1]):
                a0, a1, a2 = x[a, 0] - o0, x[a, 1] - o1, x[a, 2] - o2
                for b in range(a + 1 if d == 13 else start[target], start[target + 1]):
                    v0, v1, v2 = x[b, 0] - a0, x[b, 1] - a1, x[b, 2] - a2
                    if v0 * v0 + v1 * v1 + v2 * v2 < r2:
                        if first is not None:
                            i, j = order[a], order[b]
                            first[p], second[p] = i, j
                            shifts[p, 0] = w0 + whole[i, 0] - whole[j, 0]
                            shifts[p, 1] = w1 + whole[i, 1] - whole[j, 1]
                            shifts[p, 2] = w2 + whole[i, 2] - whole[j, 2]
                        p += 1
    return p


@jit
def laplacian_product(indptr, indices, weights, diagonal, x, out, ncol=-1):
    """``out = A x`` for :math:`A = \\mathrm{diag}(d) - W`, ``x`` and ``out`` of shape (m, k).

    Six or three columns at a time, summed in registers (one pass over ``W`` for the two
    vectors of :class:`rigidmd.relax.lbfgs.RigidLBFGS`'s step, whose components they are).
    Only the first ``ncol`` columns when ``ncol >= 0`` (the others are left as they are);
    each column's arithmetic is the same in any block.
    """
    m, k = x.shape
    if ncol >= 0:
        k = ncol
    c0 = 0
    while k - c0 >= 6:
        for i in range(m):
            d = diagonal[i]
            a0, a1, a2 = d * x[i, c0], d * x[i, c0 + 1], d * x[i, c0 + 2]
            a3, a4, a5 = d * x[i, c0 + 3], d * x[i, c0 + 4], d * x[i, c0 + 5]
            for n in range(indptr[i], indptr[i + 1]):
                j, w = indices[n], weights[n]
                a0 -= w * x[j, c0]
                a1 -= w * x[j, c0 + 1]
                a2 -= w * x[j, c0 + 2]
                a3 -= w * x[j, c0 + 3]
                a4 -= w * x[j, c0 + 4]
                a5 -= w * x[j, c0 + 5]
            out[i, c0], out[i, c0 + 1], out[i, c0 + 2] = a0, a1, a2
            out[i, c0 + 3], out[i, c0 + 4], out[i, c0 + 5] = a3, a4, a5
        c0 += 6
    while k - c0 >= 3:
        for i in range(m):
            d = diagonal[i]
            a0, a1, a2 = d * x[i, c0], d * x[i, c0 + 1], d * x[i, c0 + 2]
            for n in range(indptr[i], indptr[i + 1]):
                j, w = indices[n], weights[n]
                a0 -= w * x[j, c0]
                a1 -= w * x[j, c0 + 1]
                a2 -= w * x[j, c0 + 2]
            out[i, c0], out[i, c0 + 1], out[i, c0 + 2] = a0, a1, a2
        c0 += 3
    for c in range(c0, k):
        for i in range(m):
            a = diagonal[i] * x[i, c]
            for n in range(indptr[i], indptr[i + 1]):
                a -= weights[n] * x[indices[n], c]
            out[i, c] = a


@jit
def _precondition(r, inverse, mean_free, z):
    m, k = r.shape
    for c in range(k):
        total = 0.0
        for i in range(m):
            z[i, c] = r[i, c] * inverse[i]
            total += z[i, c]
        if mean_free:
            mean = total / m
            for i in range(m):
                z[i, c] -= mean


@jit
def _column_dots(a, b, out, ncol=-1):
    m, k = a.shape
    if ncol >= 0:
        k = ncol
    for c in range(k):
        out[c] = 0.0
    for i in range(m):
        for c in range(k):
            out[c] += a[i, c] * b[i, c]


@jit
def conjugate_gradient(indptr, indices, weights, diagonal, b, tol, maxiter, mean_free):
    r"""Solve :math:`A x = b` column by column, :math:`A = \mathrm{diag}(d) - W` (CSR ``W``).

    Jacobi-preconditioned conjugate gradients on the columns of ``b`` at
    once; a column stops when :math:`|b - Ax| \le` ``tol`` :math:`|b|`.
    Each column's sums run over the rows in order, whatever the other columns.

    Parameters
    ----------
    indptr, indices, weights : numpy.ndarray
        ``W`` in CSR form (non-negative weights).
    diagonal : numpy.ndarray, shape (m,)
        ``d``, with :math:`d_i > \sum_j W_{ij}` (positive definite).
    b : numpy.ndarray, shape (m, k)
    tol : numpy.ndarray, shape (k,)
        Each column's relative residual.  Columns whose residual is reached stop
        changing, and once every column after the first ``j`` has, the products and
        updates run over the first ``j`` only.
    maxiter : int
    mean_free : bool
        ``b`` has zero column means and ``A`` keeps that subspace (a graph
        Laplacian plus a multiple of 1): iterate in it.

    Returns
    -------
    x : numpy.ndarray, shape (m, k)
    iterations : int
        Products with ``A`` after the first.
    """
    m, k = b.shape
    inverse = 1.0 / diagonal
    x = np.empty((m, k))
    _precondition(b, inverse, mean_free, x)
    r = np.empty((m, k))
    laplacian_product(indptr, indices, weights, diagonal, x, r)
    for i in range(m):
        for c in range(k):
            r[i, c] = b[i, c] - r[i, c]
    z = np.empty((m, k))
    _precondition(r, inverse, mean_free, z)
    p = z.copy()
    ap = np.empty((m, k))
    rz, rr, pap = np.empty(k), np.empty(k), np.empty(k)
    alpha, beta, total = np.empty(k), np.empty(k), np.empty(k)
    target = np.empty(k)
    _column_dots(r, z, rz)
    _column_dots(r, r, rr)
    _column_dots(b, b, target)
    for c in range(k):
        target[c] = tol[c] * np.sqrt(target[c])
    active = np.empty(k, np.bool_)
    iterations = 0
    for _ in range(maxiter):
        kk = 0  # the columns up to the last one still active
        for c in range(k):
            active[c] = np.sqrt(rr[c]) > target[c]
            if active[c]:
                kk = c + 1
        if kk == 0:
            break
        iterations += 1
        laplacian_product(indptr, indices, weights, diagonal, p, ap, kk)
        _column_dots(p, ap, pap, kk)
        for c in range(kk):
            alpha[c] = rz[c] / pap[c] if active[c] and pap[c] > 0 else 0.0
            total[c] = 0.0
        # x += alpha p, r -= alpha A p, z = D^-1 r (and its column sums): one pass.
        for i in range(m):
            for c in range(kk):
                x[i, c] += alpha[c] * p[i, c]
                r[i, c] -= alpha[c] * ap[i, c]
                z[i, c] = r[i, c] * inverse[i]
                total[c] += z[i, c]
        for c in range(kk):
            total[c] = total[c] / m if mean_free else 0.0
            beta[c] = 0.0  # rz_new, then beta
            rr[c] = 0.0
        for i in range(m):
            for c in range(kk):
                z[i, c] -= total[c]
                beta[c] += r[i, c] * z[i, c]
                rr[c] += r[i, c] * r[i, c]
        for c in range(kk):
            rz_new = beta[c]
            beta[c] = rz_new / rz[c] if active[c] and rz[c] > 0 else 0.0
            rz[c] = rz_new
        for i in range(m):
            for c in range(kk):
                p[i, c] = z[i, c] + beta[c] * p[i, c]
    return x, iterations


# ---------------------------------------------------------------- the filter's rows, fused
@jit
def orientations(q_ref, x, lengths, linear, q):
    r"""``q = q_ref ⊗ exp(φ)`` with :math:`\varphi_b = x_b/\ell_b` (0 about a linear body's axis).

    The arithmetic of :meth:`rigidmd.relax.filter.RigidFilter`'s NumPy route
    (:func:`rigidmd.relax.rotationvector.rotation_quaternion` and
    :func:`rigidmd.core.quaternion.multiply`), term for term, in one loop over bodies.

    Parameters
    ----------
    q_ref : numpy.ndarray, shape (n, 4)
    x : numpy.ndarray, shape (n, 3)
        The rotation rows :math:`\ell_b\varphi_b` (Å).
    lengths : numpy.ndarray, shape (n,)
        :math:`\ell_b` (Å).
    linear : numpy.ndarray of bool, shape (n,)
    q : numpy.ndarray, shape (n, 4)
        Filled.
    """
    for b in range(q_ref.shape[0]):
        p0, p1, p2 = _phi(x, lengths, linear, b)
        angle = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        half = 0.5 * angle
        if angle < 1e-4:  # sin(θ/2)/θ by its series
            factor = 0.5 - angle * angle / 48.0
        else:
            factor = np.sin(half) / angle
        rw, rx, ry, rz = np.cos(half), factor * p0, factor * p1, factor * p2
        qw, qx, qy, qz = q_ref[b, 0], q_ref[b, 1], q_ref[b, 2], q_ref[b, 3]
        q[b, 0] = qw * rw - qx * rx - qy * ry - qz * rz
        q[b, 1] = qw * rx + qx * rw + qy * rz - qz * ry
        q[b, 2] = qw * ry - qx * rz + qy * rw + qz * rx
        q[b, 3] = qw * rz + qx * ry - qy * rx + qz * rw


@jit
def largest_angle(x, lengths, linear):
    """The largest :math:`|\\varphi_b|` (rad) of the rotation rows ``x`` (see :func:`orientations`;
    0 without bodies)."""
    largest = 0.0
    for b in range(x.shape[0]):
        p0, p1, p2 = _phi(x, lengths, linear, b)
        largest = max(largest, np.sqrt(p0 * p0 + p1 * p1 + p2 * p2))
    return largest


@jit
def _phi(x, lengths, linear, b):
    length = lengths[b]
    return (0.0 if linear[b] else x[b, 0] / length), x[b, 1] / length, x[b, 2] / length


@jit
def body_gradient(forces, r, order, bounds, q, x, lengths, linear, fixed, F, tau, g):
    r"""Body forces, lab torques and the rotation rows' gradient, in one loop over bodies.

    :math:`F_b = \sum_{i\in b} f_i`, :math:`\tau_b = \sum_{i\in b} r_i\times f_i`
    (summed as NumPy's ``add.reduceat`` sums a short segment: the first term plus
    the sum of the rest, :func:`rigidmd.core.operators.reduce_forces`), and
    :math:`g_b = J_r(\varphi_b)^\mathsf{T} R(q_b)^\mathsf{T}\tau_b/\ell_b`
    (:func:`rigidmd.relax.rotationvector.right_jacobian_transpose`, 0 about a linear
    body's axis), 0 for a fixed body (its force and torque are kept).  The dynamics' fused
    kick (:func:`rigidmd.core._numba.second_half`) sums a body's atoms in order instead; the
    relaxation keeps NumPy's order, as its path follows the last bit (water_box(6), TIP3P
    6 Å, fmax 0.01: -113.3369475 eV in NumPy's order, -113.3369788 eV in order).

    Parameters
    ----------
    forces : numpy.ndarray, shape (n_atoms, 3)
        eV/Å, in atom order.
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements from the centres (Å), in ``order``.
    order, bounds : numpy.ndarray of int
        As in :class:`rigidmd.core.model.BodyModel`.
    q : numpy.ndarray, shape (n, 4)
        The orientations ``r`` was placed with.
    x, lengths, linear :
        As for :func:`orientations`.
    fixed : numpy.ndarray of bool, shape (n,)
    F, tau, g : numpy.ndarray, shape (n, 3)
        Filled: eV/Å, eV (lab frame), eV/Å.
    """
    for b in range(q.shape[0]):
        start, end = bounds[b], bounds[b + 1]
        i = order[start]
        f0, f1, f2 = forces[i, 0], forces[i, 1], forces[i, 2]
        t0 = r[start, 1] * f2 - r[start, 2] * f1
        t1 = r[start, 2] * f0 - r[start, 0] * f2
        t2 = r[start, 0] * f1 - r[start, 1] * f0
        if end - start > 1:
            i = order[start + 1]
            a0, a1, a2 = forces[i, 0], forces[i, 1], forces[i, 2]
            s0 = r[start + 1, 1] * a2 - r[start + 1, 2] * a1
            s1 = r[start + 1, 2] * a0 - r[start + 1, 0] * a2
            s2 = r[start + 1, 0] * a1 - r[start + 1, 1] * a0
            for j in range(start + 2, end):
                i = order[j]
                c0, c1, c2 = forces[i, 0], forces[i, 1], forces[i, 2]
                a0 += c0
                a1 += c1
                a2 += c2
                s0 += r[j, 1] * c2 - r[j, 2] * c1
                s1 += r[j, 2] * c0 - r[j, 0] * c2
                s2 += r[j, 0] * c1 - r[j, 1] * c0
            f0, f1, f2 = f0 + a0, f1 + a1, f2 + a2
            t0, t1, t2 = t0 + s0, t1 + s1, t2 + s2
        F[b, 0], F[b, 1], F[b, 2] = f0, f1, f2
        tau[b, 0], tau[b, 1], tau[b, 2] = t0, t1, t2
        if fixed[b]:
            g[b, 0] = g[b, 1] = g[b, 2] = 0.0
            continue
        # R(q)^T tau = tau + w t + u x t, t = 2 u x tau, u = -(x, y, z) of q.
        w, u0, u1, u2 = q[b, 0], -q[b, 1], -q[b, 2], -q[b, 3]
        c0 = 2.0 * (u1 * t2 - u2 * t1)
        c1 = 2.0 * (u2 * t0 - u0 * t2)
        c2 = 2.0 * (u0 * t1 - u1 * t0)
        v0 = t0 + w * c0 + (u1 * c2 - u2 * c1)
        v1 = t1 + w * c1 + (u2 * c0 - u0 * c2)
        v2 = t2 + w * c2 + (u0 * c1 - u1 * c0)
        # J_r(phi)^T v = v + a phi x v + b phi x (phi x v).
        p0, p1, p2 = _phi(x, lengths, linear, b)
        angle = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        if angle < 1e-3:
            ca = 0.5 - angle * angle / 24.0
            cb = 1.0 / 6.0 - angle * angle / 120.0
        else:
            ca = (1.0 - np.cos(angle)) / (angle * angle)
            cb = (angle - np.sin(angle)) / (angle * angle * angle)
        d0 = p1 * v2 - p2 * v1
        d1 = p2 * v0 - p0 * v2
        d2 = p0 * v1 - p1 * v0
        e0 = p1 * d2 - p2 * d1
        e1 = p2 * d0 - p0 * d2
        e2 = p0 * d1 - p1 * d0
        length = lengths[b]
        g[b, 0] = 0.0 if linear[b] else (v0 + ca * d0 + cb * e0) / length
        g[b, 1] = (v1 + ca * d1 + cb * e1) / length
        g[b, 2] = (v2 + ca * d2 + cb * e2) / length
