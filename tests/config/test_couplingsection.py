"""The ``thermostat:`` and ``barostat:`` sections, read through the registry of coupling kinds
(rigidmd.config.couplingsection)."""

import numpy as np
import pytest
from ase import units

from rigidmd.config.couplingsection import CouplingSection, parse_coupling
from rigidmd.config.quantities import ConfigError
from rigidmd.couplings.thermostats import BussiThermostat, LangevinThermostat


def test_a_thermostat_section_becomes_its_part():
    spec = parse_coupling("thermostat", {"kind": "bussi", "temperature": "300 K",
                                         "taut": "0.1 ps", "seed": 4})
    assert (spec.section, spec.kind, spec.seed) == ("thermostat", "bussi", 4)
    assert spec.kwargs == {"temperature_K": 300.0, "taut": pytest.approx(100 * units.fs)}
    assert spec.cls is BussiThermostat
    first, second = spec.part(), spec.part()
    assert isinstance(first, BussiThermostat) and first is not second
    # Each part gets a fresh generator from the seed: the same numbers.
    assert first.rng.random() == second.rng.random() == np.random.default_rng(4).random()


@pytest.mark.parametrize("raw, match", [
    ({"kind": "berendsen"}, "thermostat.kind: use langevin, bussi, nose_hoover, langevin_baoab,"
                            " got 'berendsen'"),
    ({"kind": "bussi", "temperature": "300 K"}, "thermostat.taut: missing for bussi"),
    ({"kind": "bussi", "temperature": "-1 K", "taut": "1 ps"},
     "thermostat.temperature: must be >= 0 K, got '-1 K'"),
    ({"kind": "bussi", "temperature": "1 K", "taut": "0 ps"},
     "thermostat.taut: must be positive, got '0 ps'"),
    ({"kind": "langevin", "temperature": "1 K", "friction": "-1 1/ps"},
     "thermostat.friction: must be >= 0"),
    ({"kind": "langevin", "temperature": "1 K", "friction": "1 1/ps", "fixcm": "yes"},
     "thermostat.fixcm: use true or false, got 'yes'"),
    ({"kind": "nose_hoover", "temperature": "1 K", "tdamp": "1 ps", "tchain": 0},
     "thermostat.tchain: expected a whole number >= 1"),
    ({"kind": "bussi", "temperature": "1 K", "taut": "1 ps", "tdamp": "1 ps"},
     "thermostat.tdamp: unknown key"),
])
def test_mistakes_name_the_field(raw, match):
    with pytest.raises(ConfigError, match=match):
        parse_coupling("thermostat", raw)


def test_a_barostat_choice_is_checked():
    with pytest.raises(ConfigError, match="barostat.couple: use .*got 'xy'"):
        parse_coupling("barostat", {"kind": "mtk", "temperature": "300 K", "pressure": "1 bar",
                                    "pdamp": "1 ps", "couple": "xy"})


def test_the_barostat_takes_the_thermostats_temperature():
    section = CouplingSection.from_config({
        "thermostat": {"kind": "langevin", "temperature": "250 K", "friction": "1 1/ps"},
        "barostat": {"kind": "crescale", "pressure": "1 bar", "taup": "1 ps",
                     "compressibility": "4.5e-5 1/bar"}}, None)
    assert section.barostat.kwargs["temperature_K"] == 250.0
    assert [s.section for s in section.specs] == ["thermostat", "barostat"]
    thermostat, barostat = section.parts()
    assert isinstance(thermostat, LangevinThermostat)
    assert type(barostat).__name__ == "CRescaleBarostat"
    assert CouplingSection.from_config({}, None).specs == []


def test_two_target_temperatures_are_refused():
    with pytest.raises(ConfigError, match="barostat.temperature: 300 K differs from "
                                          "thermostat.temperature 250 K"):
        CouplingSection.from_config({
            "thermostat": {"kind": "bussi", "temperature": "250 K", "taut": "1 ps"},
            "barostat": {"kind": "mtk", "temperature": "300 K", "pressure": "1 bar",
                         "pdamp": "1 ps"}}, None)
    with pytest.raises(ConfigError, match="barostat.temperature: missing for mtk"):
        CouplingSection.from_config({"barostat": {"kind": "mtk", "pressure": "1 bar",
                                                  "pdamp": "1 ps"}}, None)
