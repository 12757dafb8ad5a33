"""Mean-squared displacement and self-diffusion coefficients."""

import warnings

import numpy as np

from rigidmd.mdanalysis._base import (
    ANGSTROM2_PER_PS_IN_CM2_PER_S,
    AnalysisBase,
    ResidueLayout,
    autocorrelation,
    check_frames,
    finish_figure,
    frame_spacing,
    group_of,
    new_figure,
    unwrap_series,
)


def mean_squared_displacement(x):
    r"""Multiple-origin mean-squared displacement of unwrapped trajectories (FFT).

    :math:`\mathrm{MSD}(m) = \langle |x(t+m) - x(t)|^2 \rangle_t`, averaged
    over all time origins, computed as :math:`S_1(m) - 2 S_2(m)` with
    :math:`S_2` the position autocorrelation (by FFT) and :math:`S_1` from
    cumulative sums of :math:`|x|^2`.

    Parameters
    ----------
    x : array_like, shape (n_frames, n_particles, d)
        Unwrapped positions (Å).

    Returns
    -------
    numpy.ndarray, shape (n_frames, n_particles)
        Å², lag 0 to ``n_frames - 1`` frames.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 3:
        raise ValueError(f"positions must have shape (n_frames, n_particles, d), got {x.shape}")
    n = x.shape[0]
    x = x - x.mean(axis=0)  # the MSD does not change; roundoff does
    sq = np.sum(x * x, axis=2)  # (n, p)
    cum = np.concatenate([np.zeros((1,) + sq.shape[1:]), np.cumsum(sq, axis=0)])
    m = np.arange(n)
    s1 = (cum[n - m] + cum[n] - cum[m]) / (n - m)[:, None]
    s2 = autocorrelation(x, n - 1).sum(axis=2)
    return np.maximum(s1 - 2.0 * s2, 0.0)


#: Yeh & Hummer's constant ξ for a cubic box (J. Phys. Chem. B 108, 15873 (2004)).
YEH_HUMMER_XI = 2.837297


def yeh_hummer_correction(temperature_K, viscosity_mPa_s, box_length_A):
    r"""Finite-size correction of a diffusion coefficient in a cubic periodic box (Å²/ps).

    :math:`D_\infty = D_\mathrm{PBC} + \xi k_B T / (6 \pi \eta L)`, ξ = 2.837297
    (Yeh & Hummer, J. Phys. Chem. B 108, 15873 (2004)).  η must be the model's own
    shear viscosity (measured, or its published value), not real water's.

    Parameters
    ----------
    temperature_K : float
    viscosity_mPa_s : float
        The model's shear viscosity (mPa s).
    box_length_A : float
        Edge of the cubic box (Å).

    Returns
    -------
    float
        The term to add to :math:`D_\mathrm{PBC}`, Å²/ps (1e-4 of it in cm²/s).
    """
    if not (temperature_K > 0 and viscosity_mPa_s > 0 and box_length_A > 0):
        raise ValueError("yeh_hummer_correction: temperature_K, viscosity_mPa_s and "
                         "box_length_A must be positive")
    kt = 1.380649e-23 * temperature_K  # J
    d = YEH_HUMMER_XI * kt / (6 * np.pi * viscosity_mPa_s * 1e-3 * box_length_A * 1e-10)  # m²/s
    return float(d * 1e8)  # 1 m²/s = 1e20 Å² / 1e12 ps


#: Largest |α - 1| of MSD ∝ t^α in the fit window for which a diffusion coefficient is given.
#: Liquid water after 1 ps gives α within 0.05 of 1; the ballistic regime gives 2.
MAX_EXPONENT_DEVIATION = 0.25


def msd_exponent(t, msd):
    """Exponent α of MSD ∝ t^α: the slope of log MSD against log t (NaN without two points).

    Parameters
    ----------
    t : array_like, shape (n,)
        Lag times (any unit; points with t <= 0 or MSD <= 0 are left out).
    msd : array_like, shape (n,)
    """
    t = np.asarray(t, dtype=float)
    msd = np.asarray(msd, dtype=float)
    keep = (t > 0) & (msd > 0)
    if np.count_nonzero(keep) < 2:
        return float("nan")
    return float(np.polyfit(np.log(t[keep]), np.log(msd[keep]), 1)[0])


class MeanSquaredDisplacement(AnalysisBase):
    r"""Mean-squared displacement and self-diffusion coefficient.

    Follows molecules by their centres of mass (``compound="residues"``, each
    residue made whole first) or single atoms (``compound="atoms"``).  The
    positions of rigidmd runs are unwrapped already; with ``unwrap=True``
    (default) any jump of more than half a box between frames is undone, so
    wrapped trajectories work too (sample often enough that nothing moves
    half a box between frames).  The diffusion coefficient comes from a
    straight-line fit :math:`\mathrm{MSD} = 2 d\, D\, t + c` over
    ``fit_range``, given only where the MSD is linear there: the exponent
    :math:`\alpha` of :math:`\mathrm{MSD} \propto t^\alpha` must be within
    0.25 of 1 (a run too short to leave the ballistic regime has
    :math:`\alpha \approx 2`).

    A drift of the whole system adds :math:`V_\mathrm{cm}^2 t^2` to the MSD.
    Stochastic thermostats (Langevin) leave the system with a random total
    momentum of thermal size, which over tens of picoseconds moves the centre
    by more than the molecules diffuse: zero the total momentum before the
    production run, or pass ``remove_com_motion=True``.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "all"
    compound : {"residues", "atoms"}, default "residues"
    msd_type : {"xyz", "xy", "yz", "xz", "x", "y", "z"}, default "xyz"
        Cartesian components included; :math:`d` is their number.
    unwrap : bool, default True
    remove_com_motion : bool, default False
        Subtract, frame by frame, the displacement of the mass-weighted centre
        of the selection.
    fit_range : (float, float), optional
        Lag times (ps) of the linear fit.  Default: 10 % to 40 % of the
        longest lag (the first excludes the ballistic and caging regime,
        the second the noisy long lags).
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase`.

    Raises
    ------
    ValueError
        A selection whose residues (``compound="residues"``) or whose atoms
        (``remove_com_motion=True``) have no mass, such as the massless M
        sites of a four-site water (``"name MW"``): no centre of mass.

    Attributes
    ----------
    results.lagtimes : numpy.ndarray, shape (n_frames,)
        ps.
    results.timeseries : numpy.ndarray, shape (n_frames,)
        MSD (Å²), averaged over particles.
    results.msds_by_particle : numpy.ndarray, shape (n_frames, n_particles)
        Å².
    results.diffusion_coefficient : float
        Å²/ps; NaN (with a warning) when the MSD is not linear in the fit
        window (see ``results.msd_exponent``).
    results.msd_exponent : float
        α of MSD ∝ t^α fitted in the window (1 for diffusion, 2 for
        ballistic motion).
    results.diffusive : bool
        Whether ``|α - 1| <= 0.25``, the condition for a diffusion coefficient.
    results.diffusion_coefficient_cm2_s : float
        cm²/s.
    results.fit_range : tuple of float
        ps.
    results.fit_slope, results.fit_intercept : float
        Å²/ps and Å².
    """

    _AXES = {"xyz": [0, 1, 2], "xy": [0, 1], "yz": [1, 2], "xz": [0, 2],
             "x": [0], "y": [1], "z": [2]}

    def __init__(self, universe, select="all", compound="residues", msd_type="xyz",
                 unwrap=True, remove_com_motion=False, fit_range=None, **kwargs):
        group = group_of(universe, select)
        super().__init__(group.universe.trajectory, **kwargs)
        if compound not in ("residues", "atoms"):
            raise ValueError(f"compound must be 'residues' or 'atoms', got {compound!r}")
        if msd_type not in self._AXES:
            raise ValueError(f"msd_type must be one of {sorted(self._AXES)}, got {msd_type!r}")
        self.group = group
        self.compound = compound
        self.msd_type = msd_type
        self.dim_fac = len(self._AXES[msd_type])
        self.unwrap = bool(unwrap)
        self.remove_com_motion = bool(remove_com_motion)
        if fit_range is not None:
            try:
                lo, hi = (float(v) for v in fit_range)
            except (TypeError, ValueError):
                raise ValueError(f"MeanSquaredDisplacement: fit_range must be two lag times "
                                 f"(ps), (start, end), got {fit_range!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
                raise ValueError(f"MeanSquaredDisplacement: fit_range must be lag times with "
                                 f"0 <= start < end (ps), got {fit_range!r}")
            fit_range = (lo, hi)
        self.fit_range = fit_range
        self._layout = ResidueLayout(group) if compound == "residues" else None
        if self._layout is not None and np.any(self._layout.mass <= 0):
            k = int(np.flatnonzero(self._layout.mass <= 0)[0])
            residue = group.residues[k]
            raise ValueError(
                f"MeanSquaredDisplacement: the selection {select!r} holds no mass in residue "
                f"{residue.resid} ({residue.resname}), whose centre of mass is then undefined; "
                "select atoms with mass (e.g. the whole molecules) or give compound='atoms'")
        if self.remove_com_motion and self._layout is None and not np.sum(group.masses) > 0:
            raise ValueError(
                f"MeanSquaredDisplacement: the selection {select!r} has no mass, so "
                "remove_com_motion has no centre of mass to remove; select atoms with mass "
                "or give remove_com_motion=False")

    def _prepare(self):
        check_frames("MeanSquaredDisplacement", self.n_frames, 2)
        n = self._layout.n if self._layout is not None else len(self.group)
        self._x = np.zeros((self.n_frames, n, 3))
        self._boxes = np.zeros((self.n_frames, 6))
        self._has_box = True

    def _single_frame(self):
        box = self._ts.dimensions
        positions = self.group.positions
        if self._layout is not None:
            positions = self._layout.centres_of_mass(self._layout.whole(positions, box))
        self._x[self._frame_index] = positions
        if box is None:
            self._has_box = False
        else:
            self._boxes[self._frame_index] = box

    def _conclude(self):
        res = self.results
        spacing = frame_spacing(self.times)
        x = self._x
        if self.unwrap and self._has_box:
            x = unwrap_series(x, self._boxes)
        if self.remove_com_motion:
            w = self._layout.mass if self._layout is not None else self.group.masses
            centre = np.einsum("p,fpk->fk", w, x) / np.sum(w)
            x = x - (centre - centre[0])[:, None, :]
        x = x[:, :, self._AXES[self.msd_type]]
        res.msds_by_particle = mean_squared_displacement(x)
        res.timeseries = res.msds_by_particle.mean(axis=1)
        res.lagtimes = np.arange(self.n_frames) * spacing
        t_max = res.lagtimes[-1]
        lo, hi = (0.1 * t_max, 0.4 * t_max) if self.fit_range is None else self.fit_range
        res.fit_range = (float(lo), float(hi))
        window = (res.lagtimes >= lo) & (res.lagtimes <= hi)
        if self.fit_range is not None and np.count_nonzero(window) < 2:
            warnings.warn(
                f"MeanSquaredDisplacement: fit_range ({lo:g}, {hi:g}) ps holds "
                f"{np.count_nonzero(window)} of the lag times (0 to {t_max:g} ps every "
                f"{spacing:g} ps), so the diffusion coefficient is NaN; give a fit_range "
                "within them", RuntimeWarning, stacklevel=2)
            res.fit_slope = res.fit_intercept = res.msd_exponent = float("nan")
            res.diffusive = False
            res.diffusion_coefficient = res.diffusion_coefficient_cm2_s = float("nan")
            return
        if np.count_nonzero(window) >= 2:
            slope, intercept = np.polyfit(res.lagtimes[window], res.timeseries[window], 1)
        else:
            slope = intercept = float("nan")
        res.fit_slope, res.fit_intercept = float(slope), float(intercept)
        res.msd_exponent = msd_exponent(res.lagtimes[window], res.timeseries[window])
        res.diffusive = bool(abs(res.msd_exponent - 1.0) <= MAX_EXPONENT_DEVIATION)
        if not res.diffusive:
            warnings.warn(
                f"MeanSquaredDisplacement: MSD grows as t^{res.msd_exponent:.2f} between "
                f"{lo:.3g} and {hi:.3g} ps, not linearly (ballistic motion gives 2, caging less "
                "than 1), so the diffusion coefficient is NaN; analyse a longer run or choose "
                "fit_range where the MSD is linear", RuntimeWarning, stacklevel=2)
            slope = float("nan")
        res.diffusion_coefficient = float(slope) / (2 * self.dim_fac)
        res.diffusion_coefficient_cm2_s = res.diffusion_coefficient * ANGSTROM2_PER_PS_IN_CM2_PER_S

    def finite_size_corrected(self, temperature_K, viscosity_mPa_s):
        """:math:`D_\\infty` (Å²/ps): the fitted D plus :func:`yeh_hummer_correction`.

        The box edge is the mean over the frames of the cube root of the
        volume (the correction is for cubic boxes).

        Parameters
        ----------
        temperature_K : float
        viscosity_mPa_s : float
            The model's shear viscosity (measured or published).
        """
        boxes = self._boxes
        if not self._has_box:
            raise ValueError("finite_size_corrected: the trajectory has no periodic box")
        from ase.geometry import cellpar_to_cell

        volumes = [abs(np.linalg.det(cellpar_to_cell(box))) for box in boxes]
        length = float(np.mean(np.cbrt(volumes)))
        return self.results.diffusion_coefficient + yeh_hummer_correction(
            temperature_K, viscosity_mPa_s, length)

    def plot(self, path=None):
        """Plot MSD(t) with the fitted line; save a PNG if ``path``.

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        fig, ax = new_figure()
        ax.plot(res.lagtimes, res.timeseries, color="C0", label="MSD")
        lo, hi = res.fit_range
        t = np.array([0.0, res.lagtimes[-1]])
        if res.diffusive:
            ax.plot(t, res.fit_intercept + res.fit_slope * t, color="C3", ls="--",
                    label=f"D = {res.diffusion_coefficient_cm2_s * 1e5:.2f}e-5 cm²/s")
            window = "fit window"
        else:
            window = f"not diffusive here: MSD ∝ t^{res.msd_exponent:.2f}, no D"
        ax.axvspan(lo, hi, color="C3", alpha=0.1, lw=0, label=window)
        ax.set_xlabel("lag time (ps)")
        ax.set_ylabel("MSD (Å²)")
        ax.legend(loc="upper left", fontsize=8)
        return finish_figure(fig, path)
