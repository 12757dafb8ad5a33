r"""A force split for multiple time steps: :class:`MultipleTimeStep`.

``MultipleTimeStep(fast, slow, substeps=k)`` is an ASE calculator whose energy,
forces and stress are the sums of its two calculators', so any ASE code
(optimizers, ``atoms.get_potential_energy()``, analyses) sees the full model.
Every rigidmd dynamics whose atoms carry one integrates it by r-RESPA
(Tuckerman, Berne & Martyna 1992; :mod:`rigidmd.core.respa`): the dynamics'
``timestep`` is the outer step, the slow forces and torques kick for half of it
on each side of ``k`` NO_SQUISH steps of ``timestep / k`` with the fast forces.
``MultipleTimeStep(fast, full=model, substeps=k)`` makes the slow level the full
model less the fast one (:class:`FullLessFast`).

The sums are computed from the two calculators' own results: each keeps its
cache (ASE's ``check_state``), so asking the split for the energy after a
dynamics asked its levels for forces and energy at the same positions calls
neither again.

References
----------
M. Tuckerman, B. J. Berne and G. J. Martyna, J. Chem. Phys. 97, 1990 (1992).
"""

from numbers import Integral

import numpy as np
from ase.calculators.calculator import (
    BaseCalculator,
    Calculator,
    PropertyNotImplementedError,
    all_changes,
)

from rigidmd.core.forces import calculate_together

__all__ = ["MultipleTimeStep", "FullLessFast", "check_substeps", "check_calculator_properties",
           "needed_properties", "missing_property", "MAX_SUBSTEPS"]

#: The most inner steps per outer step.  An outer step is never interrupted (a stop
#: signal waits for it), so a mistyped ``substeps`` (10**20) would hang the first step with
#: no way out but a kill; the r-RESPA literature and OpenMM's examples use 2-8, distilled
#: ML inner levels up to ~20, and 1000 inner steps are already 1000 fast calls per step.
MAX_SUBSTEPS = 1000

_SUMMED = ("energy", "free_energy", "forces", "stress")


def check_substeps(substeps) -> int:
    """``substeps`` as an int from 1 to :data:`MAX_SUBSTEPS`; a TypeError or ValueError in
    one line otherwise."""
    if isinstance(substeps, bool) or not isinstance(substeps, Integral):
        raise TypeError(f"MultipleTimeStep: substeps must be a whole number of inner steps "
                        f"per outer step, got {substeps!r}")
    if substeps < 1:
        raise ValueError(f"MultipleTimeStep: substeps must be at least 1, got {substeps}")
    if substeps > MAX_SUBSTEPS:
        raise ValueError(f"MultipleTimeStep: substeps must be at most {MAX_SUBSTEPS} (an outer "
                         f"step is never interrupted; {substeps} inner steps would hold a stop "
                         f"signal for {substeps} fast calls), got {substeps}")
    return int(substeps)


def _check_level(name: str, calc) -> None:
    if calc is None:
        raise TypeError(f"MultipleTimeStep: the {name} calculator is missing (None)")
    if isinstance(calc, MultipleTimeStep):
        raise TypeError(f"MultipleTimeStep: the {name} calculator is itself a "
                        "MultipleTimeStep; nest levels by splitting one of them instead")
    if isinstance(calc, type):  # (its get_forces is an unbound function: callable)
        raise TypeError(f"MultipleTimeStep: the {name} calculator is the class "
                        f"{calc.__name__}, not a calculator; make one ({calc.__name__}(...))")
    if not callable(getattr(calc, "get_forces", None)):
        raise TypeError(f"MultipleTimeStep: the {name} calculator must be an ASE calculator "
                        f"(with get_forces), got {type(calc).__name__}")


def _fixed_level(name: str):
    """Refuse replacing a level of a made split (a dynamics integrating it kept the old one,
    while the log, trajectory and energies read the new: two models mixed, silently)."""
    raise AttributeError(f"MultipleTimeStep: the {name} level is fixed when the split is made "
                         "(a dynamics integrating it holds its calculators); make a new "
                         "MultipleTimeStep, and a new dynamics for it")


class _FixedLevel:
    """A level of a split, read from ``_<name>``; setting it is refused
    (:func:`_fixed_level`)."""

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, owner=None):
        return self if obj is None else getattr(obj, "_" + self.name)

    def __set__(self, obj, value):
        _fixed_level(self.name)


class _Levels:
    """What a calculator of two levels (``levels``: ``((name, calculator), ...)``) tells a
    barostat's checks of the cell."""

    @property
    def orthorhombic_only(self) -> bool:
        """Whether a level takes only orthorhombic cells (a barostat's check reads it)."""
        return any(getattr(calc, "orthorhombic_only", False) for _, calc in self.levels)


