r"""A preconditioner for rigid bodies: :class:`RigidPrecon`, for ASE's preconditioned optimizers.

ASE's :class:`~ase.optimize.precon.Exp` preconditioner models the Hessian of
a condensed system of atoms as a weighted graph Laplacian of its pairs,
:math:`P = \mu\,(L + c_\mathrm{stab}\mathbb{1})` with pair weights
:math:`w_{ij} = \exp(-A\,(r_{ij}/r_\mathrm{NN} - 1))` within :math:`r_\mathrm{cut}`
(Packwood et al., J. Chem. Phys. 144, 164109 (2016)).  :class:`RigidPrecon`
does the same for the rows of :class:`rigidmd.relax.filter.RigidFilter`:

=====================  ==============================================================
rows                   block of :math:`P`
=====================  ==============================================================
centres of mass and    :math:`\mu_t\,(L + c_\mathrm{stab}\mathbb{1}) \otimes \mathbb{1}_3`,
free atoms             the Laplacian of the pairs of centres (and free atoms)
rotations              :math:`\mu_r\,(\mathrm{diag}_i \sum_j w_{ij} + c_\mathrm{stab})
                       \otimes \mathbb{1}_3`
cell (3 rows)          :math:`\mu_c\,\mathbb{1}_9`
=====================  ==============================================================

The rotation rows are already lengths (:math:`\ell_b\varphi_b`, Å, the
body's rotation read as the displacement of an atom at its typical radius),
so a body's rotational stiffness scales, like its translational one, with
how many neighbours it touches.  The three scales
:math:`\mu_t, \mu_r, \mu_c` are estimated as ASE estimates :math:`\mu`: one
extra force call at a smooth perturbation :math:`v` of the coordinates,

.. math:: \mu_k = \frac{\sum_{i \in k} v_i\,(g(x + v) - g(x))_i}
                       {\sum_{i \in k} v_i\,(P_1 v)_i}

summed over the rows ``k`` of each kind (:math:`P_1` the preconditioner
with unit scales, :math:`g` the gradient), each capped below at
:data:`MU_FLOOR`.  A start near a saddle can show a block no positive
curvature along :math:`v`; that block (translation or rotation) then takes
the other's scale (see :meth:`RigidPrecon.estimate_mu`).  Every operation is a sparse product: the
:math:`n\times n` Laplacian (``n`` centres) is solved by conjugate gradients
(Jacobi-preconditioned, to a relative residual of :data:`CG_TOLERANCE`;
a sparse LU factorisation fills in, 1.3 s for 1728 centres), every sum in
numpy's own order: O(n) memory and time per solve, no dense matrix, no BLAS
reduction whose order depends on the number of threads.
"""

import numpy as np
from ase import Atoms
from ase.neighborlist import neighbor_list
from ase.optimize.precon.precon import Precon
from scipy import sparse

__all__ = ["RigidPrecon", "MU_FLOOR", "conjugate_gradient", "CG_TOLERANCE"]

#: Relative residual at which :func:`conjugate_gradient` stops: a preconditioner need not be
#: exact (measured over 8- and 16-water clusters, 3 seeds each: 167 and 278 force calls to
#: fmax 0.05 and 0.01 against 167 and 277 at 1e-10, half the iterations).
CG_TOLERANCE = 1e-6

#: Smallest scale :math:`\mu` estimated (eV/Å²); a smaller one is noise of a flat start.
MU_FLOOR = 0.05


def _view_of(atoms):
    """The :class:`~rigidmd.relax.filter.RigidFilter` behind what an optimizer passes."""
    view = getattr(atoms, "rigid_rows", None)
    if view is None:
        raise TypeError("RigidPrecon: works on a rigidmd.relax.filter.RigidFilter, got "
                        f"{type(atoms).__name__}; wrap the atoms in RigidFilter(atoms)")
    return atoms


