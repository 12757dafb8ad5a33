"""Coupling parts: thermostats, barostats and the Monte Carlo barostat.

The names a new part is written against are re-exported here: the interface of
:mod:`rigidmd.core.coupling` (:class:`Coupling`, :class:`CouplingView`,
:class:`Parameter`, :class:`LammpsFix`, :class:`NotExportable`, :func:`register`,
:data:`COUPLINGS`) and what the thermostats share, from
:mod:`rigidmd.couplings.base` (:class:`Thermostat`, :class:`TargetTemperature`,
:class:`NoseHooverChain`, the parameter checks).  The user classes live in :mod:`rigidmd`.
"""

from rigidmd.core.coupling import (
    COUPLINGS,
    Coupling,
    CouplingView,
    LammpsFix,
    NotExportable,
    Parameter,
    register,
)
from rigidmd.couplings.base import (
    TEMPERATURE,
    NoseHooverChain,
    TargetTemperature,
    Thermostat,
    check_flag,
    check_positive_integer,
    check_temperature,
    check_time,
)

__all__ = ["Coupling", "CouplingView", "Parameter", "LammpsFix", "NotExportable", "register",
           "COUPLINGS", "Thermostat", "TargetTemperature", "NoseHooverChain", "TEMPERATURE",
           "check_temperature", "check_time", "check_flag", "check_positive_integer"]
