"""The coupling section of a run configuration: ``thermostat`` and ``barostat``.

It reads the registry of coupling kinds (:data:`rigidmd.couplings.base.COUPLINGS`),
so a new thermostat or barostat needs no change here.  A ``kind`` written as a dotted
path (a part of the user's own) is imported and replaced by its registered kind
before this section is read, with ``--trust`` only
(:func:`rigidmd.config.trust.coupling_class`, called by
:func:`rigidmd.config.check_config`).
"""

import re
from dataclasses import dataclass

import numpy as np
from ase import units

from rigidmd.config.quantities import (
    UNIT_TABLES,
    ConfigError,
    mapping,
    parse_quantity,
    whole_number,
)

__all__ = ["CouplingSpec", "CouplingSection", "parse_coupling"]

#: The largest size of a target pressure (eV/Å³): the barostats'
#: (:func:`rigidmd.couplings.barostats.check_pressure`), refused here in the units of the
#: configuration (160 GPa; the Python API's message speaks of ``pressure_au``).
LARGEST_PRESSURE = 1.0


def _check_sign(field_name, quantity, value, raw):
    """Physical signs of parsed quantities: one wording for every field."""
    if quantity == "temperature" and value < 0:
        raise ConfigError(f"{field_name}: must be >= 0 K, got {raw!r}")
    if quantity in ("time", "compressibility") and not value > 0:
        raise ConfigError(f"{field_name}: must be positive, got {raw!r}")
    if quantity == "rate" and value < 0:
        raise ConfigError(f"{field_name}: must be >= 0, got {raw!r}")
    if quantity == "pressure" and abs(value) > LARGEST_PRESSURE:
        limit = LARGEST_PRESSURE / units.GPa
        raise ConfigError(f"{field_name}: {raw} is beyond ±{limit:.4g} GPa "
                          f"(±{limit * 1e4:.4g} bar), the largest pressure a barostat takes; "
                          "is the unit right?")


@dataclass
class CouplingSpec:
    """A checked coupling section: the kind and its constructor arguments (ASE units)."""

    section: str
    kind: str
    kwargs: dict
    seed: int | None = None

    @property
    def cls(self):
        from rigidmd.couplings.base import COUPLINGS

        return COUPLINGS[self.kind]

    def part(self):
        """A new coupling part (a fresh random generator from ``seed`` for stochastic kinds)."""
        kwargs = dict(self.kwargs)
        if any(p.quantity == "seed" for p in self.cls.parameters):
            kwargs["rng"] = np.random.default_rng(self.seed)
        return self.cls(**kwargs)


def parse_coupling(section, raw, defaults=None):
    """Check a ``thermostat:`` (or ``barostat:``) mapping against the registry.

    ``defaults`` (constructor keyword -> value) fill parameters the section
    leaves out, e.g. the barostat's temperature from the thermostat.

    Returns
    -------
    CouplingSpec
    """
    from rigidmd.couplings.base import COUPLINGS, INTEGER_LIMITS

    raw = mapping(section, raw)
    defaults = defaults or {}
    kinds = [kind for kind, cls in COUPLINGS.items() if cls.section == section]
    kind = raw.get("kind")
    if kind not in kinds:
        raise ConfigError(f"{section}.kind: use {', '.join(kinds)}, or module.Class for a "
                          f"{section} of your own (with --trust), got {kind!r}")
    cls = COUPLINGS[kind]
    mapping(section, raw, {"kind"} | {p.field for p in cls.parameters})
    kwargs, seed = {}, None
    for p in cls.parameters:
        name = f"{section}.{p.field}"
        if p.field not in raw:
            if p.name in defaults:
                kwargs[p.name] = defaults[p.name]
                continue
            if p.required:
                example = f" (e.g. '{p.example}')" if p.example else ""
                raise ConfigError(f"{name}: missing for {kind}{example}")
            continue
        value = raw[p.field]
        if p.quantity in UNIT_TABLES:
            parsed = parse_quantity(name, value, UNIT_TABLES[p.quantity])
            _check_sign(name, p.quantity, parsed, value)
            kwargs[p.name] = parsed
        elif p.quantity == "integer":
            kwargs[p.name] = whole_number(name, value, minimum=1)
            most = INTEGER_LIMITS.get(p.name)
            if most is not None and value > most:
                raise ConfigError(f"{name}: expected a whole number from 1 to {most} (a step "
                                  f"does each in turn), got {value!r}")
        elif p.quantity == "seed":
            seed = whole_number(name, value)
        elif p.quantity == "flag":
            if not isinstance(value, bool):
                raise ConfigError(f"{name}: use true or false, got {value!r}")
            kwargs[p.name] = value
        elif p.quantity == "choice":
            if value not in p.choices:
                raise ConfigError(f"{name}: use {', '.join(p.choices)}, got {value!r}")
            kwargs[p.name] = value
        else:  # pragma: no cover - a registry entry with an unknown quantity
            raise AssertionError(f"unknown quantity {p.quantity!r} of {name}")
    spec = CouplingSpec(section, kind, kwargs, seed)
    try:
        spec.part()
    except (TypeError, ValueError) as err:
        # Name the configuration's fields, not the constructor's keywords.
        message = str(err)
        for p in cls.parameters:
            message = re.sub(rf"\b{p.name}\b", f"{section}.{p.field}", message)
        if not message.startswith(f"{section}."):
            message = f"{section}: {message}"
        raise ConfigError(message) from None
    return spec