class RigidPrecon(Precon):
    r"""Exp-like preconditioner on the rows of a :class:`~rigidmd.relax.filter.RigidFilter`.

    Pass it to ASE's :class:`~ase.optimize.precon.PreconLBFGS` or
    :class:`~ase.optimize.precon.PreconFIRE` (``precon=RigidPrecon()``) with
    a ``RigidFilter`` as the atoms; :func:`rigidmd.relax.filter.relax` uses it by default.

    Parameters
    ----------
    A : float, default 3.0
        Decay of the pair weights (dimensionless), as ASE's ``Exp``.
    r_cut : float, optional
        Pair cut-off between centres (Å); default ``2 r_NN``.
    r_NN : float, optional
        Nearest-neighbour distance between centres (Å); default the median
        over centres of the distance to the nearest other one.
    mu, mu_rot, mu_c : float, optional
        Scales of the translation, rotation and cell blocks (eV/Å²; the cell
        block's in the cell rows' units); estimated on the first
        :meth:`make_precon` when None.
    c_stab : float, default 0.1
        Added to the diagonal (dimensionless), as ASE's.
    recompute : float, default 0.1
        The matrix is rebuilt when a centre moved more than ``recompute *
        r_NN`` since the last build.
    """

    def __init__(self, A=3.0, r_cut=None, r_NN=None, mu=None, mu_rot=None, mu_c=None,
                 c_stab=0.1, recompute=0.1):
        for name, value in (("A", A), ("c_stab", c_stab), ("recompute", recompute)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"RigidPrecon: {name}={value!r} must be >= 0")
        for name, value in (("r_cut", r_cut), ("r_NN", r_NN), ("mu", mu), ("mu_rot", mu_rot),
                            ("mu_c", mu_c)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"RigidPrecon: {name}={value!r} must be positive")
        self.A, self.r_cut, self.r_NN = float(A), r_cut, r_NN
        self.mu, self.mu_rot, self.mu_c = mu, mu_rot, mu_c
        self.c_stab, self.recompute = float(c_stab), float(recompute)
        self.P = None
        self._built_at = None
        self._translation = self._jacobi = None
        self._diag = None
        self._layout = None

    # ------------------------------------------------------------ the matrix
    def _centres(self, view):
        """The centres (Å), shape (m, 3), and the layout of the rows."""
        rows = view.rigid_rows()
        return rows["centres"], rows

    def _graph(self, view, centres):
        """Laplacian ``L`` (sparse, m x m) and weighted degrees of the centres' pairs."""
        atoms = view.atoms
        m = len(centres)
        points = Atoms(positions=centres, cell=atoms.cell, pbc=atoms.pbc)
        if self.r_NN is None:
            self.r_NN = _nearest_distance(points)
        r_cut = self.r_cut if self.r_cut is not None else 2.0 * self.r_NN
        i, j, d = _pairs(points, r_cut)
        w = np.exp(-self.A * (d / self.r_NN - 1.0))
        W = sparse.coo_matrix((w, (i, j)), shape=(m, m)).tocsr()
        degree = np.asarray(W.sum(axis=1)).ravel()
        return sparse.diags(degree) - W, degree

    def _assemble(self, view, mu, mu_rot, mu_c):
        centres, rows = self._centres(view)
        L, degree = self._graph(view, centres)
        m = len(centres)
        translation = (mu * (L + self.c_stab * sparse.identity(m))).tocsc()
        rot = mu_rot * (degree[rows["rotation_centre"]] + self.c_stab)
        self._layout = rows
        self._translation = translation.tocsr()
        self._jacobi = translation.diagonal()
        self._uniform = mu * self.c_stab  # eigenvalue of the uniform translation (L 1 = 0)
        self._diag = (rot, mu_c)
        self._built_at = centres.copy()
        n = rows["n_rows"]
        # The full matrix (3n x 3n), for Pdot and asarray.
        t_rows = rows["translation_rows"]
        index = (3 * t_rows[:, None] + np.arange(3)).ravel()
        T = sparse.kron(translation, sparse.identity(3), format="coo")
        diag = np.zeros(3 * n)
        r_rows = rows["rotation_rows"]
        diag[(3 * r_rows[:, None] + np.arange(3)).ravel()] = np.repeat(rot, 3)
        c_rows = rows["cell_rows"]
        diag[(3 * c_rows[:, None] + np.arange(3)).ravel()] = mu_c
        P = sparse.coo_matrix((T.data, (index[T.row], index[T.col])), shape=(3 * n, 3 * n))
        self.P = (P + sparse.diags(diag)).tocsr()

    def make_precon(self, atoms, reinitialize=None):
        """Build :math:`P` for the current coordinates of the RigidFilter ``atoms``.

        Estimates the scales first (one extra force call) when not given or
        ``reinitialize``; rebuilds the matrix only when a centre moved more
        than ``recompute * r_NN`` since the last build.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (3 len(atoms), 3 len(atoms))
        """
        view = _view_of(atoms)
        if reinitialize or self.mu is None or self.mu_rot is None or self.mu_c is None:
            self.estimate_mu(view)
            self._built_at = None
        centres, rows = self._centres(view)
        if (self._built_at is not None and len(centres) == len(self._built_at)
                and rows["n_rows"] == self._layout["n_rows"]):
            moved = np.sqrt(np.sum((centres - self._built_at) ** 2, axis=1))
            if not len(moved) or moved.max() < self.recompute * self.r_NN:
                return self.P
        self._assemble(view, self.mu, self.mu_rot, self.mu_c)
        return self.P

    def estimate_mu(self, atoms, H=None):
        r"""Estimate :math:`\mu_t, \mu_r, \mu_c` from one force call at a perturbation.

        The perturbation: :math:`10^{-2} r_\mathrm{NN}\,\sin\phi_k` in each
        component ``k`` of the centres' rows, with :math:`\phi_k = x_k/L_k`
        (:math:`L_k` the extent of the centres along ``k``) or, along a
        periodic cell vector, :math:`\phi_k = 2\pi s_k` (:math:`s_k` the
        centre's fractional coordinate: a field continuous across the cell's
        boundary and the same for every periodic image of a body, so that
        wrapped and whole molecules relax alike); the same field on the
        rotation rows, and a strain of :math:`10^{-2}` on the cell rows.
        The view is moved back afterwards (its forces at the start are kept,
        no further call).

        Where one of the translation and rotation blocks shows no curvature
        above :data:`MU_FLOOR` along the field and the other does, the first
        takes the second's scale: both blocks' rows are lengths, and their
        Hessian diagonals agree where there is a minimum (mean 2.55 and 2.61
        eV/Å² over 18 rows each at a minimum of 64 TIP3P waters, 2.3 and
        1.9-3.6 in a 32-water cluster), while a start near a saddle (water
        molecules turned at random on a lattice: mean rotational diagonal
        -0.45 eV/Å² in ``water_box(4)``) would leave the rotations at the
        floor, ten times softer than at the minimum (benchmarks/relax.txt:
        fewer force calls and lower minima on boxes of 64 and 216 waters).

        Parameters
        ----------
        atoms : rigidmd.relax.filter.RigidFilter
        H : None
            Accepted for ASE's signature; must be None.

        Returns
        -------
        tuple of float
            ``(mu, mu_rot, mu_c)``.
        """
        if H is not None:
            raise ValueError("RigidPrecon.estimate_mu: H is not used; leave it None")
        view = _view_of(atoms)
        x = view.get_positions()
        g0 = -view.get_forces()
        centres, rows = self._centres(view)
        if self.r_NN is None and len(centres) > 1:
            self.r_NN = _nearest_distance(Atoms(positions=centres, cell=view.atoms.cell,
                                                pbc=view.atoms.pbc))
        if self.r_NN is None:
            self.r_NN = 1.0
        extent = np.ptp(centres, axis=0) if len(centres) else np.ones(3)
        extent = np.where(extent > 1e-8, extent, 1.0)
        phase = centres / extent
        pbc = view.atoms.pbc
        if len(centres) and pbc.any():
            fractional = np.linalg.solve(view.atoms.cell.array.T, centres.T).T
            phase = np.where(pbc, 2.0 * np.pi * fractional, phase)
        v = np.zeros_like(x)
        field = 1e-2 * self.r_NN * np.sin(phase)
        v[rows["translation_rows"]] = field
        v[rows["rotation_rows"]] = field[rows["rotation_centre"]]
        v[rows["cell_rows"]] = 1e-2 * view.cell_factor
        v[view.fixed_rows()] = 0.0
        view.set_positions(x + v)
        g1 = -view.get_forces()
        view.restore(x)
        dg = g1 - g0
        self._assemble(view, 1.0, 1.0, 1.0)
        Pv = self.P.dot(v.ravel()).reshape(v.shape)
        lhs, rhs = dg * v, Pv * v
        scales = []
        for key in ("translation_rows", "rotation_rows", "cell_rows"):
            which = rows[key]
            num, den = np.sum(lhs[which]), np.sum(rhs[which])
            mu = num / den if den > 0 else MU_FLOOR
            scales.append(float(max(mu, MU_FLOOR)) if np.isfinite(mu) else MU_FLOOR)
        mu, mu_rot = scales[:2]
        if mu_rot <= MU_FLOOR < mu:  # no rotational curvature along the field: a saddle
            scales[1] = mu
        elif mu <= MU_FLOOR < mu_rot:
            scales[0] = mu_rot
        self.mu, self.mu_rot, self.mu_c = scales
        self.P = None
        return tuple(scales)

    # ------------------------------------------------------------ what the optimizers call
    def Pdot(self, x):
        """:math:`P x` for ``x`` of shape (3 n,)."""
        return self.P.dot(x)

    def solve(self, x):
        """:math:`P^{-1} x` for ``x`` of shape (3 n,): the Laplacian's LU, the rest diagonal."""
        rows = self._layout
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        y = np.empty_like(x)
        t = rows["translation_rows"]
        if len(t):
            # The uniform translation is an eigenvector, (L + c) 1 = c 1: solved exactly,
            # and conjugate gradients work on the rest (its smallest eigenvalue, c mu, set
            # the iterations: 23 against 29 without it, 1728 waters, a random right side).
            b = x[t]
            mean = b.mean(axis=0)
            y[t] = conjugate_gradient(self._translation, b - mean, self._jacobi,
                                      mean_free=True) + mean / self._uniform
        rot, mu_c = self._diag
        y[rows["rotation_rows"]] = x[rows["rotation_rows"]] / rot[:, None]
        y[rows["cell_rows"]] = x[rows["cell_rows"]] / mu_c
        return y.ravel()

    def copy(self):
        """A new preconditioner with the same parameters and scales (no matrix)."""
        return RigidPrecon(self.A, self.r_cut, self.r_NN, self.mu, self.mu_rot, self.mu_c,
                           self.c_stab, self.recompute)

    def asarray(self):
        """:math:`P` as a dense array (for tests; O(n²))."""
        return self.P.toarray()


