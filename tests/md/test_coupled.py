"""The bases of the dynamics classes (:mod:`rigidmd.md.coupled`), through those classes.

``ThermostattedDynamics`` (RigidLangevin, RigidLangevinBAOAB, RigidBussi, RigidNoseHoover) and
:class:`~rigidmd.md.coupled.BarostattedDynamics` (RigidNPT, RigidCRescale,
RigidMCBarostat) build their parts themselves: what they share is tested once here for
every class, what each adds in ``tests/md/test_<module>.py``.
"""

import numpy as np
import pytest
from ase import units
from helpers import dimer_fluid, npt, waters

from rigidmd import (
    RigidBussi,
    RigidDynamics,
    RigidLangevin,
    RigidLangevinBAOAB,
    RigidNoseHoover,
)
from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.md.coupled import BarostattedDynamics

THERMOSTATTED = {
    "RigidLangevin": lambda atoms, **kw: RigidLangevin(atoms, units.fs, 300, 0.01 / units.fs,
                                                       **kw),
    "RigidLangevinBAOAB": lambda atoms, **kw: RigidLangevinBAOAB(atoms, units.fs, 300,
                                                                 0.01 / units.fs, **kw),
    "RigidBussi": lambda atoms, **kw: RigidBussi(atoms, units.fs, 300, 50 * units.fs, **kw),
    "RigidNoseHoover": lambda atoms, **kw: RigidNoseHoover(atoms, units.fs, 300,
                                                           50 * units.fs, **kw),
}
BAROSTATTED = {"RigidNPT": "mtk", "RigidCRescale": "crescale", "RigidMCBarostat": "mc"}


@pytest.mark.parametrize("name", THERMOSTATTED)
def test_a_thermostatted_class_refuses_parts_of_its_own_in_one_line(name):
    atoms = waters(2)
    before = atoms.positions.copy()
    with pytest.raises(TypeError) as err:
        THERMOSTATTED[name](atoms, couplings=[BussiThermostat(300, 50 * units.fs)])
    assert str(err.value) == (f"{name} builds its own thermostat; use "
                              "RigidDynamics(couplings=...) to compose parts")
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


@pytest.mark.parametrize("name", THERMOSTATTED)
def test_a_thermostatted_class_is_a_dynamics_with_its_one_part(name):
    """``thermostat`` is the one coupling; ``temperature_K`` and ``todict`` are the part's
    (its fields at the top level, and in ``couplings``); ``set_temperature`` reaches it."""
    dyn = THERMOSTATTED[name](waters(2))
    assert isinstance(dyn, RigidDynamics) and not isinstance(dyn, BarostattedDynamics)
    assert dyn.couplings == (dyn.thermostat,)
    assert dyn.temperature_K == dyn.thermostat.temperature_K == 300.0
    described = dyn.todict()
    assert described["md-type"] == name
    assert described["couplings"] == [dyn.thermostat.todict()]
    assert {key: described[key] for key in dyn.thermostat.todict()} == dyn.thermostat.todict()
    dyn.set_temperature(temperature_K=250)
    assert dyn.temperature_K == dyn.thermostat.temperature_K == 250.0


@pytest.mark.parametrize("name", ["RigidLangevin", "RigidLangevinBAOAB", "RigidBussi"])
def test_a_stochastic_thermostat_s_work_starts_at_zero_and_is_the_part_s(name):
    dyn = THERMOSTATTED[name](waters(4), rng=np.random.default_rng(1))
    assert dyn.thermostat_work == 0.0
    dyn.run(5)
    assert dyn.thermostat_work == dyn.thermostat.work != 0.0


@pytest.mark.parametrize("name", BAROSTATTED)
def test_a_barostatted_class_refuses_parts_of_its_own_in_one_line(name):
    atoms = dimer_fluid(n_side=3, rc=5.0)
    with pytest.raises(TypeError) as err:
        npt(atoms, BAROSTATTED[name], couplings=[])
    assert str(err.value) == (f"{name} builds its own thermostat and barostat; use "
                              "RigidDynamics(couplings=...) to compose parts")
    assert atoms.constraints == []


@pytest.mark.parametrize("name", BAROSTATTED)
def test_a_barostatted_class_is_a_dynamics_with_a_thermostat_and_a_barostat(name):
    """Two couplings, thermostat first; the targets are the parts'; ``todict`` nests each
    part's description under its section."""
    dyn = npt(dimer_fluid(n_side=3, rc=5.0), BAROSTATTED[name], pressure=50 * units.bar)
    assert isinstance(dyn, BarostattedDynamics)
    assert dyn.couplings == (dyn.thermostat, dyn.barostat)
    assert (dyn.thermostat.section, dyn.barostat.section) == ("thermostat", "barostat")
    assert dyn.temperature_K == dyn.thermostat.temperature_K == dyn.barostat.temperature_K
    assert dyn.pressure_au == dyn.barostat.pressure_au == 50 * units.bar
    described = dyn.todict()
    assert described["md-type"] == name
    assert described["thermostat"] == dyn.thermostat.todict()
    assert described["barostat"] == dyn.barostat.todict()
    assert described["couplings"] == [dyn.thermostat.todict(), dyn.barostat.todict()]
