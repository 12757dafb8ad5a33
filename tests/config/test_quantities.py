"""Quantities with units and the small checks every section uses (rigidmd.config.quantities)."""

import pytest
from ase import units

from rigidmd.config.quantities import (
    PRESSURE_UNITS,
    TEMPERATURE_UNITS,
    TIME_UNITS,
    ConfigError,
    key_name,
    mapping,
    parse_address,
    parse_quantity,
    whole_number,
)


def test_a_quantity_is_converted_to_ase_units():
    assert parse_quantity("timestep", "2 fs", TIME_UNITS) == pytest.approx(2 * units.fs)
    assert parse_quantity("timestep", "0.5 ps", TIME_UNITS) == pytest.approx(500 * units.fs)
    assert parse_quantity("p", "1e4 bar", PRESSURE_UNITS) == pytest.approx(1 * units.GPa)
    assert parse_quantity("t", "-1.5e2 K", TEMPERATURE_UNITS) == -150.0
    assert parse_quantity("fmax", 0.1, {"eV/A": 1.0}, default_unit="eV/A") == 0.1


@pytest.mark.parametrize("value, match", [
    (None, "timestep: expected a quantity such as '1 fs', got None"),
    (True, "timestep: expected a quantity"),
    (1.0, r"timestep: give a unit, e.g. '1.0 fs' \(units: fs, ps, ase\)"),
    ("1fs", "timestep: expected '<number> <unit>'"),
    ("1 2 fs", "timestep: expected '<number> <unit>'"),
    ("one fs", "timestep: 'one' is not a number"),
    ("0x1 fs", "timestep: '0x1' is not a number"),
    ("1 ns", "timestep: unknown unit 'ns'; use one of fs, ps, ase"),
    ("1e308 ps", "timestep: must be finite"),
    ("nan fs", "is not a number"),
])
def test_a_bad_quantity_names_its_field(value, match):
    with pytest.raises(ConfigError, match=match):
        parse_quantity("timestep", value, TIME_UNITS)


def test_key_names_quote_what_is_not_a_plain_word():
    assert key_name("thermostat") == "thermostat"
    assert key_name("a.b-c^2") == "a.b-c^2"
    assert key_name("two words") == "'two words'"
    assert key_name(3) == "3"
    assert key_name("") == "''"


def test_mappings_and_their_unknown_keys():
    assert mapping("relax", {"fmax": 1}, ("fmax", "steps")) == {"fmax": 1}
    with pytest.raises(ConfigError, match="relax: expected a mapping, got list"):
        mapping("relax", [1])
    with pytest.raises(ConfigError, match="relax.'a b': unknown key; allowed: fmax, steps"):
        mapping("relax", {"a b": 1, "fmax": 2}, ("steps", "fmax"))


def test_whole_numbers():
    assert whole_number("steps", 0) == 0
    assert whole_number("steps", 5, minimum=5) == 5
    for bad in (4, 2.0, True, "5", None):
        with pytest.raises(ConfigError, match=f"steps: expected a whole number >= 5, got "
                                              f"{bad!r}"):
            whole_number("steps", bad, minimum=5)


def test_addresses():
    assert parse_address("calculator.address", "unix:rigidmd") == {"unixsocket": "rigidmd"}
    assert parse_address("calculator.address", "node7:31415") == {"host": "node7",
                                                                  "port": 31415}
    with pytest.raises(ConfigError, match="calculator.address: 'a/b' is not a plain socket"):
        parse_address("calculator.address", "unix:a/b")
    with pytest.raises(ConfigError, match="IPv6 address"):
        parse_address("calculator.address", "[::1]:31415")
    for bad in ("node7:1024", "node7:65536", "node7", ":31415", "unix:"):
        with pytest.raises(ConfigError, match="expected unix:NAME or HOST:PORT"):
            parse_address("calculator.address", bad)
