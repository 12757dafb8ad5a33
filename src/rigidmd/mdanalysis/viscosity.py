r"""Shear viscosity by Green–Kubo from the molecular stress a rigid-body run computes.

.. math::
    \eta = \frac{V}{k_B T} \int_0^\infty \langle P_{ab}(0)\, P_{ab}(t) \rangle\, dt

averaged over the five independent traceless components of the pressure
tensor of an isotropic liquid, :math:`P_{xy}, P_{xz}, P_{yz}, (P_{xx} -
P_{yy})/2, (P_{yy} - P_{zz})/2` [1]_.  The pressure is the molecular one
(centres of mass and the forces on them, with their kinetic part:
:meth:`rigidmd.RigidDynamics.get_stress`), which for rigid molecules has the
same shear relaxation as the atomic one with constraint forces.  Record it
with :class:`StressRecorder` during an NVT (weakly thermostatted) or NVE run
at the equilibrium volume.

The components are correlated as they are, without their run's mean taken
off (zero at equilibrium in a liquid; subtracting a finite run's own mean
biases :math:`\eta` low by about :math:`2 t_\mathrm{plateau} / t_\mathrm{run}`).
The running integral :math:`\eta(t)` rises over the stress relaxation time
(about 1 ps in water) and then, in a finite run, wanders as the noise of the
correlation function accumulates.  The estimate is the mean of
:math:`\eta(t)` over a plateau window ``plateau_ps`` (default 2–4 ps for
water: after the relaxation, before the noise dominates), and its error the
standard error of the same estimate over ``blocks`` independent stretches
of the run.

References
----------
.. [1] M. A. González and J. L. F. Abascal, J. Chem. Phys. 132, 096101 (2010)
   (the shear viscosity of rigid water models by Green–Kubo).
"""

from __future__ import annotations

import numpy as np
from ase import units

from rigidmd.mdanalysis._base import PS, autocorrelation
from rigidmd.mdanalysis.thermo import Results

__all__ = ["StressRecorder", "ShearViscosity", "shear_components", "EV_PS_PER_A3_IN_MPA_S"]

#: eV ps / Å³ in mPa s.
EV_PS_PER_A3_IN_MPA_S = 1e30 * 1e-12 * 1e3 / units.J  # 1 / units.J is e in C


class StressRecorder:
    """Observer that records the molecular stress tensor of a rigid dynamics.

    ``dyn.attach(recorder, interval=k)`` records
    ``dyn.get_stress(include_ideal_gas=True)`` (Voigt ``xx yy zz yz xz xy``,
    eV/Å³), the volume and the time every ``k`` steps.  It sets
    ``dyn.stress_on_observed_steps``, so the calculator computes the stress in
    the same call as the forces on those steps (without it, each record costs
    LAMMPS a second evaluation: measured 1.8 to 2.3 times the step time).

    Parameters
    ----------
    dyn : rigidmd.RigidDynamics
        A periodic system whose calculator gives a stress.

    Attributes
    ----------
    stress : numpy.ndarray, shape (n, 6)
    volumes : numpy.ndarray, shape (n,)
        Å³.
    times_ps : numpy.ndarray, shape (n,)
    """

    def __init__(self, dyn):
        self.dyn = dyn
        dyn.stress_on_observed_steps = True  # stress with the forces: one calculator call
        self._stress, self._volume, self._time = [], [], []

    def __call__(self):
        self._stress.append(np.asarray(self.dyn.get_stress(include_ideal_gas=True), float))
        self._volume.append(self.dyn.get_volume())
        self._time.append(self.dyn.get_time() / PS)

    @property
    def stress(self):
        return np.array(self._stress).reshape(-1, 6)

    @property
    def volumes(self):
        return np.array(self._volume)

    @property
    def times_ps(self):
        return np.array(self._time)

    def save(self, path):
        """Write ``stress``, ``volumes`` and ``times_ps`` to an ``.npz`` file."""
        np.savez(path, stress=self.stress, volumes=self.volumes, times_ps=self.times_ps)

    def load(self, path):
        """Append what :meth:`save` wrote (to continue a recording after a restart)."""
        with np.load(path) as data:
            self._stress.extend(data["stress"])
            self._volume.extend(data["volumes"])
            self._time.extend(data["times_ps"])
        return self


def shear_components(stress):
    """The five independent traceless components of a stress series, shape (n, 5).

    Parameters
    ----------
    stress : array_like, shape (n, 6)
        Voigt order ``xx yy zz yz xz xy`` (ASE's); the sign does not matter.
    """
    s = np.asarray(stress, dtype=float)
    if s.ndim != 2 or s.shape[1] != 6:
        raise ValueError(f"stress must have shape (n, 6) in Voigt order, got {s.shape}")
    return np.stack([s[:, 5], s[:, 4], s[:, 3], (s[:, 0] - s[:, 1]) / 2,
                     (s[:, 1] - s[:, 2]) / 2], axis=1)


