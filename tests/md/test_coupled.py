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


THERMOSTATS = {
    "RigidLangevinBAOAB": lambda a, **kw: RigidLangevinBAOAB(
        a, 2 * units.fs, temperature_K=300, friction=0.01, rng=np.random.default_rng(1), **kw),
    "RigidLangevin": lambda a, **kw: RigidLangevin(
        a, 2 * units.fs, temperature_K=300, friction=0.01, rng=np.random.default_rng(1), **kw),
    "RigidBussi": lambda a, **kw: RigidBussi(
        a, 2 * units.fs, temperature_K=300, taut=50 * units.fs, rng=np.random.default_rng(1),
        **kw),
    "RigidNoseHoover": lambda a, **kw: RigidNoseHoover(
        a, 2 * units.fs, temperature_K=300, tdamp=50 * units.fs, **kw),
}


@pytest.mark.parametrize("name", sorted(THERMOSTATS))
def test_readings_follow_momenta_changed_between_steps(name):
    """New momenta given to the Atoms between runs (or by an observer) are read at the next
    step; until then the kinetic readings are theirs.  Before, T_tr and T_rot (and the
    reported T under a thermostat that holds the momentum or reports after its O step) were
    those of the last step: 210 and 244 K for waters set to 20 K, while the log's Econs
    used the new ones.  Without a change, BAOAB still reports after its O step."""
    from rigidmd import rigid_maxwell_boltzmann
    from rigidmd.core.observables import kinetic_dof, kinetic_temperatures

    atoms = waters(6)
    dyn = THERMOSTATS[name](atoms)
    dyn.run(10)
    if name == "RigidLangevinBAOAB":  # after O, not the end of the step's momenta
        end = kinetic_temperatures(dyn.get_translational_kinetic_energy(),
                                   dyn.get_rotational_kinetic_energy(),
                                   kinetic_dof(dyn.model, dyn.holds_momentum))
        assert not np.allclose(dyn.get_kinetic_temperatures(), end, rtol=1e-6)
    rigid_maxwell_boltzmann(atoms, 20, rng=np.random.default_rng(5))
    fresh = THERMOSTATS[name](atoms.copy())  # reads those momenta at its construction
    fresh.atoms.calc = atoms.calc
    np.testing.assert_allclose(dyn.get_kinetic_temperatures(), fresh.get_kinetic_temperatures(),
                               rtol=1e-9)
    np.testing.assert_allclose(dyn.get_reported_kinetic_energy(),
                               fresh.get_reported_kinetic_energy(), rtol=1e-9)
    assert max(dyn.get_kinetic_temperatures()) < 60


@pytest.mark.parametrize("make, message", [
    (lambda a: RigidLangevinBAOAB(a, units.fs, temperature_K=True, friction=0.01),
     "temperature_K must be a number"),
    (lambda a: RigidLangevinBAOAB(a, units.fs, temperature_K=300, friction=True),
     "friction must be a number"),
    (lambda a: RigidLangevinBAOAB(a, units.fs, temperature_K=300, T_tau=True),
     "T_tau must be a time"),
    (lambda a: RigidLangevinBAOAB(a, units.fs, temperature_K=300, T_tau=1e-320),
     "T_tau 1e-320 .ASE units. is too small: its inverse, the friction"),
    (lambda a: RigidBussi(a, units.fs, temperature_K=300, taut=True), "taut must be a time"),
    (lambda a: RigidNoseHoover(a, units.fs, temperature_K=300, tdamp=True),
     "tdamp must be a time"),
    (lambda a: RigidLangevin(a, units.fs, temperature_K=300, friction=0.01).set_temperature(
        temperature=0.0258), "give temperature_K= .K., not temperature="),
    (lambda a: RigidLangevin(a, units.fs, temperature_K=300, friction=0.01).set_temperature(
        True), "temperature_K must be a number"),
    (lambda a: RigidLangevin(a, units.fs, temperature_K=300, friction=0.01).set_friction(
        True), "friction must be a number"),
])
def test_a_bool_or_an_ambiguous_temperature_is_refused(make, message):
    """A bool was read as 1 (1 K, a friction of 1 per ASE time, a T_tau of 1); ASE's
    thermostats read ``set_temperature(temperature=x)`` in eV (Langevin) or K
    (NVTBerendsen), and rigidmd read K: refused, naming ``temperature_K``."""
    with pytest.raises((TypeError, ValueError), match=message) as err:
        make(waters(3))
    assert "\n" not in str(err.value)
