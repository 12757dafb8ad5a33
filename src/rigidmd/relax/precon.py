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
the other's scale (see :meth:`RigidPrecon.estimate_mu`).  Every operation is
O(n) in memory and time: the pairs come from a Verlet list (:data:`SKIN`), the weights and the
:math:`n\times n` Laplacian (``n`` centres) from one compiled loop over it
when a centre moved more than ``recompute * r_NN``, and the Laplacian is
solved by conjugate gradients (Jacobi-preconditioned, to a relative
residual of :data:`CG_TOLERANCE`, several right-hand sides at once; a
sparse LU factorisation fills in, 1.3 s for 1728 centres) in the compiled
loops of :mod:`rigidmd.relax._numba`: no dense matrix, no BLAS reduction
whose order depends on the number of threads.
"""

import numpy as np
from ase import Atoms
from ase.neighborlist import neighbor_list
from ase.optimize.precon.precon import Precon
from scipy import sparse

from rigidmd.core.neighbours import tree_nearest, tree_pairs
from rigidmd.relax import _numba

__all__ = ["RigidPrecon", "MU_FLOOR", "CG_TOLERANCE", "SKIN", "MAX_ITERATIONS"]

#: Relative residual at which conjugate gradients stop: a preconditioner need not be
#: exact.  Measured with relax()'s defaults over 21 unrelaxed systems (water_cluster of 8,
#: 16, 24, 32 and 64 molecules, seeds 0-2; water_box of 64, 125 and 216, seeds 0-1; ASE's
#: TIP3P), the scale's solve to the same tolerance, force calls to fmax 0.05 / 0.01 eV/Å
#: summed: 968 / 1882 at 1e-2, 993 / 1851 at 1e-3, and 952-1028 / 1734-1898 over 9e-4,
#: 2e-3, 5e-3 and 2e-2 (the spread of one path's bit-level changes: a relaxation of 1728
#: waters took 225 or 255 steps after a change of one unit in the last place of one
#: coefficient); mean energies within 5e-4 eV/molecule of each other.  At 1728 waters 6.3
#: iterations a solve against 11.3 at 1e-3 (0.69-0.74 against 1.10-1.16 ms CPU a step for
#: the step's two vectors).  All in ``benchmarks/relax.txt`` (``relax.py tolerances``,
#: ``relax.py large 12 none 2000 CG:SCALE``).
CG_TOLERANCE = 1e-2

#: Conjugate-gradient iterations at most per solve (a bound, never reached: at most 7 a
#: solve at 1728 waters with the defaults, 12 at a tolerance of 1e-3).
MAX_ITERATIONS = 10000

#: Skin of the candidate pairs' list, in units of ``r_NN``: pairs within ``r_cut + SKIN r_NN``
#: are listed, and listed again only when a centre moved more than half the skin.
SKIN = 0.5

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
        r_NN`` since the last build (with the cell relaxing: against the
        lattice, plus the strain since the build times ``r_NN``; see
        :meth:`make_precon`).
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
        self._P = None
        self._built_at = None
        self._graph = None  # (indptr, indices, mu * weights, mu * (degree + c_stab))
        self._diag = None
        self._layout = None
        self._listed = None  # (centres, first, second, shifts, cell) of the candidate pairs

    # ------------------------------------------------------------ the matrix
    def _centres(self, view):
        """The centres (Å), shape (m, 3), and the layout of the rows."""
        rows = view.rigid_rows()
        return rows["centres"], rows

    def _cut(self):
        return self.r_cut if self.r_cut is not None else 2.0 * self.r_NN

    def _candidates(self, view, centres):
        r"""Pairs of centres within ``r_cut + skin`` (a Verlet list), listed again only when
        one within ``r_cut`` now might be missing from it.

        Each centre, carried back to the listing's cell by its fractional coordinates, has
        moved at most ``m`` and the cell has deformed by :math:`M = C_0^{-1} C` since
        (:math:`\lVert M - 1\rVert_2 = e`): a pair listed neither way was at least
        ``r_cut + skin`` apart and is now at least ``(r_cut + skin - 2m)(1 - e)``.
        """
        atoms = view.atoms
        cell = atoms.cell.array
        listed = self._listed
        skin = SKIN * self.r_NN
        if listed is not None and len(listed[0]) == len(centres):
            back, strain = centres, 0.0
            if not np.array_equal(listed[4], cell):  # a cell relaxation: periodic, full rank
                back = np.linalg.solve(cell.T, centres.T).T @ listed[4]
                strain = np.linalg.norm(np.linalg.solve(listed[4], cell) - np.eye(3), 2)
            moved = np.sqrt(np.sum((back - listed[0]) ** 2, axis=1).max()) if len(back) else 0
            if (self._cut() + skin - 2.0 * moved) * (1.0 - strain) > self._cut():
                return listed
        points = Atoms(positions=centres, cell=cell, pbc=atoms.pbc)
        i, j, shifts = _pairs(points, self._cut() + skin)
        self._listed = (centres.copy(), i, j, np.ascontiguousarray(shifts, dtype=float),
                        cell.copy())
        return self._listed

    def _assemble(self, view, mu, mu_rot, mu_c):
        centres, rows = self._centres(view)
        atoms = view.atoms
        if self.r_NN is None:
            self.r_NN = _nearest_distance(Atoms(positions=centres, cell=atoms.cell,
                                                pbc=atoms.pbc))
        self._candidates(view, centres)
        self._assemble_at(centres, atoms.cell.array, rows, mu, mu_rot, mu_c)

    def _assemble_at(self, centres, cell, rows, mu, mu_rot, mu_c):
        _, first, second, shifts, _ = self._listed
        indptr, indices, weights, degree = _numba.pair_graph(
            np.ascontiguousarray(centres, dtype=float), cell, first, second, shifts,
            float(self._cut()), float(self.r_NN), self.A)
        self._graph = (indptr, indices, mu * weights, mu * (degree + self.c_stab))
        self._uniform = mu * self.c_stab  # eigenvalue of the uniform translation (L 1 = 0)
        self._diag = (mu_rot * (degree[rows["rotation_centre"]] + self.c_stab), mu_c)
        self._layout = rows
        self._index = tuple(_as_slice(rows[key]) for key in
                            ("translation_rows", "rotation_rows", "cell_rows"))
        self._built_at, self._built_cell = centres.copy(), np.array(cell, dtype=float)
        self._P = None

    @property
    def P(self):
        """:math:`P` as a sparse matrix (scipy CSR, 3n x 3n), built when asked."""
        if self._graph is None:
            return None
        if self._P is None:
            rows, (indptr, indices, weights, diagonal) = self._layout, self._graph
            m = len(diagonal)
            T = (sparse.diags(diagonal)
                 - sparse.csr_matrix((weights, indices, indptr), shape=(m, m)))
            t_rows = rows["translation_rows"]
            index = (3 * t_rows[:, None] + np.arange(3)).ravel()
            T = sparse.kron(T, sparse.identity(3), format="coo")
            n = rows["n_rows"]
            diag = np.zeros(3 * n)
            rot, mu_c = self._diag
            diag[(3 * rows["rotation_rows"][:, None] + np.arange(3)).ravel()] = np.repeat(rot, 3)
            diag[(3 * rows["cell_rows"][:, None] + np.arange(3)).ravel()] = mu_c
            P = sparse.coo_matrix((T.data, (index[T.row], index[T.col])), shape=(3 * n, 3 * n))
            self._P = (P + sparse.diags(diag)).tocsr()
        return self._P

    def make_precon(self, atoms, reinitialize=None):
        r"""Build :math:`P` for the current coordinates of the RigidFilter ``atoms``.

        Estimates the scales first (one extra force call) when not given or
        ``reinitialize``; rebuilds the matrix only when a centre moved more
        than ``recompute * r_NN`` since the last build (the pairs are listed
        again only when one moved more than half of :data:`SKIN` ``* r_NN``
        since they were).  With the cell relaxing, a centre's move is measured
        against the lattice (the change of its fractional coordinates, mapped
        through the current cell) and the cell's strain since the build adds
        its change of a nearest neighbour's distance, :math:`\lVert C_b^{-1}C
        - 1\rVert_2\,r_\mathrm{NN}`: the test is the same for every periodic
        image of a body, so that wrapped and whole molecules relax alike.

        The matrix itself, :attr:`P`, is built only when asked for (what the
        optimizers call, :meth:`solve` and :meth:`Pdot`, do without it).
        """
        view = _view_of(atoms)
        if reinitialize or self.mu is None or self.mu_rot is None or self.mu_c is None:
            self.estimate_mu(view)
            self._built_at = None
        centres, rows = self._centres(view)
        if (self._built_at is not None and len(centres) == len(self._built_at)
                and rows["n_rows"] == self._layout["n_rows"]
                and self._moved_since_built(centres, view.atoms.cell.array)
                < self.recompute * self.r_NN):
            return
        self._assemble(view, self.mu, self.mu_rot, self.mu_c)

    def _moved_since_built(self, centres, cell):
        r"""How far the centres moved against their neighbours since the matrix was built (Å).

        In an unchanged cell the largest distance a centre moved.  In a cell deformed by
        :math:`M = C_b^{-1} C` since the build (a cell relaxation: periodic, full rank), the
        largest move of a centre against the lattice, its fractional coordinates' change
        mapped through the current cell, :math:`\lVert (s - s_b)\,C\rVert`, plus
        :math:`\lVert M - 1\rVert_2\,r_\mathrm{NN}`, what the strain changed the distance to
        a nearest neighbour by: the same for every periodic image of a body (wrapped and
        whole molecules rebuild at the same steps), where the distance moved in the lab
        frame grows with the distance from the origin (a strain moves a far image further).
        """
        built, built_cell = self._built_at, self._built_cell
        if not len(centres):
            return 0.0
        if np.array_equal(built_cell, cell):
            return float(np.sqrt(np.sum((centres - built) ** 2, axis=1).max()))
        shift = (np.linalg.solve(cell.T, centres.T).T
                 - np.linalg.solve(built_cell.T, built.T).T) @ cell
        strain = np.linalg.norm(np.linalg.solve(built_cell, cell) - np.eye(3), 2)
        return float(np.sqrt(np.sum(shift * shift, axis=1).max()) + strain * self.r_NN)

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
        Pv = self.Pdot(v.ravel()).reshape(v.shape)
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
        self._graph = self._P = None
        return tuple(scales)

    # ------------------------------------------------------------ continuing exactly
    def get_state(self):
        """The scales and the centres the matrix and the pair list were built at (dict).

        ``scales`` holds ``mu, mu_rot, mu_c, r_NN`` and ``scales_known`` which of them are
        set: one not yet estimated (a relaxation stopped at step 0) is ``False`` there and 0
        in ``scales``, never NaN, so that every number of the state is finite (a state file
        holding a NaN is refused as damaged, :mod:`rigidmd.relax.optimizerstate`).
        """
        values = (self.mu, self.mu_rot, self.mu_c, self.r_NN)
        state = {"scales": np.array([0.0 if v is None else float(v) for v in values]),
                 "scales_known": np.array([v is not None for v in values])}
        if self._built_at is not None and self._listed is not None:
            state["built_at"], state["built_cell"] = self._built_at.copy(), self._built_cell
            state["listed_at"], state["listed_cell"] = self._listed[0], self._listed[4]
        return state

    def set_state(self, state, atoms):
        """Continue from :meth:`get_state`: the same scales and the same matrix, rebuilt for
        the RigidFilter ``atoms`` (whose rows must be those of the state's)."""
        view = _view_of(atoms)
        scales = np.asarray(state["scales"], dtype=float)
        # A state of an earlier release marked a scale not yet estimated by NaN.
        known = np.asarray(state["scales_known"], dtype=bool) if "scales_known" in state \
            else ~np.isnan(scales)
        if scales.shape != (4,) or known.shape != (4,):
            raise ValueError(f"RigidPrecon.set_state: scales of shape {scales.shape} and "
                             f"scales_known of shape {known.shape}, not (4,)")
        self.mu, self.mu_rot, self.mu_c, self.r_NN = (
            float(v) if k else None for v, k in zip(scales, known, strict=True))
        self._graph = self._P = self._built_at = self._listed = None
        if "built_at" not in state:
            return
        rows = view.rigid_rows()
        listed_at, cell = state["listed_at"], state["listed_cell"]
        points = Atoms(positions=listed_at, cell=cell, pbc=view.atoms.pbc)
        i, j, shifts = _pairs(points, self._cut() + SKIN * self.r_NN)
        self._listed = (listed_at.copy(), i, j, np.ascontiguousarray(shifts, dtype=float),
                        cell.copy())
        self._assemble_at(state["built_at"], state["built_cell"], rows, self.mu, self.mu_rot,
                          self.mu_c)

    # ------------------------------------------------------------ what the optimizers call
    def Pdot(self, x):
        """:math:`P x` for ``x`` of shape (3 n,)."""
        rows = self._layout
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        y = np.empty_like(x)
        t = rows["translation_rows"]
        if len(t):
            out = np.empty((len(t), 3))
            _numba.laplacian_product(*self._graph, np.ascontiguousarray(x[t]), out)
            y[t] = out
        rot, mu_c = self._diag
        y[rows["rotation_rows"]] = x[rows["rotation_rows"]] * rot[:, None]
        y[rows["cell_rows"]] = x[rows["cell_rows"]] * mu_c
        return y.ravel()

    def solve(self, x, tolerances=None):
        """:math:`P^{-1} x` for ``x`` of shape (3 n,), or for each row of ``x`` of shape (k, 3 n).

        The translation block by conjugate gradients (:func:`rigidmd.relax._numba.
        conjugate_gradient`, all right-hand sides at once), the rest diagonal.
        ``tolerances`` (k,): each row's relative residual (None: :data:`CG_TOLERANCE`).
        """
        rows = self._layout
        x = np.asarray(x, dtype=float)
        k = 1 if x.ndim == 1 else len(x)
        x3 = x.reshape(k, -1, 3)
        y = np.empty_like(x3)
        t, r, c = self._index  # slices where the rows are contiguous (views, not copies)
        m = len(rows["translation_rows"])
        if m:
            # The uniform translation is an eigenvector, (L + c) 1 = c 1: solved exactly,
            # and conjugate gradients work on the rest (its smallest eigenvalue, c mu, set
            # the iterations: 23 against 29 without it, 1728 waters, a random right side).
            b = np.ascontiguousarray(x3[:, t, :].transpose(1, 0, 2).reshape(m, 3 * k))
            mean = b.mean(axis=0)
            tol = np.repeat([CG_TOLERANCE if t is None else float(t)
                             for t in (tolerances or [None] * k)], 3)
            solved, _ = _numba.conjugate_gradient(*self._graph, b - mean, tol,
                                                   MAX_ITERATIONS, True)
            solved += mean / self._uniform
            y[:, t, :] = solved.reshape(m, k, 3).transpose(1, 0, 2)
        rot, mu_c = self._diag
        y[:, r] = x3[:, r] / rot[:, None]
        y[:, c] = x3[:, c] / mu_c
        return y.reshape(x.shape)

    def copy(self):
        """A new preconditioner with the same parameters and scales (no matrix)."""
        return RigidPrecon(self.A, self.r_cut, self.r_NN, self.mu, self.mu_rot, self.mu_c,
                           self.c_stab, self.recompute)

    def asarray(self):
        """:math:`P` as a dense array (for tests; O(n²))."""
        return self.P.toarray()


def _as_slice(index):
    """``index`` (whole numbers) as a slice when it is a contiguous increasing run, else as is."""
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def _nearest_distance(points):
    """Median over points of the distance to the nearest other one (Å)."""
    m = len(points)
    if m < 2:
        return 1.0
    nearest = tree_nearest(points.positions, points.cell.array, points.pbc)
    if nearest is not None:
        return float(np.median(nearest))
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
    """Pairs of points within ``r_cut``, each once, all periodic images: ``(i, j, shifts)``.

    The pair's vector is ``positions[j] - positions[i] + shifts @ cell`` (``shifts``
    whole numbers, shape (p, 3)).  A compiled cell list
    (:func:`rigidmd.relax._numba.cell_list_pairs`; 2.4 ms CPU for 1728 centres of
    water, 50,262 pairs within 7.5 Å, against 7.0 ms for scipy's k-d tree and its
    shifts) in a cell periodic in all three directions with its planes at least
    ``3 r_cut`` apart, of any shape (ASE's neighbour list took over 100 ms in a sheared
    one); scipy's k-d tree (:func:`rigidmd.core.neighbours.tree_pairs`) without
    periodicity or in an orthorhombic cell at least ``2 r_cut`` wide; else ASE's
    ``neighbor_list``.  All O(n).
    """
    m = len(points)
    if m < 2:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3), int)
    pbc, cell, positions = points.pbc, points.cell.array, points.positions
    nbin = np.zeros(3, np.int64)
    if pbc.all() and abs(np.linalg.det(cell)) > 0:
        spacing = abs(np.linalg.det(cell)) / np.linalg.norm(
            np.cross(cell[[1, 2, 0]], cell[[2, 0, 1]]), axis=1)
        nbin = np.floor(spacing / r_cut).astype(np.int64)
    if np.any(nbin < 3):
        found = tree_pairs(positions, cell, pbc, r_cut)
        if found is not None:
            return found
        i, j, shifts = neighbor_list("ijS", points, r_cut)
        once = (i < j) | ((i == j) & _positive(shifts))
        return i[once], j[once], shifts[once]
    fractional = np.linalg.solve(cell.T, positions.T).T
    whole = np.floor(fractional)
    inside = fractional - whole
    over = inside >= 1.0  # -1e-17 - floor(-1e-17) rounds to 1
    inside[over], whole[over] = 0.0, whole[over] + 1.0
    # The shifts for the points as given (whole numbers, as floats).
    return _numba.cell_list_pairs(np.ascontiguousarray(inside), whole, np.array(cell, float),
                                   nbin, pbc.copy(), float(r_cut))


def _positive(shifts):
    """Whether each shift is lexicographically positive (one of each pair of opposite images)."""
    first = np.argmax(shifts != 0, axis=1)
    return shifts[np.arange(len(shifts)), first] > 0
