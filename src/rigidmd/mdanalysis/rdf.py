"""Radial distribution functions between selections, intramolecular pairs left out."""

import numpy as np

from rigidmd.core.bodies import cell_widths
from rigidmd.mdanalysis._base import (
    InterRDF,
    check_frames,
    finish_figure,
    group_of,
    new_figure,
)


def _first_shell(bins, rdf, cumulative):
    """First peak (position, height), first minimum and coordination number of g(r)."""
    nan = float("nan")
    above = np.flatnonzero(rdf > 1.0)
    if above.size == 0:
        return nan, nan, nan, nan
    start = above[0]
    below = np.flatnonzero(rdf[start:] < 1.0)
    stop = start + (below[0] if below.size else len(rdf) - start)
    k = start + int(np.argmax(rdf[start:stop]))
    position, height = float(bins[k]), float(rdf[k])
    if 0 < k < len(rdf) - 1:  # parabola through the three highest bins
        y0, y1, y2 = rdf[k - 1], rdf[k], rdf[k + 1]
        denom = y0 - 2 * y1 + y2
        if denom < 0:
            h = bins[1] - bins[0]
            shift = 0.5 * (y0 - y2) / denom
            position = float(bins[k] + shift * h)
            height = float(y1 - 0.25 * (y0 - y2) * shift)
    # First minimum: lowest point after the peak before g(r) climbs back above 1.
    after = np.flatnonzero(rdf[stop:] > 1.0)
    end = stop + (after[0] if after.size else len(rdf) - stop)
    if end <= stop:
        return position, height, nan, nan
    m = stop + int(np.argmin(rdf[stop:end]))
    # The count within the minimum's position, the bin's centre: half-way between the
    # cumulative numbers at its lower and upper edges (cumulative[m] is the upper edge's,
    # half a bin further out: 5 % high with 0.3 Å bins on fcc argon).
    lower = float(cumulative[m - 1]) if m > 0 else 0.0
    return position, height, float(bins[m]), 0.5 * (lower + float(cumulative[m]))


