"""Rotational (orientational) correlation of molecular axes and relaxation times."""

import numpy as np

from rigidmd.core import quaternion as quat
from rigidmd.mdanalysis._base import (
    AnalysisBase,
    ResidueLayout,
    autocorrelation,
    check_frames,
    finish_figure,
    frame_spacing,
    group_of,
    new_figure,
)
from rigidmd.mdanalysis.topology import atom_charges


def orientational_correlation(vectors, max_lag=None):
    r"""Legendre orientational correlations :math:`C_1(t)`, :math:`C_2(t)`.

    :math:`C_\ell(m) = \langle P_\ell(\mathbf u_i(t) \cdot \mathbf u_i(t+m))
    \rangle_{i,t}` with :math:`P_1(x) = x`, :math:`P_2(x) = (3x^2 - 1)/2`,
    averaged over molecules and all time origins.  Computed by FFT from the
    autocorrelations of the components :math:`u_a` (for :math:`P_1`) and of
    the products :math:`u_a u_b` (for :math:`(\mathbf u \cdot \mathbf u')^2`).

    Parameters
    ----------
    vectors : array_like, shape (n_frames, n_molecules, 3)
        Orientation vectors; normalised here.
    max_lag : int, optional
        Largest lag (frames); default ``n_frames - 1``.

    Returns
    -------
    c1, c2 : numpy.ndarray, shape (max_lag + 1,)
    """
    u = np.asarray(vectors, dtype=float)
    if u.ndim != 3 or u.shape[2] != 3:
        raise ValueError(f"vectors must have shape (n_frames, n_molecules, 3), got {u.shape}")
    norm = np.linalg.norm(u, axis=2, keepdims=True)
    if np.any(norm == 0):
        raise ValueError("an orientation vector has zero length")
    u = u / norm
    n = u.shape[0]
    max_lag = n - 1 if max_lag is None else min(int(max_lag), n - 1)
    c1 = np.zeros(max_lag + 1)
    cos2 = np.zeros(max_lag + 1)
    for a in range(3):
        c1 += autocorrelation(u[:, :, a], max_lag).mean(axis=1)
        for b in range(a, 3):
            weight = 1.0 if a == b else 2.0
            cos2 += weight * autocorrelation(u[:, :, a] * u[:, :, b], max_lag).mean(axis=1)
    return c1, 1.5 * cos2 - 0.5


def relaxation_time(t, c, window=(0.1, 0.5)):
    r"""Relaxation time of a correlation function, by fit and by integral.

    The fit is :math:`\ln C = \ln A - t/\tau` over the points with
    ``window[0] <= C <= window[1]`` before :math:`C` first falls below
    ``window[0]`` (after the fast librational drop, before the noise).  The
    integral is :math:`\int_0^{t_c} C\,dt` (trapezoids) up to that crossing
    :math:`t_c`, plus the fitted exponential's tail :math:`A\tau
    e^{-t_c/\tau}`.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times (ps).
    c : array_like, shape (n,)
    window : (float, float)

    Returns
    -------
    tau_fit, tau_integral, amplitude : float
        ps, ps and dimensionless; NaN when fewer than three points fit the window.
    """
    t = np.asarray(t, dtype=float)
    c = np.asarray(c, dtype=float)
    low, high = window
    below = np.flatnonzero(c < low)
    cut = below[0] if below.size else len(c)
    sel = np.flatnonzero((c[:cut] >= low) & (c[:cut] <= high))
    tau = amplitude = float("nan")
    if sel.size >= 3:
        slope, intercept = np.polyfit(t[sel], np.log(c[sel]), 1)
        if slope < 0:
            tau, amplitude = -1.0 / slope, float(np.exp(intercept))
    end = min(cut, len(c) - 1)
    integral = float(np.sum(0.5 * (c[1:end + 1] + c[:end]) * np.diff(t[:end + 1])))
    if np.isfinite(tau):
        integral += amplitude * tau * np.exp(-t[end] / tau)
    return float(tau), integral, amplitude


