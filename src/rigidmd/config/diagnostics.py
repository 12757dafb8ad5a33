"""The ``diagnostics:`` section of a run configuration: measurements a run may add.

::

    diagnostics:
      configurational_temperature:  # translational and rotational T_conf
        interval: 100               # steps between samples (each costs 2 * probes force calls)
        probes: 4                   # Hutchinson vectors per sample (default 4)
        seed: 0                     # the probes' random numbers (default 0)

A diagnostic never changes the trajectory (so it is not part of what
``--resume`` compares): ``rigidmd run`` gives it a calculator of its own, built
from the same ``calculator:`` section, when the forces are computed in
process (LAMMPS keeps state of its own beyond its results); an engine in
other processes or at an address is shared, and the run may then part from
an unobserved one by rounding.  Its estimates go to the run's summary
(:class:`rigidmd.core.configurational.ConfigurationalTemperature`).
"""

from dataclasses import dataclass

from rigidmd.config.quantities import ConfigError, mapping, whole_number

__all__ = ["DiagnosticsSection", "own_calculator"]


@dataclass
class DiagnosticsSection:
    """What a run measures besides its outputs.

    Attributes
    ----------
    configurational_temperature : dict or None
        ``{"interval": int, "probes": int, "seed": int}``, or None (off).
    """

    KEYS = ("diagnostics",)
    FIELDS = ("configurational_temperature",)

    configurational_temperature: dict | None = None

    @classmethod
    def from_config(cls, raw, base=None):
        """The section of ``raw["diagnostics"]`` (an empty one when absent)."""
        out = cls()
        if raw.get("diagnostics") is None:
            return out
        section = mapping("diagnostics", raw["diagnostics"], cls.FIELDS)
        spec = section.get("configurational_temperature")
        if spec is not None:
            field = "diagnostics.configurational_temperature"
            spec = mapping(field, spec, ("interval", "probes", "seed"))
            if "interval" not in spec:
                raise ConfigError(f"{field}.interval: missing (steps between samples, "
                                  "e.g. 100)")
            out.configurational_temperature = {
                "interval": whole_number(f"{field}.interval", spec["interval"], minimum=1),
                "probes": whole_number(f"{field}.probes", spec.get("probes", 4), minimum=1),
                "seed": whole_number(f"{field}.seed", spec.get("seed", 0))}
        return out

    def attach(self, dyn, calculator=None):
        """Attach the diagnostics asked for to ``dyn``; returns them (objects with ``report``).

        ``calculator``: evaluates their displaced configurations (default: the
        dynamics' own; see :class:`~rigidmd.core.configurational.ConfigurationalTemperature`).
        """
        from rigidmd.core.configurational import ConfigurationalTemperature

        attached = []
        spec = self.configurational_temperature
        if spec is not None:
            tconf = ConfigurationalTemperature(dyn, probes=spec["probes"], rng=spec["seed"],
                                               calculator=calculator)
            dyn.attach(tconf, interval=spec["interval"])
            attached.append(tconf)
        return attached


def own_calculator(calculator, atoms, engine_directory):
    """A calculator of the diagnostics' own for ``atoms``, built from the ``calculator:``
    section when its forces run in this process; ``None`` (the dynamics' own is shared) for
    an engine in other processes or at an address."""
    if calculator.processes is None and calculator.address is None:
        return calculator.build(atoms.copy(), engine_directory)
    return None
