"""The extension API: what a thermostat, a barostat or another coupling part is built on.

A :class:`~rigidmd.RigidDynamics` is an integrator scheme and a list of coupling
parts (``RigidDynamics(atoms, dt, couplings=[...])``).  A part subclasses
:class:`Coupling` (a thermostat: :class:`Thermostat`; a barostat:
:class:`Barostat`), says what it is in a configuration file (:attr:`Coupling.kind`,
:attr:`Coupling.parameters`, :class:`Parameter`), joins the registry
:data:`COUPLINGS` with :func:`register`, acts on the state a :class:`CouplingView`
gives it for half a step before and after the deterministic step, and says what it
is in a LAMMPS deck (:class:`LammpsFix`) or why it is nothing there
(:class:`NotExportable`).  :doc:`/howto/write-a-thermostat` writes one end to end.

The interface itself lives in the core (:mod:`rigidmd.core.coupling`), which imports
nothing above it; what the thermostats share is :mod:`rigidmd.couplings.base`
(:class:`Thermostat`, :class:`TargetTemperature`, :class:`NoseHooverChain`, the
parameter checks).  The parts rigidmd ships are in the modules of this package
(``rigidmd.couplings.thermostats``, ``barostats``, ``montecarlo``, ``baoab``); the
dynamics users construct from them (:class:`~rigidmd.RigidBussi`, ...) are imported
from :mod:`rigidmd`.
"""

from rigidmd.core.coupling import (
    COUPLINGS,
    Coupling,
    CouplingView,
    LammpsFix,
    NotExportable,
    Parameter,
    check_rng,
    register,
    rng_state,
    set_rng_state,
)
from rigidmd.couplings.barostats import Barostat
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

__all__ = ["Coupling", "CouplingView", "Thermostat", "Barostat", "TargetTemperature",
           "NoseHooverChain", "register", "COUPLINGS", "Parameter", "TEMPERATURE", "LammpsFix",
           "NotExportable", "check_temperature", "check_time", "check_flag",
           "check_positive_integer", "check_rng", "rng_state", "set_rng_state"]