def _residue_vectors(positions, layout, charges, kind):
    """Dipole (sum q_i r_i) or heavy-atom-to-centroid vector per residue, shape (n_res, 3)."""
    idx = layout.index
    if kind == "dipole":
        return np.stack([np.bincount(idx, weights=charges * positions[:, k], minlength=layout.n)
                         for k in range(3)], axis=1)
    # "bisector": from the heaviest atom (first if tied) to the centroid of the others.
    m = layout.masses
    order = np.lexsort((np.arange(len(m)), -m, idx))  # by residue, heaviest first
    _, first = np.unique(idx[order], return_index=True)
    heavy = order[first]
    others = np.ones(len(m), dtype=bool)
    others[heavy] = False
    count = np.bincount(idx[others], minlength=layout.n).astype(float)
    if np.any(count == 0):
        raise ValueError("vector='bisector' needs residues of at least two atoms")
    centroid = np.stack([np.bincount(idx[others], weights=positions[others, k],
                                     minlength=layout.n) for k in range(3)], axis=1)
    centroid /= count[:, None]
    return centroid - positions[heavy]


class RotationalCorrelation(AnalysisBase):
    r"""Rotational correlation of a molecular axis (the dipole of water) and its times.

    :math:`C_\ell(t) = \langle P_\ell(\mathbf u(0) \cdot \mathbf u(t))\rangle`
    for :math:`\ell = 1, 2`, with :math:`\mathbf u` the unit vector of each
    selected residue, averaged over residues and time origins
    (:func:`orientational_correlation`), and relaxation times
    :math:`\tau_1, \tau_2` (:func:`relaxation_time`).  For rigid bodies the
    vector is fixed in the body, so this is the correlation of the bodies'
    orientations (:func:`body_dipole_directions` gives the same vectors from
    the quaternions of a running dynamics).

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "resname SOL"
        Whole residues are used.  Residues of one atom (ions) have no
        orientation and are left out; ``results.n_molecules`` counts the
        residues analysed.
    vector : {"auto", "dipole", "bisector"}, default "auto"
        ``"dipole"``: :math:`\sum_i q_i \mathbf r_i` per residue (needs
        charges); ``"bisector"``: from the heaviest atom to the centroid of
        the others (for water, O to the H–H midpoint: the dipole direction);
        ``"auto"``: dipole if every residue has charges giving a nonzero
        dipole, else bisector.
    max_lag : float, optional
        Longest lag (ps), positive; default half the analysed time.
    window : (float, float), default (0.1, 0.5)
        Correlation values fitted by an exponential (see :func:`relaxation_time`).
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase`.

    Attributes
    ----------
    results.times : numpy.ndarray, shape (n_lags,)
        ps.
    results.c1, results.c2 : numpy.ndarray, shape (n_lags,)
    results.tau1, results.tau2 : float
        Exponential-fit relaxation times (ps).
    results.tau1_integral, results.tau2_integral : float
        Integrated relaxation times (ps).
    results.vector : str
        The vector used ("dipole" or "bisector").
    results.n_molecules : int
        Residues analysed.

    Raises
    ------
    ValueError
        No residue of two or more atoms in the selection, or
        ``vector="dipole"`` without charges.
    """

    def __init__(self, universe, select="resname SOL", vector="auto", max_lag=None,
                 window=(0.1, 0.5), **kwargs):
        whole = group_of(universe, select).residues.atoms
        ids, sizes = np.unique(whole.resindices, return_counts=True)
        if not np.any(sizes >= 2):
            raise ValueError(f"RotationalCorrelation: the selection {select!r} holds no molecule "
                             "of two or more atoms (single atoms have no orientation)")
        group = whole[np.isin(whole.resindices, ids[sizes >= 2])]
        super().__init__(group.universe.trajectory, **kwargs)
        if vector not in ("auto", "dipole", "bisector"):
            raise ValueError(f"vector must be 'auto', 'dipole' or 'bisector', got {vector!r}")
        self.group = group
        self._layout = ResidueLayout(group)
        self._charges = (group.charges.astype(float) if hasattr(group, "charges")
                         else np.zeros(len(group)))
        if vector == "auto":
            probe = _residue_vectors(self._layout.whole(group.positions,
                                                        group.universe.trajectory.ts.dimensions),
                                     self._layout, self._charges, "dipole")
            vector = "dipole" if np.all(np.linalg.norm(probe, axis=1) > 1e-6) else "bisector"
        elif vector == "dipole" and not np.any(self._charges):
            raise ValueError("vector='dipole' needs charges; the atoms have none "
                             "(pass charges to to_universe or use vector='bisector')")
        self.vector = vector
        if max_lag is not None and (
                isinstance(max_lag, bool) or not isinstance(max_lag, (int, float, np.number))
                or not np.isfinite(max_lag) or max_lag <= 0):
            raise ValueError(f"RotationalCorrelation: max_lag must be a positive time in ps, "
                             f"got {max_lag!r}")
        self.max_lag = max_lag
        try:
            low, high = (float(v) for v in window)
        except (TypeError, ValueError):
            raise ValueError(f"RotationalCorrelation: window must be two correlation values "
                             f"(low, high), got {window!r}") from None
        if not 0 < low < high <= 1:
            raise ValueError(f"RotationalCorrelation: window must be correlation values with "
                             f"0 < low < high <= 1, got {window!r}")
        self.window = (low, high)

    def _prepare(self):
        check_frames("RotationalCorrelation", self.n_frames, 2)
        self._u = np.zeros((self.n_frames, self._layout.n, 3))

    def _single_frame(self):
        x = self._layout.whole(self.group.positions, self._ts.dimensions)
        self._u[self._frame_index] = _residue_vectors(x, self._layout, self._charges, self.vector)

    def _conclude(self):
        res = self.results
        spacing = frame_spacing(self.times)
        n = self.n_frames
        lag = (n - 1) // 2 if self.max_lag is None else int(round(self.max_lag / spacing))
        if self.max_lag is not None and lag < 1:
            raise ValueError(f"RotationalCorrelation: max_lag {self.max_lag:g} ps is shorter "
                             f"than the time between the frames analysed ({spacing:g} ps); "
                             "give at least that")
        res.c1, res.c2 = orientational_correlation(self._u, max(lag, 0))
        res.times = np.arange(len(res.c1)) * spacing
        res.tau1, res.tau1_integral, res.amplitude1 = relaxation_time(res.times, res.c1,
                                                                      self.window)
        res.tau2, res.tau2_integral, res.amplitude2 = relaxation_time(res.times, res.c2,
                                                                      self.window)
        res.vector = self.vector
        res.n_molecules = self._layout.n

    def plot(self, path=None):
        """Plot C1(t), C2(t) and their exponential fits; save a PNG if ``path``.

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        fig, ax = new_figure()
        low, high = self.window
        for name, c, tau, amp, color in (("C₁", res.c1, res.tau1, res.amplitude1, "C0"),
                                         ("C₂", res.c2, res.tau2, res.amplitude2, "C1")):
            if np.isfinite(tau):
                label = f"{name}(t), τ = {tau:.2f} ps"
                ax.plot(res.times, amp * np.exp(-res.times / tau), color=color, ls=":", lw=1)
            else:
                label = f"{name}(t), no τ: under 3 points with {low:g} ≤ C ≤ {high:g}"
            ax.plot(res.times, c, color=color, label=label)
        ax.axhline(0.0, color="0.7", lw=0.8)
        ax.set_xlabel("t (ps)")
        ax.set_ylabel(rf"$C_\ell(t)$, {res.vector} vector")
        ax.legend(loc="upper right", fontsize=8)
        return finish_figure(fig, path)


def body_dipole_directions(dyn, charges=None):
    r"""Unit dipole direction of every rigid body of a dynamics, from its quaternions.

    The body-frame dipole :math:`\mathbf d_b = \sum_{i \in b} q_i \mathbf d_i`
    (charges times body-frame coordinates) is rotated to the lab frame by the
    body's orientation, :math:`R(q_b)\,\mathbf d_b`.  Attach a recorder to
    collect them during a run and pass the array to
    :func:`orientational_correlation`::

        frames = []
        dyn.attach(lambda: frames.append(body_dipole_directions(dyn)), interval=5)

    Parameters
    ----------
    dyn : RigidVerlet
    charges : array_like, shape (n_atoms,), optional
        e; default the atoms' initial charges.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        Unit vectors.

    Raises
    ------
    ValueError
        A body with no dipole (all charges zero).
    """
    g = dyn.model
    q = atom_charges(dyn.atoms, charges)[g.order]
    d_body = np.stack([np.bincount(g.atom_body, weights=q * g.body_coordinates[:, k],
                                   minlength=g.n_bodies) for k in range(3)], axis=1)
    norm = np.linalg.norm(d_body, axis=1)
    if np.any(norm <= 1e-12):
        b = int(np.flatnonzero(norm <= 1e-12)[0])
        raise ValueError(f"body {b} has no dipole: give charges (e.g. tip3p_charges(atoms))")
    return quat.rotate(dyn.quaternions, d_body / norm[:, None])