class MultipleTimeStep(_Levels, Calculator):
    """An ASE calculator: the sum of a fast and a slow calculator, integrated by r-RESPA.

    Parameters
    ----------
    fast : ASE calculator
        The rapidly varying forces (bonded, short-range pair): called ``substeps``
        times per outer step of a rigidmd dynamics.
    slow : ASE calculator, optional
        The slowly varying rest (long-range electrostatics, the difference between
        an expensive model and a cheap one): called once per outer step.
    substeps : int, default 1
        Inner steps per outer step (``k``); the dynamics' ``timestep`` is the
        outer step.  ``1`` is the impulse form of velocity Verlet.
    full : ASE calculator, optional
        In place of ``slow``: the full model, whose difference from ``fast`` is the
        slow level (:class:`FullLessFast`; one call of ``full`` per outer step, and
        none of ``fast``, whose last inner call is at the same positions).

    Raises
    ------
    TypeError
        A calculator missing or not an ASE calculator, both or neither of ``slow``
        and ``full``, or ``substeps`` not a whole number.
    ValueError
        ``substeps`` below 1 or above :data:`MAX_SUBSTEPS` (1000).

    Notes
    -----
    Energy, free energy, forces and stress are sums; a property one level lacks
    (e.g. stress) is not in :attr:`implemented_properties`, so ASE's
    ``get_stress`` raises its :class:`~ase.calculators.calculator.PropertyNotImplementedError`,
    and a barostat refuses the split in one line naming that level.  Outside a
    rigidmd dynamics (an optimizer, an ASE integrator) the split plays no part: the
    sum is the model.  Inside one, the levels are called directly; after each outer
    step the split holds their sums at the new positions (:meth:`publish`), so what
    reads the calculator without calling it (ASE's trajectory writer, ``ase.io.write``)
    finds the full model there.
    """

    implemented_properties = list(_SUMMED)

    def __init__(self, fast, slow=None, substeps: int = 1, *, full=None):
        if (slow is None) == (full is None):
            raise TypeError("MultipleTimeStep: give the slow level as slow= or the full model "
                            "as full= (the slow level is then full less fast), "
                            + ("not both" if full is not None else "the slow calculator is "
                               "missing (None)"))
        _check_level("fast", fast)
        if full is not None:
            _check_level("full", full)
            if full is fast:
                raise ValueError("MultipleTimeStep: full and fast are the same calculator "
                                 "object, so the slow level would be zero; give the fast "
                                 "level a calculator of its own")
            slow = FullLessFast(full, fast)
        else:
            _check_level("slow", slow)
            if slow is fast:
                raise ValueError("MultipleTimeStep: fast and slow are the same calculator "
                                 "object, so the sum would be twice its model; give each "
                                 "level a calculator of its own (full= for the model less "
                                 "the fast level)")
        k = check_substeps(substeps)
        super().__init__()
        self._fast, self._slow, self._substeps, self._full = fast, slow, k, full
        # What both levels compute (a property one lacks is no property of the sum).
        own = [getattr(calc, "implemented_properties", _SUMMED) for calc in (fast, slow)]
        self.implemented_properties = [
            name for name in _SUMMED
            if all(name in names or (name == "free_energy" and "energy" in names)
                   for names in own)]

    #: The fast level's calculator; the slow level's (with ``full=``, the
    #: :class:`FullLessFast`); the full model given as ``full=``, else None.  Each is
    #: fixed when the split is made (a dynamics integrating it holds its calculators).
    fast, slow, full = (_FixedLevel() for _ in range(3))

    @property
    def substeps(self) -> int:
        """Inner (fast) steps per outer step; read by the dynamics at every outer step."""
        return self._substeps

    @substeps.setter
    def substeps(self, value) -> None:
        self._substeps = check_substeps(value)

    @property
    def levels(self) -> tuple:
        """``(("fast", fast), ("slow", slow))``."""
        return (("fast", self.fast), ("slow", self.slow))

    def publish(self, atoms) -> None:
        """Hold, as the split's own results, the levels' sums at ``atoms`` from what the
        levels hold for those atoms, without calling them.

        The r-RESPA step calls each level itself; this makes the split's cache current
        after it, so a reader that does not calculate (ASE's trajectory writer,
        ``ase.io.write``) finds the full model at the current positions, never a
        previous one.  A property some level does not hold for ``atoms`` is left out (a
        later ``get_property`` computes it from the levels).
        """
        held = [_held_results(calc, atoms) for _, calc in self.levels]
        sums = {name: np.add(held[0][name], held[1][name]) for name in _SUMMED
                if name in held[0] and name in held[1]}
        if "energy" in sums:
            sums["energy"] = float(sums["energy"])
            sums["free_energy"] = float(sums.get("free_energy", sums["energy"]))
        self.results = sums
        self.atoms = atoms.copy()

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        """Sum the levels' properties (each level computes what is asked in one call)."""
        super().calculate(atoms, properties, system_changes)
        atoms = atoms if atoms is not None else self.atoms
        terms = [(level, calc, False) for level, calc in self.levels]
        self.results.update(_combined("MultipleTimeStep", terms, atoms, properties))

    def check_level_properties(self, name: str, needed_by: str) -> None:
        """Refuse in one line a level that lacks ``name`` (e.g. ``"stress"``), naming it:
        with ``full=`` the full model or the fast level, the calculators the user gave."""
        levels = [("fast", self.fast)] + (list(self.slow.levels) if self.full is not None
                                          else [("slow", self.slow)])
        for level, calc in levels:
            implemented = getattr(calc, "implemented_properties", _SUMMED)
            if name not in implemented:
                raise ValueError(
                    f"MultipleTimeStep: the {level} calculator {type(calc).__name__} provides "
                    f"no {name} (it implements {', '.join(implemented)}), which {needed_by} "
                    "needs")

    def close(self) -> None:
        """Close each level that has a ``close`` (an engine in its own process), both
        always: the slow level is closed even when the fast level's close fails."""
        try:
            close = getattr(self.fast, "close", None)
            if callable(close):
                close()
        finally:
            close = getattr(self.slow, "close", None)
            if callable(close):
                close()

    def get_checkpoint_state(self) -> dict:
        """Each level's ``get_checkpoint_state()`` (None for a level without one)."""
        return {level: (calc.get_checkpoint_state()
                        if hasattr(calc, "get_checkpoint_state") else None)
                for level, calc in self.levels}

    def set_checkpoint_state(self, saved: dict) -> None:
        """Give each level what its ``get_checkpoint_state`` gave."""
        for level, calc in self.levels:
            if saved.get(level) is not None and hasattr(calc, "set_checkpoint_state"):
                calc.set_checkpoint_state(saved[level])

    def todict(self) -> dict:
        out = {"fast": type(self.fast).__name__, "slow": type(self.slow).__name__,
               "substeps": self._substeps}
        if self.full is not None:
            out["full"] = type(self.full).__name__
        return out