def _nearest_distance(points):
    """Median over points of the distance to the nearest other one (Å)."""
    m = len(points)
    if m < 2:
        return 1.0
    radius = 3.0
    while True:
        i, d = neighbor_list("id", points, radius)
        nearest = np.full(m, np.inf)
        np.minimum.at(nearest, i, d)
        if np.all(np.isfinite(nearest)) or radius > 100.0:
            finite = nearest[np.isfinite(nearest)]
            return float(np.median(finite)) if len(finite) else 1.0
        radius *= 2.0


def _pairs(points, r_cut):
    """Pairs (i, j, distance) of points within ``r_cut``, both orders, all periodic images.

    A k-d tree (scipy's ``cKDTree``) without periodicity or in an orthorhombic
    cell at least ``2 r_cut`` wide (one image per pair), else ASE's
    ``neighbor_list``; both O(n).
    """
    from scipy.spatial import cKDTree

    m = len(points)
    if m < 2:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    pbc, cell = points.pbc, points.cell.array
    orthorhombic = np.allclose(cell, np.diag(np.diag(cell)))
    lengths = np.diag(cell)
    if not pbc.any():
        tree = cKDTree(points.positions)
    elif pbc.all() and orthorhombic and np.all(lengths > 2 * r_cut):
        wrapped = np.mod(points.positions, lengths)
        wrapped[wrapped >= lengths] = 0.0  # -1e-17 mod L rounds to L, outside the box
        tree = cKDTree(wrapped, boxsize=lengths)
    else:
        return neighbor_list("ijd", points, r_cut)
    pairs = tree.sparse_distance_matrix(tree, r_cut, output_type="coo_matrix")
    keep = pairs.row != pairs.col
    return pairs.row[keep], pairs.col[keep], pairs.data[keep]


