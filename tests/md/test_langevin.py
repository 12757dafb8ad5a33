"""RigidLangevin (:mod:`rigidmd.md.langevin`): ASE's ``Langevin`` for rigid bodies.

The part it builds (:class:`~rigidmd.couplings.thermostats.LangevinThermostat`) samples
the canonical ensemble in ``tests/couplings/test_thermostats.py``; here, the class: its
arguments and refusals, the part it composes, a short run's energy bookkeeping and
temperature, its checkpoint.
"""

import inspect

import numpy as np
import pytest
from ase import units
from helpers import (
    CoulombLJ,
    checkpoint_continues,
    free_waters,
    mixture,
    rigid_temperature,
    waters,
)

from rigidmd import RigidLangevin
from rigidmd.couplings.thermostats import LangevinThermostat
from rigidmd.systems import water_cluster


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        ({"temperature_K": -1, "friction": 0.01}, ValueError, "temperature_K"),
        # 10 meant as 10/ps is 1/fs in ASE units: friction * dt = 0.98.
        ({"temperature_K": 300, "friction": 10.0}, ValueError,
         "above 0.5: the velocities would forget themselves within a step"),
        ({"temperature_K": 300, "friction": -0.1}, ValueError, "friction"),
        ({"temperature_K": 300}, TypeError, "needs temperature_K"),
    ],
)
def test_bad_parameters(kwargs, error, match):
    atoms = water_cluster(2)
    before = atoms.positions.copy()
    with pytest.raises(error, match=match):
        RigidLangevin(atoms, 1 * units.fs, **kwargs)
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def test_a_missing_argument_is_named_with_its_unit():
    with pytest.raises(TypeError) as err:
        RigidLangevin(waters(2), units.fs, 300)
    assert str(err.value) == ("RigidLangevin needs temperature_K (K) and friction (per ASE "
                              "time unit); missing: friction")
    with pytest.raises(TypeError, match="missing: temperature_K, friction$"):
        RigidLangevin(waters(2), units.fs)


def test_builds_one_langevin_part_from_ase_s_arguments():
    """ASE's order (atoms, timestep, temperature_K, friction), ``rng`` and ``fixcm`` handed
    to the part; the class reads and changes the part's friction."""
    rng = np.random.default_rng(3)
    dyn = RigidLangevin(waters(2), 2 * units.fs, 300, 0.01 / units.fs, rng=rng, fixcm=False)
    assert type(dyn.thermostat) is LangevinThermostat
    assert dyn.couplings == (dyn.thermostat,)
    assert dyn.thermostat.rng is rng
    assert dyn.thermostat.fixcm_option is False
    assert dyn.temperature_K == 300.0
    assert dyn.friction == 0.01 / units.fs
    dyn.set_friction(0.02 / units.fs)
    assert dyn.friction == dyn.thermostat.friction == 0.02 / units.fs
    with pytest.raises(ValueError, match="the velocities would forget themselves"):
        dyn.set_friction(5.0)  # friction * dt = 0.98
    assert dyn.friction == 0.02 / units.fs
    assert dyn.todict()["kind"] == "langevin"
    assert dyn.todict()["friction"] == 0.02 / units.fs
    assert dyn.todict()["couplings"] == [dyn.thermostat.todict()]


def test_the_work_is_the_kinetic_energy_it_put_in():
    """Free tops: the thermostat is the only source of energy, so its work is the change
    of the kinetic energy and the conserved energy stays (to the rotation's splitting
    error)."""
    atoms = free_waters(8)
    dyn = RigidLangevin(atoms, units.fs, 300, 0.05 / units.fs, rng=np.random.default_rng(1))
    K0, E0 = atoms.get_kinetic_energy(), dyn.get_conserved_energy()
    dyn.run(100)
    work = dyn.thermostat_work
    # Measured: 0.25 eV of work from 250 K to 300 K and noise; 1.8e-6 eV apart.
    assert work > 0.1
    assert atoms.get_kinetic_energy() - K0 == pytest.approx(work, abs=2e-5)
    assert dyn.get_conserved_energy() == pytest.approx(E0, abs=2e-5)


def test_free_tops_come_to_the_target_temperature():
    """64 free waters from 250 K: the mean temperature of steps 100-400 (friction 0.1/fs,
    relaxation time 5 fs) is 300 K within 12 K, 4 standard errors (the temperature's
    standard deviation is 300 K sqrt(2/381) = 22 K, about 60 independent samples).
    Measured with seeds 0-4: 300.0-309.8 K (seed 1: 300.0 K)."""
    atoms = free_waters(64)
    dyn = RigidLangevin(atoms, units.fs, 300, 0.1 / units.fs, rng=np.random.default_rng(1))
    temperatures = []
    dyn.attach(lambda: temperatures.append(rigid_temperature(atoms, 64)))
    dyn.run(400)
    assert np.mean(temperatures[100:]) == pytest.approx(300, abs=12)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(
        lambda: RigidLangevin(mixture(), 2 * units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                              rng=np.random.default_rng(5)), CoulombLJ(), tmp_path / "state.npz")


def test_the_positional_arguments_are_in_ase_s_order():
    """``RigidLangevin(atoms, dt, T, friction, fixcm)`` in the order of ASE's ``Langevin``
    (``rng`` by keyword in both); the third is ``temperature_K`` (K) where ASE's
    positional one is its deprecated ``temperature`` (eV), which the docstring says."""
    from ase.md.langevin import Langevin

    ours = inspect.signature(RigidLangevin.__init__).parameters
    ase = inspect.signature(Langevin.__init__).parameters

    def positional(parameters):
        return [p.name for p in parameters.values() if p.kind is p.POSITIONAL_OR_KEYWORD]

    assert positional(ase) == ["self", "atoms", "timestep", "temperature", "friction", "fixcm"]
    assert positional(ours) == ["self", "atoms", "timestep", "temperature_K", "friction",
                                "fixcm"]
    assert ours["rng"].kind is ase["rng"].kind is inspect.Parameter.KEYWORD_ONLY
    assert "the third is ``temperature_K``, in K, where ASE's is ``temperature`` in eV" in " ".join(
        RigidLangevin.__doc__.split())
    dyn = RigidLangevin(waters(2), units.fs, 300, 0.01 / units.fs, False)
    assert dyn.thermostat.fixcm is False
