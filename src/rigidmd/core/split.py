r"""A force split for multiple time steps: :class:`MultipleTimeStep`.

``MultipleTimeStep(fast, slow, substeps=k)`` is an ASE calculator whose energy,
forces and stress are the sums of its two calculators', so any ASE code
(optimizers, ``atoms.get_potential_energy()``, analyses) sees the full model.
Every rigidmd dynamics whose atoms carry one integrates it by r-RESPA
(Tuckerman, Berne & Martyna 1992; :mod:`rigidmd.core.respa`): the dynamics'
``timestep`` is the outer step, the slow forces and torques kick for half of it
on each side of ``k`` NO_SQUISH steps of ``timestep / k`` with the fast forces.

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

__all__ = ["MultipleTimeStep", "check_substeps"]

_SUMMED = ("energy", "free_energy", "forces", "stress")


def check_substeps(substeps) -> int:
    """``substeps`` as an int of at least 1; a TypeError or ValueError in one line otherwise."""
    if isinstance(substeps, bool) or not isinstance(substeps, Integral):
        raise TypeError(f"MultipleTimeStep: substeps must be a whole number of inner steps "
                        f"per outer step, got {substeps!r}")
    if substeps < 1:
        raise ValueError(f"MultipleTimeStep: substeps must be at least 1, got {substeps}")
    return int(substeps)


def _check_level(name: str, calc) -> None:
    if calc is None:
        raise TypeError(f"MultipleTimeStep: the {name} calculator is missing (None)")
    if isinstance(calc, MultipleTimeStep):
        raise TypeError(f"MultipleTimeStep: the {name} calculator is itself a "
                        "MultipleTimeStep; nest levels by splitting one of them instead")
    if not callable(getattr(calc, "get_forces", None)):
        raise TypeError(f"MultipleTimeStep: the {name} calculator must be an ASE calculator "
                        f"(with get_forces), got {type(calc).__name__}")


class MultipleTimeStep(Calculator):
    """An ASE calculator: the sum of a fast and a slow calculator, integrated by r-RESPA.

    Parameters
    ----------
    fast : ASE calculator
        The rapidly varying forces (bonded, short-range pair): called ``substeps``
        times per outer step of a rigidmd dynamics.
    slow : ASE calculator
        The slowly varying rest (long-range electrostatics, the difference between
        an expensive model and a cheap one): called once per outer step.
    substeps : int, default 1
        Inner steps per outer step (``k``); the dynamics' ``timestep`` is the
        outer step.  ``1`` is the impulse form of velocity Verlet.

    Raises
    ------
    TypeError
        A calculator missing or not an ASE calculator, or ``substeps`` not a whole number.
    ValueError
        ``substeps`` below 1.

    Notes
    -----
    Energy, free energy, forces and stress are sums; a property one level lacks
    (e.g. stress) raises :class:`~ase.calculators.calculator.PropertyNotImplementedError`
    naming that level.  Outside a rigidmd dynamics (an optimizer, an ASE integrator)
    the split plays no part: the sum is the model.
    """

    implemented_properties = list(_SUMMED)

    def __init__(self, fast, slow, substeps: int = 1):
        _check_level("fast", fast)
        _check_level("slow", slow)
        k = check_substeps(substeps)
        super().__init__()
        self.fast, self.slow, self._substeps = fast, slow, k
        # What both levels compute (a property one lacks is no property of the sum).
        own = [getattr(calc, "implemented_properties", _SUMMED) for calc in (fast, slow)]
        self.implemented_properties = [
            name for name in _SUMMED
            if all(name in names or (name == "free_energy" and "energy" in names)
                   for names in own)]

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

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        """Sum the levels' properties (each level computes what is asked in one call)."""
        super().calculate(atoms, properties, system_changes)
        atoms = atoms if atoms is not None else self.atoms
        wanted = [name for name in properties if name in _SUMMED]
        sums = {}
        for level, calc in self.levels:
            names = [name for name in wanted
                     if name in getattr(calc, "implemented_properties", _SUMMED)]
            calculate_together(calc, atoms, names)
            for name in wanted:
                try:
                    value = _level_property(calc, name, atoms)
                except PropertyNotImplementedError:
                    if name in properties:
                        raise PropertyNotImplementedError(
                            f"MultipleTimeStep: the {level} calculator "
                            f"{type(calc).__name__} provides no {name}") from None
                    continue
                sums[name] = value if name not in sums else sums[name] + value
        if "energy" in sums and "free_energy" not in sums:
            sums["free_energy"] = sums["energy"]
        self.results.update(sums)

    def check_level_properties(self, name: str, needed_by: str) -> None:
        """Refuse in one line a level that lacks ``name`` (e.g. ``"stress"``), naming it."""
        for level, calc in self.levels:
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
        return {"fast": type(self.fast).__name__, "slow": type(self.slow).__name__,
                "substeps": self._substeps}


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