class FullLessFast(_Levels, Calculator):
    """An ASE calculator: a full model less a fast one, each asked once for everything.

    The slow level of ``MultipleTimeStep(fast, full=model)``.  Each call asks
    ``full`` for all the properties wanted in one call, then ``fast``, whose cache
    holds them when its last call was at the same positions (the last inner step of
    an outer step).  ASE's ``LinearCombinationCalculator`` asks its calculators one
    property at a time: a calculator that computes only what it is asked for
    (:class:`~rigidmd.lammps.LAMMPSCalculator` tallies the energy only when asked)
    was then called twice when the step wanted forces and energy.

    Parameters
    ----------
    full, fast : ASE calculators
    """

    def __init__(self, full, fast):
        _check_level("full", full)
        _check_level("fast", fast)
        super().__init__()
        self._full, self._fast = full, fast
        own = [getattr(calc, "implemented_properties", _SUMMED) for calc in (full, fast)]
        self.implemented_properties = [
            name for name in _SUMMED
            if all(name in names or (name == "free_energy" and "energy" in names)
                   for names in own)]

    #: The full model, and the fast level it is less; fixed when made.
    full, fast = _FixedLevel(), _FixedLevel()

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        """``full`` less ``fast`` for every property asked (one call of each at most)."""
        super().calculate(atoms, properties, system_changes)
        atoms = atoms if atoms is not None else self.atoms
        terms = [("full", self.full, False), ("fast", self.fast, True)]
        self.results.update(_combined("FullLessFast", terms, atoms, properties))

    @property
    def levels(self) -> tuple:
        """``(("full", full), ("fast", fast))``."""
        return (("full", self.full), ("fast", self.fast))

    def close(self) -> None:
        """Close the full model if it has a ``close`` (the fast level is the split's own)."""
        close = getattr(self.full, "close", None)
        if callable(close):
            close()

    def get_checkpoint_state(self):
        """The full model's ``get_checkpoint_state()`` (None without one)."""
        return (self.full.get_checkpoint_state()
                if hasattr(self.full, "get_checkpoint_state") else None)

    def set_checkpoint_state(self, saved) -> None:
        """Give the full model what its ``get_checkpoint_state`` gave."""
        if saved is not None and hasattr(self.full, "set_checkpoint_state"):
            self.full.set_checkpoint_state(saved)

    def todict(self) -> dict:
        return {"full": type(self.full).__name__, "fast": type(self.fast).__name__}


