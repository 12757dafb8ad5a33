"""Green–Kubo shear viscosity and the stress recorder (rigidmd.mdanalysis.viscosity)."""

import numpy as np
import pytest
from ase import units
from ase.calculators.calculator import all_changes
from helpers import PeriodicLJ, dimer_fluid

from rigidmd.mdanalysis.viscosity import EV_PS_PER_A3_IN_MPA_S, ShearViscosity


# ------------------------------------------------------------- viscosity
def ornstein_uhlenbeck(n, dt, tau, sigma, rng, k=5):
    """k independent OU series (exact discretisation): <x(0)x(t)> = σ² exp(-t/τ)."""
    a = np.exp(-dt / tau)
    noise = rng.normal(0.0, sigma * np.sqrt(1 - a * a), (n, k))
    x = np.empty((n, k))
    x[0] = rng.normal(0.0, sigma, k)
    for i in range(1, n):  # test data only
        x[i] = a * x[i - 1] + noise[i]
    return x


def test_green_kubo_viscosity_of_an_ornstein_uhlenbeck_stress(rng):
    """Five OU components with ∫<P(0)P(t)> = σ²τ: η = V σ² τ / kT, within 3 block errors,
    and the block error within a factor 2 of the spread over independent runs."""
    dt, tau, sigma, volume, temperature = 0.01, 0.3, 1e-4, 6500.0, 298.0
    exact = volume * sigma**2 * tau / (units.kB * temperature) * EV_PS_PER_A3_IN_MPA_S
    estimates, errors = [], []
    for _ in range(4):
        u = ornstein_uhlenbeck(100_000, dt, tau, sigma, rng)
        stress = np.zeros((len(u), 6))
        stress[:, 5], stress[:, 4], stress[:, 3] = u[:, 0], u[:, 1], u[:, 2]
        stress[:, 0], stress[:, 2] = 2 * u[:, 3], -2 * u[:, 4]  # (xx-yy)/2, (yy-zz)/2
        gk = ShearViscosity(stress, volume, temperature, dt, max_lag_ps=4.0,
                            plateau_ps=(2.0, 3.0), blocks=10).run()
        res = gk.results
        assert abs(res.viscosity_mPa_s - exact) < 3 * res.viscosity_stderr_mPa_s
        assert res.acf[0] == pytest.approx(sigma**2, rel=0.05)
        estimates.append(res.viscosity_mPa_s)
        errors.append(res.viscosity_stderr_mPa_s)
    spread = np.std(estimates, ddof=1)
    assert 0.3 < np.mean(errors) / spread < 3.0, (errors, spread)
    assert abs(np.mean(estimates) - exact) < 0.05 * exact


def test_stress_recorder_costs_no_second_calculator_call():
    """Recording the stress every step asks the calculator once per step (stress with the
    forces), not twice: before ``stress_on_observed_steps``, 20 steps made 42 calls."""
    from rigidmd import RigidVerlet
    from rigidmd.mdanalysis import StressRecorder

    class LazyStress(PeriodicLJ):
        """Computes the stress only when asked for it (as LAMMPS does)."""

        def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
            super().calculate(atoms, properties, system_changes)
            if "stress" not in properties:
                del self.results["stress"]

    atoms = dimer_fluid(4)
    calc = atoms.calc = LazyStress(rc=atoms.calc.rc)
    calls = []
    original = calc.calculate
    calc.calculate = lambda *a, **k: (calls.append(1), original(*a, **k))[1]
    dyn = RigidVerlet(atoms, 2 * units.fs)
    recorder = StressRecorder(dyn)
    dyn.attach(recorder, interval=1)
    dyn.run(20)
    assert len(recorder.stress) == 21
    assert len(calls) == 21, len(calls)
    assert np.array_equal(recorder.stress[-1], dyn.get_stress())


def test_a_plateau_between_the_lag_times_is_refused():
    """With a frame every 1 ps, ``plateau_ps=(2.2, 2.8)`` holds no lag time: the viscosity was
    NaN with only NumPy's "Mean of empty slice"."""
    stress = np.random.default_rng(0).normal(size=(5000, 6))
    with pytest.raises(ValueError, match=r"^ShearViscosity: plateau_ps \(2.2, 2.8\) holds none "
                                         r"of the lag times \(0 to 10 ps every 1 ps\)"):
        ShearViscosity(stress, 1000.0, 300.0, 1.0, max_lag_ps=10.0, plateau_ps=(2.2, 2.8))
    one = ShearViscosity(stress, 1000.0, 300.0, 1.0, max_lag_ps=10.0, plateau_ps=(2.2, 3.0))
    assert np.isfinite(one.run().results.viscosity_mPa_s)  # one lag time, 3 ps: taken
