"""RigidBussi (:mod:`rigidmd.md.bussi`): ASE's ``Bussi`` for rigid bodies.

The part it builds (:class:`~rigidmd.couplings.thermostats.BussiThermostat`) samples the
canonical ensemble in ``tests/couplings/test_thermostats.py``; here, the class: its
arguments and refusals, the part it composes, a short run, its checkpoint.
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

from rigidmd import RigidBussi
from rigidmd.core import operators as ops
from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.systems import water_cluster


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        ({"temperature_K": 300, "taut": 0}, ValueError, "taut must be a positive"),
        ({"temperature_K": 300, "taut": 100, "fixcm": "yes"}, TypeError,
         "fixcm must be True or False"),
    ],
)
def test_bad_parameters(kwargs, error, match):
    atoms = water_cluster(2)
    before = atoms.positions.copy()
    with pytest.raises(error, match=match):
        RigidBussi(atoms, 1 * units.fs, **kwargs)
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def test_a_missing_argument_is_named_with_its_unit():
    with pytest.raises(TypeError) as err:
        RigidBussi(waters(2), units.fs, 300)
    assert str(err.value) == ("RigidBussi needs temperature_K (K) and taut (ASE time units); "
                              "missing: taut")


def test_builds_one_bussi_part_from_ase_s_arguments():
    """ASE's order (atoms, timestep, temperature_K, taut); ``rng`` and ``fixcm`` to the part."""
    rng = np.random.default_rng(3)
    dyn = RigidBussi(waters(2), units.fs, 300, 100 * units.fs, rng=rng, fixcm=True)
    assert type(dyn.thermostat) is BussiThermostat
    assert dyn.couplings == (dyn.thermostat,)
    assert dyn.thermostat.rng is rng
    assert dyn.thermostat.fixcm_option is True
    assert (dyn.temperature_K, dyn.taut) == (300.0, 100 * units.fs)
    assert dyn.todict()["kind"] == "bussi"
    assert dyn.todict()["taut"] == 100 * units.fs
    assert dyn.todict()["couplings"] == [dyn.thermostat.todict()]


def test_one_factor_scales_every_velocity_and_one_every_angular_momentum():
    """Free tops, total momentum left in (``fixcm=False``): a step multiplies every centre
    of mass velocity by one factor and every angular momentum (in the lab frame, which
    the free rotation keeps) by another (the part rescales the translational and the
    rotational kinetic energies each), and the work is the kinetic energy they put in."""
    atoms = free_waters(8)
    dyn = RigidBussi(atoms, units.fs, 300, 20 * units.fs, rng=np.random.default_rng(1),
                     fixcm=False)
    V0, L0 = dyn.state.V.copy(), ops.lab_angular_momentum(dyn.state.q, dyn.state.p)
    K0 = atoms.get_kinetic_energy()
    dyn.run(1)
    L = ops.lab_angular_momentum(dyn.state.q, dyn.state.p)
    alpha, beta = dyn.state.V[0, 0] / V0[0, 0], L[0, 0] / L0[0, 0]
    # Measured: 1.047 and 0.971 (the thermostat did act); each the same for every body
    # to 2.2e-16 and 7.6e-16 relative (roundoff); bounds 1e-14.
    assert abs(alpha - 1) > 1e-3 and abs(beta - 1) > 1e-3 and abs(alpha - beta) > 1e-3
    np.testing.assert_allclose(dyn.state.V, alpha * V0, rtol=1e-14)
    np.testing.assert_allclose(L, beta * L0, rtol=0, atol=1e-14 * np.abs(L0).max())
    # Measured: 3.5e-6 relative apart (the rotation's splitting error); bound 2e-5.
    assert atoms.get_kinetic_energy() - K0 == pytest.approx(dyn.thermostat_work, rel=2e-5)


def test_free_tops_come_to_the_target_temperature():
    """64 free waters from 250 K (taut 10 fs): the mean temperature of steps 100-400 is
    300 K within 12 K, 4 standard errors (as tests/md/test_langevin.py's).  Measured with
    seeds 0-4: 299.6-306.9 K (seed 1: 301.1 K)."""
    atoms = free_waters(64)
    dyn = RigidBussi(atoms, units.fs, 300, 10 * units.fs, rng=np.random.default_rng(1))
    temperatures = []
    dyn.attach(lambda: temperatures.append(rigid_temperature(atoms, 64)))
    dyn.run(400)
    assert np.mean(temperatures[100:]) == pytest.approx(300, abs=12)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(
        lambda: RigidBussi(mixture(), 2 * units.fs, 300, 50 * units.fs, bodies="mol-id",
                           rng=np.random.default_rng(5)), CoulombLJ(), tmp_path / "state.npz")


def test_the_positional_arguments_are_ase_s():
    """``RigidBussi(atoms, dt, T, taut, rng)`` reads as ASE's ``Bussi(atoms, dt, T, taut,
    rng)``, ``rng`` by keyword as well; ``fixcm``, which ASE's has not, by keyword only."""
    from ase.md.bussi import Bussi

    ours = inspect.signature(RigidBussi.__init__).parameters
    ase = inspect.signature(Bussi.__init__).parameters
    positional = [p.name for p in ours.values() if p.kind is p.POSITIONAL_OR_KEYWORD]
    assert positional == [p.name for p in ase.values() if p.kind is p.POSITIONAL_OR_KEYWORD]
    assert positional == ["self", "atoms", "timestep", "temperature_K", "taut", "rng"]
    assert ours["rng"].default is ase["rng"].default is None
    assert ours["fixcm"].kind is inspect.Parameter.KEYWORD_ONLY
    rng = np.random.default_rng(4)
    by_position = RigidBussi(waters(2), units.fs, 300, 100 * units.fs, rng)
    by_name = RigidBussi(waters(2), units.fs, temperature_K=300, taut=100 * units.fs, rng=rng)
    assert by_position.thermostat.rng is by_name.thermostat.rng is rng