def _combined(owner: str, terms, atoms, properties) -> dict:
    """The sum of the ``terms``' properties asked, each calculator called once for all of them.

    ``terms``: ``(level, calculator, subtract)``, the first added (``subtract`` False).
    A level without a property asked is refused in one line naming ``owner`` and the level.
    ``free_energy`` is the energy when no level gives its own.
    """
    wanted = [name for name in properties if name in _SUMMED]
    out = {}
    for level, calc, subtract in terms:
        calculate_together(calc, atoms, [
            name for name in wanted if name in getattr(calc, "implemented_properties", _SUMMED)])
        for name in wanted:
            try:
                value = _level_property(calc, name, atoms)
            except PropertyNotImplementedError:
                raise PropertyNotImplementedError(
                    f"{owner}: the {level} calculator {type(calc).__name__} provides no "
                    f"{name}") from None
            if name not in out:
                out[name] = value
            else:
                out[name] = out[name] - value if subtract else out[name] + value
    if "energy" in out and "free_energy" not in out:
        out["free_energy"] = out["energy"]
    return out


def _held_results(calc, atoms) -> dict:
    """What a level holds for ``atoms`` (its results, ``free_energy`` the energy when it has
    none of its own), or nothing when it holds none for them; its cache is checked once
    (ASE's ``check_state``) and it is never called."""
    results = getattr(calc, "results", None)
    check_state = getattr(calc, "check_state", None)
    if not isinstance(calc, BaseCalculator) or not results or check_state is None \
            or check_state(atoms):
        return {}
    held = {name: results[name] for name in _SUMMED if name in results}
    if "energy" in held:
        held.setdefault("free_energy", held["energy"])
    return held


def _level_property(calc, name: str, atoms):
    """One level's ``name`` at ``atoms`` (its cache when current), as a float or an array."""
    if name == "free_energy" and "free_energy" not in getattr(calc, "results", {}):
        name = "energy"
    if isinstance(calc, BaseCalculator):
        value = calc.get_property(name, atoms)
    elif name in ("energy", "free_energy"):
        value = calc.get_potential_energy(atoms)
    elif name == "forces":
        value = calc.get_forces(atoms)
    else:
        value = calc.get_stress(atoms)
    if value is None:
        raise PropertyNotImplementedError(name)
    return float(value) if name in ("energy", "free_energy") else np.array(value, dtype=float)


def needed_properties(couplings) -> list:
    """``(property, part)`` for each property a coupling part reads of the calculator:
    ``"stress"`` (``needs_stress``: a barostat's pressure) and ``"energy"``
    (``needs_energy``: the Monte Carlo barostat's energy difference).  ``couplings``: the
    parts, or their classes (only class attributes are read)."""
    return [(name, part) for part in couplings
            for name, needed in (("stress", part.needs_stress), ("energy", part.needs_energy))
            if needed]


def missing_property(calc, couplings, declared: bool = False):
    """The first ``(property, part)`` of :func:`needed_properties` that a plain calculator
    declares it lacks, else None.

    A calculator that declares no ``implemented_properties`` lacks nothing here.  Without
    ``declared`` only the energy is judged by the declaration: some calculators give a
    stress they do not declare, so the dynamics looks for it at the first call (where
    :class:`~rigidmd.core.forces.ForceEvaluator` refuses its absence).  With ``declared``
    (a configuration's calculators, which declare what they give) the stress is judged
    so too.
    """
    implemented = getattr(calc, "implemented_properties", None)
    if implemented is None:
        return None
    for name, part in needed_properties(couplings):
        if (declared or name == "energy") and name not in implemented:
            return name, part
    return None


def check_calculator_properties(calc, couplings) -> None:
    """Refuse in one line a calculator that lacks a property a coupling part needs.

    A :class:`MultipleTimeStep` is asked for each of :func:`needed_properties` on each level
    (:meth:`MultipleTimeStep.check_level_properties`); a plain calculator as
    :func:`missing_property` judges it.  Changes nothing.

    Parameters
    ----------
    calc : ase.calculators.calculator.BaseCalculator
        The atoms' calculator.
    couplings : sequence of rigidmd.couplings.base.Coupling
        The dynamics' coupling parts.

    Raises
    ------
    ValueError
        Naming the calculator (or level), the property and the part that needs it.
    """
    if isinstance(calc, MultipleTimeStep):
        for name, part in needed_properties(couplings):
            calc.check_level_properties(name, f"the {part.kind} {part.section}")
        return
    missing = missing_property(calc, couplings)
    if missing is not None:
        name, part = missing
        raise ValueError(f"the calculator {type(calc).__name__} provides no {name} (it "
                         f"implements {', '.join(calc.implemented_properties)}), which the "
                         f"{part.kind} {part.section} needs")
