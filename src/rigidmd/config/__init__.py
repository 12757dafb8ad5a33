"""Run configurations for the ``rigidmd`` command: reading, checking, building.

The loader is :mod:`rigidmd.config.loader` (the keys, :func:`load_config`,
:func:`check_config`, :class:`RunConfig`); each group of keys is checked by its
section (:mod:`rigidmd.config.sections`, :mod:`rigidmd.config.couplingsection`,
:mod:`rigidmd.config.relaxsection`), quantities with units by
:mod:`rigidmd.config.quantities`, and what a configuration may do without
``--trust`` by :mod:`rigidmd.config.trust`.  The names below are re-exported.
"""

from rigidmd.config.loader import (
    DEMO_CONFIG,
    RunConfig,
    check_config,
    known_keys,
    load_config,
)
from rigidmd.config.quantities import (
    COMPRESSIBILITY_UNITS,
    PRESSURE_UNITS,
    RATE_UNITS,
    TEMPERATURE_UNITS,
    TIME_UNITS,
    ConfigError,
    parse_quantity,
)
from rigidmd.config.relaxsection import RelaxSection

__all__ = ["ConfigError", "RunConfig", "load_config", "check_config", "parse_quantity",
           "known_keys", "RelaxSection",
           "DEMO_CONFIG", "TIME_UNITS", "RATE_UNITS", "TEMPERATURE_UNITS", "PRESSURE_UNITS",
           "COMPRESSIBILITY_UNITS"]
