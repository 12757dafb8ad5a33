"""The coupling parts' interface (rigidmd.core.coupling): the registry, the generators'
state, what a dynamics may compose, the export of parts, and the one target temperature
of a dynamics.  Built-in parts serve as the examples."""

import numpy as np
import pytest
from ase import units
from helpers import waters

from rigidmd import RigidDynamics
from rigidmd.core import coupling as base
from rigidmd.couplings.baoab import LangevinBAOABThermostat
from rigidmd.couplings.barostats import CRescaleBarostat, MTKBarostat
from rigidmd.couplings.base import TEMPERATURE
from rigidmd.couplings.thermostats import (
    BussiThermostat,
    LangevinThermostat,
    NoseHooverThermostat,
)


def test_the_registry_holds_every_kind_once():
    assert set(base.COUPLINGS) == {"langevin", "bussi", "nose_hoover", "langevin_baoab", "mtk",
                                   "crescale", "monte_carlo"}
    for kind, cls in base.COUPLINGS.items():
        assert cls.kind == kind and cls.section in ("thermostat", "barostat")
        assert all(isinstance(p, base.Parameter) for p in cls.parameters)
        assert cls.parameters[0] == TEMPERATURE
    with pytest.raises(ValueError, match="coupling kind 'bussi' registered twice"):
        base.register(BussiThermostat)


@pytest.mark.parametrize("rng", [np.random.default_rng(1), np.random.RandomState(1)])
def test_generators_save_and_restore_their_state(rng):
    assert base.check_rng(rng) is rng
    state = base.rng_state(rng)
    first = rng.random(3)
    base.set_rng_state(rng, state)
    assert np.array_equal(rng.random(3), first)
    other = base.new_rng(base.rng_kind(rng))
    assert type(other) is type(rng)
    base.set_rng_state(other, state)
    assert np.array_equal(other.random(3), first)
    assert isinstance(base.check_rng(None), np.random.Generator)
    with pytest.raises(TypeError, match="rng must be a numpy.random.Generator, a "
                                        "numpy.random.RandomState or numpy.random, got int"):
        base.check_rng(3)


def mtk(temperature_K=300.0):
    return MTKBarostat(temperature_K, units.bar, 1000 * units.fs)


def test_what_no_dynamics_can_compose_is_refused():
    bussi = BussiThermostat(300.0, 100 * units.fs, rng=np.random.default_rng(0))
    assert base.check_composition([bussi], fixcom=False) is None
    barostat = mtk()
    assert base.check_composition([bussi, barostat], fixcom=False) is barostat
    crescale = CRescaleBarostat(300.0, units.bar, 1000 * units.fs, 4.5e-5 / units.bar,
                                rng=np.random.default_rng(0))
    cases = [
        ([barostat, crescale], False, "two parts move the cell \\(mtk, crescale\\)"),
        ([NoseHooverThermostat(300.0, 100 * units.fs, fixcm=True), mtk()], False,
         "thermostat fixcm=True with a barostat"),
        ([LangevinBAOABThermostat(300.0, 0.01, rng=np.random.default_rng(0)), mtk()], False,
         "langevin_baoab acts in the middle of the step"),
        ([mtk()], True, "FixCom with a barostat"),
        ([LangevinThermostat(300.0, 0.01, rng=np.random.default_rng(0)), mtk(250.0)], False,
         "barostat temperature_K = 250 K differs from the thermostat's 300 K"),
        (["bussi"], False, "couplings must be coupling parts"),
        # it acted twice a half step: +0.466 eV of conserved-energy drift in 200 steps of
        # 6 waters, against -0.0008 with it once (the MTS and couplings pass)
        ([bussi, bussi], False, "the same bussi part is given twice"),
    ]
    for parts, fixcom, match in cases:
        with pytest.raises((ValueError, TypeError), match=match):
            base.check_composition(parts, fixcom)


def test_export_keeps_a_shared_generator_shared():
    rng = np.random.default_rng(5)
    parts = [BussiThermostat(300.0, 100 * units.fs, rng=rng),
             CRescaleBarostat(300.0, units.bar, 1000 * units.fs, 4.5e-5 / units.bar, rng=rng)]
    exported = base.export_parts(parts)
    assert [p["class"] for p in exported] == ["BussiThermostat", "CRescaleBarostat"]
    assert [p["rng_owner"] for p in exported] == [0, 0]
    assert exported[0]["rng"] == {"type": "generator", "bit_generator": "PCG64"}
    assert base.export_parts([mtk()])[0]["rng"] is None
    assert exported[0]["parameters"]["temperature_K"] == 300.0


def test_one_target_temperature_is_shared_by_the_parts_of_a_dynamics():
    thermostat = LangevinThermostat(300, 0.01, rng=np.random.default_rng(1))
    assert thermostat.temperature_K == 300  # its own value until bound
    dyn = RigidDynamics(waters(4), 1 * units.fs, couplings=[thermostat])
    assert dyn.target.parts == [thermostat] and dyn.target.temperature_K == 300
    thermostat.set_temperature(250)  # through a part: the dynamics' target moves
    assert dyn.target.temperature_K == 250 == thermostat.temperature_K
    dyn.target.set_temperature(320)
    assert thermostat.temperature_K == 320
    with pytest.raises(ValueError, match="temperature"):
        dyn.target.set_temperature(-5)  # the part refuses it: nothing changes
    assert thermostat.temperature_K == 320


def test_a_target_without_parts_refuses_a_temperature():
    target = base.share_target([])
    assert target.temperature_K is None
    with pytest.raises(ValueError, match="no part of this dynamics has a target temperature"):
        target.set_temperature(300)
