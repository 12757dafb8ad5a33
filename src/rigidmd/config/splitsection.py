"""The ``calculator:`` section of a force split: ``{fast: {...}, slow: {...}, substeps: k}``.

Each level is a calculator section of its own (any calculator a configuration
supports: ``tip3p``, ``tip4p``, ``lammps``, ``ipi`` or a dotted class path); the
configured run's calculator is :class:`rigidmd.MultipleTimeStep` of the two, which
every dynamics integrates by r-RESPA with ``substeps`` inner steps per ``timestep``.
``full: {...}`` in place of ``slow`` makes the slow level the full model less the fast
one (``MultipleTimeStep(fast, full=...)``, :class:`rigidmd.core.split.FullLessFast`: the
fast level's call at the end of each outer step is its cache, so the difference costs one
call of the full model).
:func:`calculator_section` reads either form.
"""

from dataclasses import dataclass
from pathlib import Path

from rigidmd.config.quantities import ConfigError, mapping
from rigidmd.config.sections import CalculatorSection
from rigidmd.core.split import MAX_SUBSTEPS, MultipleTimeStep, check_substeps

__all__ = ["SplitCalculatorSection", "calculator_section"]

#: The keys that make a ``calculator:`` section a force split.
SPLIT_FIELDS = ("fast", "slow", "full", "substeps")


def _renamed(err: ConfigError, level: str) -> ConfigError:
    """A level's error, naming its field under ``calculator.<level>``."""
    text = str(err)
    if text.startswith("calculator"):
        text = f"calculator.{level}" + text[len("calculator"):]
    return ConfigError(text)


@dataclass
class SplitCalculatorSection:
    """``calculator: {fast: ..., slow: ..., substeps: k}``: two calculators, r-RESPA.

    Attributes
    ----------
    fast, slow : CalculatorSection
        ``slow`` is the full model when ``difference`` is set.
    substeps : int
        Inner (fast) steps per ``timestep``.
    difference : bool
        ``full`` was given: the slow level is ``slow`` less ``fast``.
    """

    KEYS = ("calculator",)

    fast: CalculatorSection
    slow: CalculatorSection
    substeps: int
    difference: bool = False

    @property
    def name(self) -> str:
        """What a calculator section's ``name`` says: this one is a split."""
        return "multiple_time_step"

    @property
    def processes(self) -> int | None:
        """A level's engine processes (``None`` when every level runs in this process)."""
        return next((s.processes for _, s in self.levels if s.processes is not None), None)

    @property
    def address(self) -> str | None:
        """A level's engine address (``None`` when no level connects to an engine)."""
        return next((s.address for _, s in self.levels if s.address is not None), None)

    @property
    def levels(self) -> tuple:
        return (("fast", self.fast), ("full" if self.difference else "slow", self.slow))

    @classmethod
    def from_config(cls, raw, base) -> "SplitCalculatorSection":
        calc = mapping("calculator", raw["calculator"], SPLIT_FIELDS)
        difference = "full" in calc
        if difference and "slow" in calc:
            raise ConfigError("calculator.full: the slow level is full less fast; give slow or "
                              "full, not both")
        for key in ("fast", "full" if difference else "slow", "substeps"):
            if key not in calc:
                what = ("inner steps per timestep, e.g. 4" if key == "substeps"
                        else "a calculator section, e.g. {name: tip3p}")
                raise ConfigError(f"calculator.{key}: missing ({what})")
        substeps = calc["substeps"]
        try:
            check_substeps(substeps)  # the calculator's own rule
        except (TypeError, ValueError):
            raise ConfigError(f"calculator.substeps: expected a whole number from 1 to "
                              f"{MAX_SUBSTEPS} (inner steps per timestep), got {substeps!r}"
                              ) from None
        levels = {}
        for level in ("fast", "full" if difference else "slow"):
            spec = calc[level]
            if isinstance(spec, dict) and set(SPLIT_FIELDS) & set(spec):
                raise ConfigError(f"calculator.{level}: a level is one calculator, not another "
                                  "split")
            try:
                levels[level] = CalculatorSection.from_config({"calculator": spec}, base,
                                                              default_name=None)
            except ConfigError as err:
                raise _renamed(err, level) from None
        return cls(levels["fast"], levels["full" if difference else "slow"], substeps,
                   difference)

    def check_trust(self, trust=False) -> None:
        """Each level's :meth:`CalculatorSection.check_trust`, its errors naming the level."""
        for level, section in self.levels:
            try:
                section.check_trust(trust)
            except ConfigError as err:
                raise _renamed(err, level) from None

    def build(self, atoms, engine_directory="engine") -> MultipleTimeStep:
        """The split: each level built for ``atoms`` (an engine's input under its level's
        folder of ``engine_directory``)."""
        built = {}
        for level, section in self.levels:
            try:
                built[level] = section.build(atoms, Path(engine_directory) / level)
            except ConfigError as err:
                raise _renamed(err, level) from None
        if self.difference:
            return MultipleTimeStep(built["fast"], full=built["full"], substeps=self.substeps)
        return MultipleTimeStep(built["fast"], built["slow"], substeps=self.substeps)

    def fingerprint_fields(self, level_fields) -> dict:
        """What the levels compute, for ``--resume``: ``level_fields(section)`` gives a
        level's fields (a single calculator's, without where it runs or who may answer)."""
        return {"substeps": self.substeps, "difference": self.difference,
                **{level: level_fields(section) for level, section in self.levels}}


class CalculatorChoice:
    """The ``calculator:`` section in either form: one calculator, or a split."""

    KEYS = ("calculator",)

    @staticmethod
    def from_config(raw, base):
        return calculator_section(raw, base)


def calculator_section(raw, base):
    """A :class:`SplitCalculatorSection` when ``calculator`` has ``fast``, ``slow`` or
    ``substeps``, else a :class:`~rigidmd.config.sections.CalculatorSection`."""
    calc = raw.get("calculator")
    if isinstance(calc, dict) and set(SPLIT_FIELDS) & set(calc):
        return SplitCalculatorSection.from_config(raw, base)
    return CalculatorSection.from_config(raw, base)
