"""The bases of the dynamics classes built from coupling parts.

:class:`ThermostattedDynamics` is a :class:`~rigidmd.core.dynamics.RigidDynamics` with one
thermostat part (``self.thermostat``), :class:`BarostattedDynamics` one with a
thermostat part and a barostat part (``self.barostat``); the classes of this
package (:mod:`rigidmd.md`) build the parts from ASE-style arguments, and
:meth:`~rigidmd.core.dynamics.RigidDynamics.from_parts` builds any of them around
ready parts (a checkpoint's: :func:`rigidmd.load_checkpoint`), checked against its
``part_types``.
"""

from rigidmd.core.dynamics import RigidDynamics
from rigidmd.couplings.barostats import Barostat
from rigidmd.couplings.base import Thermostat

__all__ = ["ThermostattedDynamics", "BarostattedDynamics", "required_arguments", "ARGUMENT_UNITS"]


class ThermostattedDynamics(RigidDynamics):
    """A rigid dynamics with one thermostat part, exposed as ``self.thermostat``."""

    part_types = (Thermostat,)

    def __init__(self, atoms, timestep, thermostat, **kwargs):
        if "couplings" in kwargs:
            raise TypeError(f"{type(self).__name__} builds its own thermostat; "
                            "use RigidDynamics(couplings=...) to compose parts")
        self.thermostat = thermostat
        super().__init__(atoms, timestep, couplings=[thermostat], **kwargs)

    def _assemble(self, atoms, timestep, parts, **kwargs):
        ThermostattedDynamics.__init__(self, atoms, timestep, *parts, **kwargs)

    @property
    def temperature_K(self):
        """Target temperature (K)."""
        return self.thermostat.temperature_K

    @property
    def thermostat_work(self):
        """Energy a stochastic thermostat has put into the system so far (eV)."""
        return self.thermostat.work

    def todict(self):
        return super().todict() | self.thermostat.todict()


#: The unit of each argument :func:`required_arguments` may name.
ARGUMENT_UNITS = {"temperature_K": "K", "friction": "per ASE time unit",
                  "taut": "ASE time units", "tdamp": "ASE time units"}


def required_arguments(cls: str, **values) -> None:
    """Refuse (TypeError, one line naming the class ``cls``, every argument and its unit) when
    one of ``values`` is None: the ASE-style arguments a dynamics cannot do without."""
    missing = [name for name, value in values.items() if value is None]
    if missing:
        needed = " and ".join(f"{name} ({ARGUMENT_UNITS[name]})" for name in values)
        raise TypeError(f"{cls} needs {needed}; missing: {', '.join(missing)}")


class BarostattedDynamics(RigidDynamics):
    """A rigid dynamics with a thermostat part and a barostat part."""

    part_types = (Thermostat, Barostat)

    def __init__(self, atoms, timestep, thermostat, barostat, **kwargs):
        if "couplings" in kwargs:
            raise TypeError(f"{type(self).__name__} builds its own thermostat and barostat; "
                            "use RigidDynamics(couplings=...) to compose parts")
        self.thermostat, self.barostat = thermostat, barostat
        super().__init__(atoms, timestep, couplings=[thermostat, barostat], **kwargs)

    def _assemble(self, atoms, timestep, parts, **kwargs):
        BarostattedDynamics.__init__(self, atoms, timestep, *parts, **kwargs)

    @property
    def temperature_K(self):
        """Target temperature (K)."""
        return self.thermostat.temperature_K

    @property
    def pressure_au(self):
        """Target pressure (eV/Å³)."""
        return self.barostat.pressure_au

    def todict(self):
        return super().todict() | {"thermostat": self.thermostat.todict(),
                                   "barostat": self.barostat.todict()}
