"""Quantities with units in configuration files, and the configuration error.

Quantities are strings ``"<number> <unit>"``: ``"2 fs"``, ``"300 K"``,
``"0.01 1/fs"``, ``"1 bar"``.  They are converted to ASE units (ASE time,
K, 1/ASE time, eV/Å³, Å³/eV).
"""

import math
import re

from ase import units

__all__ = ["ConfigError", "parse_quantity", "mapping", "key_name", "whole_number", "parse_address",
           "UNIT_TABLES", "LENGTH_UNITS",
           "TIME_UNITS", "RATE_UNITS", "TEMPERATURE_UNITS", "PRESSURE_UNITS",
           "COMPRESSIBILITY_UNITS"]

TIME_UNITS = {"fs": units.fs, "ps": 1000 * units.fs, "ase": 1.0}
RATE_UNITS = {"1/fs": 1 / units.fs, "1/ps": 1 / (1000 * units.fs), "1/ase": 1.0}
TEMPERATURE_UNITS = {"K": 1.0}
#: Lengths: Å (``A`` as ``eV/A`` and ``eV/A^3`` write it, or ``Å``) and nm.
LENGTH_UNITS = {"A": 1.0, "Å": 1.0, "nm": 10.0}
PRESSURE_UNITS = {"bar": units.bar, "atm": 1.01325 * units.bar, "GPa": units.GPa,
                  "Pa": units.Pascal, "eV/A^3": 1.0}
COMPRESSIBILITY_UNITS = {"1/bar": 1 / units.bar, "1/atm": 1 / (1.01325 * units.bar),
                         "1/GPa": 1 / units.GPa, "1/Pa": 1 / units.Pascal, "A^3/eV": 1.0}
#: A number as a configuration writes it: ASCII digits, an optional sign, point and
#: exponent.  Python's float() also takes "1_0" (10), "infinity" and other scripts' digits.
NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")

#: Unit table of each kind of quantity.
UNIT_TABLES = {"time": TIME_UNITS, "rate": RATE_UNITS, "temperature": TEMPERATURE_UNITS,
               "pressure": PRESSURE_UNITS, "compressibility": COMPRESSIBILITY_UNITS}


class ConfigError(ValueError):
    """A configuration mistake; the message starts with the field at fault."""


def parse_quantity(field, value, unit_table, default_unit=None):
    """``"1 fs"`` → 1 fs in ASE units, with the unit looked up in ``unit_table``.

    A bare number is accepted only when ``default_unit`` is given.

    Raises
    ------
    ConfigError
        Naming ``field``: not a quantity, an unknown unit, or not finite.
    """
    example = f"'1 {next(iter(unit_table))}'"
    if isinstance(value, bool) or value is None:
        raise ConfigError(f"{field}: expected a quantity such as {example}, got {value!r}")
    if isinstance(value, (int, float)):
        if default_unit is None:
            raise ConfigError(
                f"{field}: give a unit, e.g. '{value} {next(iter(unit_table))}' "
                f"(units: {', '.join(unit_table)})")
        number, unit = float(value), default_unit
    else:
        parts = str(value).split()
        if len(parts) != 2:
            raise ConfigError(f"{field}: expected '<number> <unit>' such as {example}, "
                              f"got {value!r}")
        number, unit = parts
        if not NUMBER.fullmatch(number):
            raise ConfigError(f"{field}: {number!r} is not a number (digits, with an optional "
                              f"sign, point and exponent, e.g. {example})")
        number = float(number)
    if unit not in unit_table:
        raise ConfigError(f"{field}: unknown unit {unit!r}; use one of {', '.join(unit_table)}")
    if not math.isfinite(number * unit_table[unit]):  # '1e308 ps' overflows to inf
        raise ConfigError(f"{field}: must be finite, got {value!r}")
    return number * unit_table[unit]


def key_name(key):
    """A key as a message shows it: plain words as they are, anything else quoted."""
    if isinstance(key, str) and re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_./^-]*", key):
        return key
    return repr(key)


def mapping(field, value, allowed=None):
    """``value`` if it is a mapping (with only ``allowed`` keys), else a ConfigError."""
    if not isinstance(value, dict):
        raise ConfigError(f"{field}: expected a mapping, got {type(value).__name__}")
    if allowed is not None:
        unknown = sorted(set(value) - set(allowed), key=str)
        if unknown:
            raise ConfigError(
                f"{field}.{key_name(unknown[0])}: unknown key; allowed: "
                f"{', '.join(sorted(allowed))}")
    return value


def whole_number(field, value, minimum=0):
    """``value`` as an int >= ``minimum``, else a ConfigError naming ``field``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        how = ""
        if isinstance(value, float) and value.is_integer() and value >= minimum:
            # 1e3 is read as the float 1000.0: a whole value, not an integer
            how = f" (a number with a decimal point or exponent; write {int(value)})"
        raise ConfigError(f"{field}: expected a whole number >= {minimum}, got "
                          f"{value!r}{how}")
    return value


def parse_address(field, address):
    """``unix:NAME`` or ``HOST:PORT`` as IPICalculator keywords, else a ConfigError.

    Parameters
    ----------
    field : str
        The configuration field, e.g. ``"calculator.address"``.
    address : str

    Returns
    -------
    dict
        ``{"unixsocket": NAME}`` or ``{"host": HOST, "port": PORT}`` (``PORT`` 1025-65535).
    """
    text = str(address)
    if text.startswith("unix:") and len(text) > 5:
        from rigidmd.ipi.connection import SOCKET_NAME_RULE, socket_name_ok

        name = text[5:]
        if not socket_name_ok(name):
            raise ConfigError(f"{field}: {name!r} is not a plain socket name "
                              f"({SOCKET_NAME_RULE})")
        return {"unixsocket": name}
    host, _, port = text.rpartition(":")
    if ":" in host or host.startswith("["):  # the socket is IPv4 (ipi.connection)
        raise ConfigError(f"{field}: {address!r} is an IPv6 address; the i-PI socket "
                          "listens on IPv4: give an IPv4 address or a host name")
    if host and port.isdigit() and 1024 < int(port) < 65536:
        return {"host": host, "port": int(port)}
    raise ConfigError(f"{field}: expected unix:NAME or HOST:PORT (port 1025-65535), "
                      f"got {address!r}")