class RadialDistribution(InterRDF):
    r"""Radial distribution function between two selections, e.g. O–O in water.

    A thin layer over :class:`MDAnalysis.analysis.rdf.InterRDF`: pairs inside
    one residue (one rigid body) are excluded and the normalisation counts
    only the pairs that remain, so :math:`g(r) \to 1` at large :math:`r` for
    a selection with one atom per molecule.  After :meth:`run` the results
    also hold the first peak, the first minimum and the coordination number.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "name OW"
        First selection (water oxygens as named by :func:`to_universe`).
    select2 : str, optional
        Second selection; default the first.
    r_max : float, optional
        Largest distance (Å); default 10 Å or half the narrowest width of the
        first frame's box, whichever is smaller.  Rounded down to whole bins.
    bin_width : float, default 0.05
        Å; at most ``r_max``.
    exclude_same_residue : bool, default True
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase` (e.g. ``verbose``).

    Raises
    ------
    ValueError
        A frame without a periodic cell (a cluster has no number density to
        normalise by), an empty selection, an ``r_max`` beyond half the cell's
        narrowest width, or a ``bin_width`` wider than ``r_max``.

    Attributes
    ----------
    results.bins : numpy.ndarray, shape (n_bins,)
        Bin centres (Å).
    results.edges : numpy.ndarray, shape (n_bins + 1,)
    results.rdf : numpy.ndarray, shape (n_bins,)
        :math:`g(r)`.
    results.count : numpy.ndarray, shape (n_bins,)
        Ordered pairs counted per bin, summed over frames.
    results.cumulative_number : numpy.ndarray, shape (n_bins,)
        Mean number of selection-2 atoms within the upper edge of each bin of
        a selection-1 atom.
    results.first_peak_position, results.first_peak_height : float
        Å and dimensionless (parabola through the highest three bins of the
        first region where :math:`g > 1`).
    results.first_minimum_position : float
        Å: the centre of the lowest bin after the first peak.
    results.coordination_number : float
        Neighbours within the first minimum's position (the cumulative number
        interpolated to the bin's centre).
    """

    def __init__(self, universe, select="name OW", select2=None, r_max=None, bin_width=0.05,
                 exclude_same_residue=True, **kwargs):
        taken = sorted({"range", "nbins", "exclude_same"} & set(kwargs))
        if taken:
            raise TypeError(f"RadialDistribution: {', '.join(taken)} is MDAnalysis's InterRDF "
                            "argument; give r_max and bin_width (Å) and exclude_same_residue")
        g1 = group_of(universe, select)
        g2 = g1 if select2 is None else group_of(universe, select2)
        box = g1.universe.trajectory.ts.dimensions
        if box is None:
            raise ValueError("RadialDistribution: g(r) needs a periodic cell (its normalisation "
                             "is the number density), and the first frame has none")
        from ase.cell import Cell

        half = 0.5 * float(cell_widths(Cell.fromcellpar(box).array).min())
        if r_max is None:
            r_max = min(10.0, half)
        for name, value in (("r_max", r_max), ("bin_width", bin_width)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ValueError(f"RadialDistribution: {name} must be a number of Å, got "
                                 f"{value!r}")
        r_max = float(r_max)
        if not (r_max > 0 and bin_width > 0):
            raise ValueError("r_max and bin_width must be positive (Å)")
        if bin_width > r_max:
            raise ValueError(f"RadialDistribution: bin_width {bin_width:g} Å is wider than "
                             f"r_max {r_max:g} Å, so its one bin would reach past r_max; give "
                             "bin_width <= r_max")
        if r_max > half * (1 + 1e-9):
            raise ValueError(f"RadialDistribution: r_max {r_max:g} Å is beyond half the cell's "
                             f"narrowest width ({half:g} Å in the first frame), where the "
                             "minimum image stops counting pairs; give r_max <= that")
        # Whole bins of the requested width, not beyond r_max (the minimum image
        # counts every pair only up to half the box).
        nbins = max(int(np.floor(r_max / bin_width + 1e-9)), 1)
        self._exclude = bool(exclude_same_residue)
        super().__init__(g1, g2, nbins=nbins, range=(0.0, nbins * bin_width),
                         exclude_same="residue" if self._exclude else None, **kwargs)

    def _prepare(self):
        check_frames("RadialDistribution", self.n_frames, 1)
        super()._prepare()

    def _single_frame(self):
        if self._ts.dimensions is None:
            raise ValueError(f"RadialDistribution: frame {self._ts.frame} has no periodic cell; "
                             "g(r) needs one in every frame")
        super()._single_frame()

    def _conclude(self):
        super()._conclude()
        res = self.results
        n1, n2 = len(self.g1), len(self.g2)
        if self._exclude and self.norm == "rdf":
            # Ordered pairs in different residues, instead of MDAnalysis's n1 * n2.
            r1, c1 = np.unique(self.g1.resindices, return_counts=True)
            r2, c2 = np.unique(self.g2.resindices, return_counts=True)
            _, i1, i2 = np.intersect1d(r1, r2, return_indices=True)
            pairs = n1 * n2 - float(np.sum(c1[i1] * c2[i2]))
            res.rdf = res.rdf * (n1 * n2) / pairs if pairs > 0 else res.rdf * np.nan
        res.cumulative_number = np.cumsum(res.count) / (self.n_frames * n1)
        (res.first_peak_position, res.first_peak_height, res.first_minimum_position,
         res.coordination_number) = _first_shell(res.bins, res.rdf, res.cumulative_number)

    def plot(self, path=None, label=None):
        """Plot g(r) and the running coordination number; save a PNG if ``path``.

        Parameters
        ----------
        path : str or os.PathLike, optional
        label : str, optional
            Pair label, e.g. ``"O–O"``; default the elements of the two
            selections (the selection strings when a selection mixes elements).

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        if label is None:
            label = f"{_label(self.g1)}–{_label(self.g2)}"
        fig, ax = new_figure()
        ax.plot(res.bins, res.rdf, color="C0", label=f"g(r) {label}")
        ax.axhline(1.0, color="0.7", lw=0.8)
        if np.isfinite(res.first_peak_position):
            ax.plot([res.first_peak_position], [res.first_peak_height], "o", color="C3",
                    label=f"peak {res.first_peak_position:.2f} Å, {res.first_peak_height:.2f}")
        ax.set_xlabel("r (Å)")
        ax.set_ylabel("g(r)")
        twin = ax.twinx()
        twin.plot(res.bins, res.cumulative_number, color="C2", ls="--", label="n(r)")
        twin.set_ylabel("n(r)")
        handles, labels = ax.get_legend_handles_labels()
        more, more_labels = twin.get_legend_handles_labels()
        ax.legend(handles + more, labels + more_labels, loc="upper right", fontsize=8)
        return finish_figure(fig, path)


def _label(group):
    """The element of a selection, or a short description when it mixes elements."""
    elements = np.unique(group.elements) if hasattr(group, "elements") else []
    if len(elements) == 1:
        return str(elements[0])
    return "+".join(str(e) for e in elements) if len(elements) else "selection"