def conjugate_gradient(A, b, diagonal, tol=CG_TOLERANCE, maxiter=10000, mean_free=False):
    """Solve :math:`A x = b` for a sparse symmetric positive definite ``A``, column by column.

    Jacobi-preconditioned conjugate gradients on the columns of ``b`` at
    once; every sum in numpy's own order (the same result with any number
    of threads).

    Parameters
    ----------
    A : scipy.sparse.csr_matrix, shape (m, m)
    b : numpy.ndarray, shape (m, k)
    diagonal : numpy.ndarray, shape (m,)
        The diagonal of ``A`` (positive).
    tol : float
        Relative residual :math:`|b - Ax| / |b|` per column at which to stop.
    mean_free : bool
        ``b`` has zero column means and ``A`` keeps that subspace (a graph
        Laplacian plus a multiple of 1): iterate in it (the preconditioned
        residual's column means removed).

    Returns
    -------
    numpy.ndarray, shape (m, k)
    """
    inverse = (1.0 / diagonal)[:, None]

    def precondition(r):
        z = r * inverse
        return z - z.mean(axis=0) if mean_free else z

    x = precondition(b)
    r = b - A @ x
    z = precondition(r)
    p = z.copy()
    rz = np.sum(r * z, axis=0)
    target = tol * np.sqrt(np.sum(b * b, axis=0))
    for _ in range(maxiter):
        active = np.sqrt(np.sum(r * r, axis=0)) > target
        if not active.any():
            break
        Ap = A @ p
        pAp = np.sum(p * Ap, axis=0)
        alpha = np.where(active, rz / np.where(pAp > 0, pAp, 1.0), 0.0)
        x += alpha * p
        r -= alpha * Ap
        z = precondition(r)
        rz_new = np.sum(r * z, axis=0)
        beta = np.where(active, rz_new / np.where(rz > 0, rz, 1.0), 0.0)
        p = z + beta * p
        rz = rz_new
    return x
