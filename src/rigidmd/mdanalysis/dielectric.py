r"""Static dielectric constant from the total dipole fluctuations, with its error.

With conducting (tin-foil) boundary conditions, which Ewald and PPPM
sums impose,

.. math::
    \varepsilon = 1 + \frac{\langle \mathbf M^2\rangle - \langle \mathbf M\rangle^2}
                          {3 V \varepsilon_0 k_B T},
    \qquad \mathbf M = \sum_i q_i \mathbf r_i .

MDAnalysis's :class:`MDAnalysis.analysis.dielectric.DielectricConstant`
computes exactly this, and fits rigid water as rigidmd writes it: charges
come from the topology (:func:`~rigidmd.mdanalysis.to_universe` sets them,
the massless M sites included), the molecules are whole and neutral, so
:math:`\mathbf M` is the sum of the molecular dipoles whether positions are
wrapped or unwrapped (its ``make_whole`` unwraps molecules over their bonds,
which ``to_universe`` adds).  What it lacks is an error:
:class:`DielectricConstant` here is MDAnalysis's, recording
:math:`\mathbf M` every frame, with a jackknife error over blocks of the run
(the fluctuation is a non-linear estimator, so a plain block average of
per-block ε would be biased low for short blocks).  The dipole decorrelates
slowly (about 10 ps in water), so ε converges slowly: for a Gaussian
:math:`\mathbf M` with correlation time :math:`\tau_M` the relative error
of :math:`\varepsilon - 1` after a run of length :math:`t` is about
:math:`\sqrt{4\tau_M/(3t)}` (12 % after 1 ns of 216 waters).
"""

from __future__ import annotations

import numpy as np
from ase import units

from rigidmd.mdanalysis._base import require_mdanalysis
from rigidmd.mdanalysis.thermo import COULOMB

try:
    from MDAnalysis.analysis.dielectric import DielectricConstant as _MDADielectric
except ImportError:  # pragma: no cover - MDAnalysis missing
    _MDADielectric = object

__all__ = ["DielectricConstant", "dielectric_from_dipoles"]

#: Vacuum permittivity in e² / (eV Å).
EPSILON0 = 1.0 / (4 * np.pi * COULOMB)


def dielectric_from_dipoles(M, volume, temperature_K):
    r"""ε from total dipoles :math:`\mathbf M` (e Å, shape (n, 3)), V (Å³) and T (K)."""
    M = np.asarray(M, dtype=float)
    fluct = np.sum(np.mean(M * M, axis=0) - np.mean(M, axis=0) ** 2)
    return float(1.0 + fluct / (3 * volume * EPSILON0 * units.kB * temperature_K))


class DielectricConstant(_MDADielectric):
    """MDAnalysis's ``DielectricConstant`` with the dipole series and a jackknife error.

    Parameters
    ----------
    atomgroup : MDAnalysis.core.groups.AtomGroup
        Neutral molecules with charges (e.g. ``to_universe(...).atoms``).
    temperature : float, default 300
        K, as MDAnalysis names it.
    make_whole : bool, default True
        Passed on (whole molecules need no unwrapping; False is faster).
    blocks : int, default 10
        Blocks of the jackknife error.
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase`.

    Attributes
    ----------
    results.eps_mean : float
        ε (MDAnalysis's, the mean of its three directions).
    results.eps_stderr : float
        Jackknife standard error over ``blocks``.
    results.dipoles : numpy.ndarray, shape (n_frames, 3)
        :math:`\\mathbf M` per frame, e Å.
    results.volumes : numpy.ndarray, shape (n_frames,)
        Å³.
    """

    def __init__(self, atomgroup, temperature=300, make_whole=True, blocks=10, **kwargs):
        require_mdanalysis()
        if isinstance(temperature, bool) or not isinstance(temperature, (int, float,
                                                                          np.number)) \
                or not (np.isfinite(temperature) and temperature > 0):
            raise ValueError(f"DielectricConstant: temperature must be a positive number of "
                             f"kelvin, got {temperature!r}")
        if isinstance(blocks, bool) or not isinstance(blocks, (int, np.integer)) or blocks < 2:
            raise ValueError(f"DielectricConstant: blocks must be a whole number >= 2 (the "
                             f"jackknife's), got {blocks!r}")
        charges = getattr(atomgroup, "charges", None)
        if charges is None or not np.any(np.asarray(charges) != 0):
            raise ValueError("DielectricConstant: the atoms' charges are all zero (a topology "
                             "without charges), so ε would read 1; give them, e.g. "
                             "to_universe(..., charges=...) or the atoms' initial charges")
        super().__init__(atomgroup, temperature=temperature, make_whole=make_whole, **kwargs)
        self.blocks = int(blocks)

    def _prepare(self):
        super()._prepare()
        self._dipoles = []
        self._volumes = []

    def _single_frame(self):
        super()._single_frame()
        group = self.atomgroup
        self._dipoles.append(group.charges.astype(float) @ group.positions.astype(float))
        self._volumes.append(group.universe.trajectory.ts.volume)

    def _conclude(self):
        super()._conclude()
        res = self.results
        res.dipoles = np.array(self._dipoles)
        res.volumes = np.array(self._volumes)
        res.eps_stderr = jackknife_error(res.dipoles, res.volumes.mean(), self.temperature,
                                         self.blocks)


def jackknife_error(M, volume, temperature_K, blocks=10):
    """Jackknife standard error of :func:`dielectric_from_dipoles` over ``blocks`` blocks."""
    M = np.asarray(M, dtype=float)
    if blocks < 2 or len(M) < 2 * blocks:
        return float("nan")
    parts = np.array_split(np.arange(len(M)), blocks)
    leave_out = np.array([dielectric_from_dipoles(np.delete(M, p, axis=0), volume, temperature_K)
                          for p in parts])
    return float(np.sqrt((blocks - 1) / blocks * np.sum((leave_out - leave_out.mean()) ** 2)))