@dataclass
class CouplingSection:
    """Thermostat and barostat parts, from the registry of coupling kinds.

    ``barostat:`` takes the thermostat's temperature unless it gives its
    own; a barostat without a thermostat is NPH (MTK) or its stochastic
    counterpart.

    Attributes
    ----------
    thermostat, barostat : CouplingSpec or None
    """

    KEYS = ("thermostat", "barostat")

    thermostat: CouplingSpec | None = None
    barostat: CouplingSpec | None = None

    @classmethod
    def from_config(cls, raw, base):
        thermostat = raw.get("thermostat")
        if thermostat is not None:
            thermostat = parse_coupling("thermostat", thermostat)
        barostat = raw.get("barostat")
        if barostat is not None:
            defaults = {} if thermostat is None else {
                "temperature_K": thermostat.kwargs["temperature_K"]}
            barostat = parse_coupling("barostat", barostat, defaults)
            if thermostat is not None:
                own = barostat.kwargs["temperature_K"]
                target = thermostat.kwargs["temperature_K"]
                if own != target:
                    raise ConfigError(
                        f"barostat.temperature: {own:g} K differs from thermostat.temperature "
                        f"{target:g} K; one run has one target temperature (leave "
                        "barostat.temperature out)")
        return cls(thermostat, barostat)

    @property
    def specs(self):
        """The checked coupling sections present, in the order they act."""
        return [spec for spec in (self.thermostat, self.barostat) if spec is not None]

    def parts(self):
        """New coupling parts for a dynamics."""
        return [spec.part() for spec in self.specs]

    def check_structure(self, atoms):
        """Refuse (ConfigError naming the section) a part that moves the cell (a barostat)
        for a structure whose cell is not periodic in all three directions."""
        for spec in self.specs:
            if spec.cls.moves_cell and not np.all(atoms.pbc):
                periodic = [axis for axis, on in zip("xyz", atoms.pbc, strict=True) if on]
                has = (f"periodic along {' and '.join(periodic)} only" if periodic
                       else "not periodic (a cluster)")
                raise ConfigError(f"{spec.section}: {spec.kind} changes the periodic cell, "
                                  f"which needs periodicity in x, y and z; the structure is "
                                  f"{has}; leave {spec.section} out, or give a periodic box")

    def check_calculator(self, calc, name):
        """Refuse (ConfigError naming ``calculator.name``) a calculator that declares it
        provides no stress or no energy where a part reads it (a barostat's pressure, the
        Monte Carlo barostat's energy): :func:`rigidmd.core.split.missing_property`, with
        the configuration's calculators taken at their declaration.  ``calc``: the built
        calculator; ``name``: the configuration's ``calculator.name``.  A force split's
        levels are checked by the dynamics, naming the level."""
        from rigidmd.core.split import missing_property

        if name == "multiple_time_step":
            return
        missing = missing_property(calc, [spec.cls for spec in self.specs], declared=True)
        if missing is not None:
            needed, part = missing
            why = "the pressure" if needed == "stress" else "its moves' energies"
            raise ConfigError(
                f"calculator.name: {name} provides no {needed} (it implements "
                f"{', '.join(calc.implemented_properties)}), which {part.section} {part.kind} "
                f"needs for {why}; use a calculator with {needed}, e.g. lammps")
