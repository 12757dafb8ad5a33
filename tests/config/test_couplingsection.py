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
                            " or module.Class for a thermostat of your own \\(with --trust\\),"
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


@pytest.mark.parametrize("kind, extra", [
    ("mtk", {"pdamp": "1 ps"}),
    ("monte_carlo", {}),
])
@pytest.mark.parametrize("pressure", ["200 GPa", "-2e6 bar"])
def test_a_pressure_beyond_the_barostats_range_is_refused_in_the_users_units(kind, extra,
                                                                             pressure):
    """``barostat.pressure: 200 GPa`` was refused in the Python API's words ("barostat.
    pressure is in eV/Å³ (1 bar = ase.units.bar ...)") although the user wrote GPa."""
    with pytest.raises(ConfigError) as err:
        parse_coupling("barostat", {"kind": kind, "temperature": "300 K",
                                    "pressure": pressure, **extra})
    assert str(err.value) == (f"barostat.pressure: {pressure} is beyond ±160.2 GPa "
                              "(±1.602e+06 bar), the largest pressure a barostat takes; is the "
                              "unit right?")
    assert parse_coupling("barostat", {"kind": kind, "temperature": "300 K",
                                       "pressure": "150 GPa", **extra}).kwargs[
        "pressure_au"] == pytest.approx(150 * units.GPa)


def test_a_barostat_is_refused_for_a_cluster_or_a_calculator_without_stress():
    """Refused by the dynamics in the Python API's words ("atoms.pbc is [False, False,
    False]", "the calculator TIP3P provides no stress"), without the field at fault."""
    from ase.calculators.tip3p import TIP3P

    from rigidmd.systems import water_box, water_cluster

    section = CouplingSection.from_config({"barostat": {
        "kind": "mtk", "temperature": "300 K", "pressure": "1 bar", "pdamp": "1 ps"}}, None)
    with pytest.raises(ConfigError) as err:
        section.check_structure(water_cluster(2, seed=0))
    assert str(err.value) == ("barostat: mtk changes the periodic cell, which needs "
                              "periodicity in x, y and z; the structure is not periodic (a "
                              "cluster); leave barostat out, or give a periodic box")
    slab = water_box(2)
    slab.pbc = [True, True, False]
    with pytest.raises(ConfigError, match="the structure is periodic along x and y only"):
        section.check_structure(slab)
    section.check_structure(water_box(2))
    with pytest.raises(ConfigError) as err:
        section.check_calculator(TIP3P(), "tip3p")
    assert str(err.value) == ("calculator.name: tip3p provides no stress (it implements "
                              "energy, forces), which barostat mtk needs for the pressure; use "
                              "a calculator with stress, e.g. lammps")
    CouplingSection.from_config({}, None).check_calculator(TIP3P(), "tip3p")