class ShearViscosity:
    r"""Green–Kubo shear viscosity from a series of stress tensors.

    Parameters
    ----------
    stress : array_like, shape (n_frames, 6)
        eV/Å³, Voigt order, evenly spaced by ``dt_ps``.
    volume : float
        Å³ (the run's, constant in NVT/NVE; the mean otherwise).
    temperature_K : float
        The run's temperature.
    dt_ps : float
        Time between frames (ps); a few fs resolves water's stress
        correlation (its fast librational part decays in tens of fs).
    max_lag_ps : float, default 10
        Longest lag of the correlation function and its integral.
    plateau_ps : (float, float), default (2, 4)
        Window of the running integral whose mean is the viscosity; it must
        hold at least one lag time (a multiple of ``dt_ps``).
    blocks : int, default 5
        Independent stretches for the error (each much longer than
        ``max_lag_ps``).

    Attributes
    ----------
    results.lagtimes : numpy.ndarray, shape (n_lags,)
        ps.
    results.acf : numpy.ndarray, shape (n_lags,)
        :math:`\langle P_{ab}(0) P_{ab}(t)\rangle` averaged over the five
        components, (eV/Å³)².
    results.running_integral : numpy.ndarray, shape (n_lags,)
        :math:`\eta(t)`, mPa s.
    results.viscosity_mPa_s, results.viscosity_stderr_mPa_s : float
    results.block_viscosities_mPa_s : numpy.ndarray, shape (blocks,)
    results.plateau_ps : tuple of float
    """

    def __init__(self, stress, volume, temperature_K, dt_ps, max_lag_ps=10.0,
                 plateau_ps=(2.0, 4.0), blocks=5):
        self.components = shear_components(stress)
        self.volume = float(volume)
        self.temperature_K = float(temperature_K)
        self.dt_ps = float(dt_ps)
        if not (self.volume > 0 and self.temperature_K > 0 and self.dt_ps > 0):
            raise ValueError("ShearViscosity: volume, temperature_K and dt_ps must be positive")
        lo, hi = (float(v) for v in plateau_ps)
        if not 0 <= lo < hi <= max_lag_ps:
            raise ValueError(f"ShearViscosity: plateau_ps {plateau_ps} must lie in "
                             f"[0, max_lag_ps = {max_lag_ps}] with its start before its end")
        self.max_lag = int(round(max_lag_ps / self.dt_ps))
        lags = np.arange(self.max_lag + 1) * self.dt_ps
        if not np.any((lags >= lo) & (lags <= hi)):
            raise ValueError(f"ShearViscosity: plateau_ps {plateau_ps} holds none of the lag "
                             f"times (0 to {lags[-1]:g} ps every {self.dt_ps:g} ps), so there "
                             "is no plateau to average; widen it or record the stress more often")
        self.plateau_ps = (lo, hi)
        self.blocks = int(blocks)
        n = len(self.components)
        if self.blocks < 2 or n // self.blocks <= 2 * self.max_lag:
            raise ValueError(
                f"ShearViscosity: {n} frames make {self.blocks} blocks of "
                f"{n // max(self.blocks, 1)}"
                f" frames, but each must be longer than twice max_lag_ps ({self.max_lag} frames);"
                " record a longer run or shorten max_lag_ps")
        self.results = Results()

    def _integral(self, components):
        # The components' mean is zero in a liquid at equilibrium and is not subtracted: a
        # run's own mean taken off biases η low by about 2 t_plateau / t_run (measured on
        # TIP4P/2005's 500 ps: -25 % in blocks of 25 ps, -7 % in blocks of 100 ps, -1.7 % for
        # the whole run), and its blocks would not average to the whole.
        c = autocorrelation(components, self.max_lag).mean(axis=1)
        kt = units.kB * self.temperature_K
        steps = 0.5 * (c[1:] + c[:-1]) * self.dt_ps
        running = np.concatenate([[0.0], np.cumsum(steps)]) * self.volume / kt
        return c, running * EV_PS_PER_A3_IN_MPA_S

    def _plateau(self, running):
        t = np.arange(len(running)) * self.dt_ps
        lo, hi = self.plateau_ps
        return float(running[(t >= lo) & (t <= hi)].mean())

    def run(self):
        """Compute; returns ``self``."""
        res = self.results
        c, running = self._integral(self.components)
        res.lagtimes = np.arange(len(c)) * self.dt_ps
        res.acf = c
        res.running_integral = running
        res.plateau_ps = self.plateau_ps
        res.viscosity_mPa_s = self._plateau(running)
        per_block = [self._plateau(self._integral(b)[1])
                     for b in np.array_split(self.components, self.blocks)]
        res.block_viscosities_mPa_s = np.array(per_block)
        res.viscosity_stderr_mPa_s = float(np.std(per_block, ddof=1) / np.sqrt(self.blocks))
        return self
