r"""The force evaluator: one calculator call per step, checked, reduced to the bodies.

:class:`ForceEvaluator` places the atoms through a :class:`~rigidmd.core.link.BodyLink`,
asks the calculator in one call for what the step needs (forces; the stress
when a barostat reads the pressure; the energy when an observer is due),
refuses non-finite results, reduces the forces to body forces and torques and
keeps them, with the molecular virial and the potential energy, in a
:class:`~rigidmd.core.record.StepRecord`.  It does not know who asked.

It also answers energy-only questions about a trial configuration (a Monte
Carlo move of the cell, a line search) and puts the calculator back as it
was when the trial is rejected, without another call::

    saved = evaluator.save_results()
    energy = evaluator.trial_energy(trial_state)     # one call, energy only
    if rejected:
        evaluator.restore_results(saved, state)      # atoms and calculator as before
    else:
        evaluator.evaluate(trial_state)              # the forces the next kick needs

``trial_state`` is a :class:`~rigidmd.core.state.RigidState` (``state.copy()`` with
centres of mass, point particles and cell moved); the evaluator never keeps it.
"""

import numpy as np
from ase import Atoms
from ase.calculators.calculator import BaseCalculator, PropertyNotImplementedError

from rigidmd.core import operators as ops
from rigidmd.core.bodies import check_bodies_fit
from rigidmd.core.dof import RigidBodyDOF
from rigidmd.core.link import BodyLink
from rigidmd.core.record import StepRecord
from rigidmd.core.state import RigidState

__all__ = ["ForceEvaluator", "NonFiniteForceError", "calculate_together", "level_forces"]


class NonFiniteForceError(ValueError):
    """The calculator returned a force, energy or stress that is NaN or infinite."""


def calculate_together(calc, atoms: Atoms, names) -> bool:
    """Have an ASE calculator compute several properties in one call.

    What :meth:`ase.calculators.calculator.BaseCalculator.get_property` does
    for one property, for several: a calculator asked for forces and later
    for the energy or stress of the same positions would otherwise be called
    twice (and LAMMPS, for one, would evaluate the forces twice).
    Calculators without ASE's ``calculate``/``check_state`` are left alone
    (their properties are then asked one by one).

    Returns
    -------
    bool
        True when ``calc.results`` now hold the properties of ``atoms`` as
        they are (False: the calculator was left alone).
    """
    if not (hasattr(calc, "calculate") and hasattr(calc, "check_state")):
        return False
    names = [name for name in names if name in getattr(calc, "implemented_properties", names)]
    changes = calc.check_state(atoms)
    if changes:
        calc.atoms = None
        calc.results = {}
    missing = [name for name in names if name not in calc.results]
    if missing:
        if getattr(calc, "use_cache", True):
            calc.atoms = atoms.copy()
        calc.calculate(atoms, missing, changes)
    return True


def _reads_results(calc, atoms: Atoms) -> bool:
    """Whether ``atoms.get_forces``/``get_stress`` would only copy ``calc.results``.

    True for a calculator that keeps ASE's own ``get_property``, ``get_forces``
    and ``get_stress`` on atoms with no constraint but rigidmd's own
    :class:`~rigidmd.core.dof.RigidBodyDOF` (which changes neither forces nor
    stress): the results just computed can then be read without the further
    ``check_state`` comparisons of the positions that those getters make.
    """
    kind = type(calc)
    return (all(type(c) is RigidBodyDOF for c in atoms.constraints)
            and getattr(kind, "get_property", None) is BaseCalculator.get_property
            and getattr(kind, "get_forces", None) is BaseCalculator.get_forces
            and getattr(kind, "get_stress", None) is BaseCalculator.get_stress)


def level_forces(calc, atoms: Atoms) -> np.ndarray:
    """The forces of ``calc`` on ``atoms`` as ``atoms.get_forces(md=True)`` would give them.

    For a calculator that is not the atoms' own (a level of a force split): the
    atoms' constraints adjust them as ASE does in molecular dynamics.
    """
    forces = np.array(calc.get_forces(atoms), dtype=float)
    for constraint in atoms.constraints:
        if hasattr(constraint, "redistribute_forces_md"):
            constraint.redistribute_forces_md(atoms, forces)
        if hasattr(constraint, "adjust_potential_energy"):
            constraint.adjust_forces(atoms, forces)
    return forces


class ForceEvaluator:
    """Calculator calls for a rigid system, filling a :class:`StepRecord`.

    Parameters
    ----------
    link : BodyLink
        Places the atoms (``link.atoms`` carries the calculator).
    record : StepRecord
        Receives forces, torques, displacements, virial and energy.
    stress : bool
        Ask for the stress at every call and keep the molecular virial.
    cell_moves : bool
        Set the atoms' cell from the state before every call, and check
        that every body stays under half the cell's width.
    calc : ASE calculator, optional
        The calculator to call on the atoms instead of the atoms' own: one
        level of a :class:`~rigidmd.core.split.MultipleTimeStep` (its fast or
        slow part), whose record holds that level's forces alone.
    label : str, default ``"calculator"``
        What a refusal of non-finite forces or energy calls the calculator
        (a split's level names itself: ``"the slow level (LAMMPSCalculator)"``).

    Attributes
    ----------
    step : int
        Steps completed before the step being taken, for the messages
        (:meth:`begin_step` sets it).
    energy_known : bool
        Whether the last call computed the energy.
    """

    def __init__(self, link: BodyLink, record: StepRecord, *, stress: bool = False,
                 cell_moves: bool = False, calc=None, label: str = "calculator"):
        self.link, self.record = link, record
        self.calc = calc  # None: the atoms' calculator
        #: What a refusal calls the calculator (a split's level names itself).
        self.label = label
        self.atoms, self.model = link.atoms, link.model
        self.stress, self.cell_moves = stress, cell_moves
        self._shape = (len(self.atoms), 3)  # of the forces (the atoms cannot change in number)
        self._energy = False  # the energy with the forces (begin_step)
        self._stress = False  # the stress with the forces (begin_step)
        self.energy_known = False
        self.step = 0

    def begin_step(self, step: int, energy: bool = False, stress: bool = False) -> None:
        """What the calls of the step after ``step`` completed steps must compute.

        Parameters
        ----------
        step : int
            Steps completed (for the messages).
        energy : bool
            The energy too, in the same call (an observer or a coupling part
            will read it).
        stress : bool
            The stress too, with a periodic cell (an observer will read it),
            without forming the molecular virial (a barostat's ``stress`` at
            construction forms it at every call).
        """
        self.step, self._energy, self._stress = step, energy, stress

    # ------------------------------------------------------------ one step's call
    def evaluate(self, state: RigidState) -> None:
        """Place the atoms from ``state``, call the calculator, reduce to the bodies."""
        record = self.record
        record.r = self.link.place(state, record.r)
        forces = self.calculator_forces(state)
        record.F, record.tau = ops.reduce_forces(forces, record.r, self.model)
        record.f = forces[self.model.free]

    def calculator_forces(self, state: RigidState, check: bool = True) -> np.ndarray:
        """Call the calculator on the atoms as placed and return checked atom forces.

        With a moving cell the cell is set from ``state`` first (and checked
        against the bodies' extents, with ``record.r`` placed); with
        ``stress`` the stress is asked in the same call and the molecular
        virial kept in the record.  ``check=False`` leaves the forces'
        finiteness to the caller (the fused kernel checks it in its own loop
        and calls :meth:`check_forces` for the message).

        Returns
        -------
        numpy.ndarray, shape (n_atoms, 3)
            eV/Å.
        """
        atoms, record = self.atoms, self.record
        if self.cell_moves and not np.array_equal(atoms.cell.array, state.cell):
            if not self.link.backend.cell_clearly_fits(self.model, state.cell, atoms.pbc):
                check_bodies_fit(self.model, state.cell, atoms.pbc,
                                 f"the barostat's cell at step {self.step + 1} is too small "
                                 "for it; the step was undone")
            atoms.set_cell(state.cell)
        together = self.stress or self._energy or self._stress
        results = None  # the calculator's results, when they are known to be this call's
        if together:
            wanted = ["forces"]
            if self.stress or (self._stress and atoms.pbc.all()):
                wanted.append("stress")  # a barostat, or an observer (a stress recorder)
            if self._energy:
                wanted.append("energy")  # a logger will ask: one calculator call, not two
            calc = atoms.calc if self.calc is None else self.calc
            if (len(wanted) > 1 and calculate_together(calc, atoms, wanted)
                    and _reads_results(calc, atoms) and "forces" in calc.results):
                results = calc.results
        if results is not None:  # what atoms.get_forces would copy, without its checks
            forces = np.array(results["forces"], dtype=float)
        elif self.calc is None:
            forces = np.asarray(atoms.get_forces(md=True), dtype=float)
        else:
            forces = level_forces(self.calc, atoms)
        if forces.shape != self._shape:
            raise ValueError(f"calculator returned forces of shape {forces.shape}, "
                             f"expected {(len(atoms), 3)}")
        if check or together:  # the energy's and stress's messages assume finite forces
            self.check_forces(forces)
        record.energy = None
        calc = atoms.calc if self.calc is None else self.calc
        self.energy_known = self._energy and "energy" in getattr(calc, "results", {})
        if self.energy_known:
            results = calc.results
            energy = results["energy"]
            if not np.isfinite(energy):
                raise NonFiniteForceError(
                    f"{self.label} returned a non-finite energy ({energy}) with finite forces "
                    f"after step {self.step}; the atoms are left at step {self.step}")
            record.energy = float(energy)
        if self.stress:
            stress = None if results is None else results.get("stress")
            record.virial = self.molecular_virial(forces, stress)
        return forces

    def check_forces(self, forces: np.ndarray) -> None:
        """Refuse forces with a NaN or an infinity, naming the atoms (NonFiniteForceError)."""
        # One reduction: a NaN or an infinity anywhere makes the sum non-finite.
        if not np.isfinite(forces.sum()):
            bad = np.flatnonzero(~np.isfinite(forces).all(axis=1))
            raise NonFiniteForceError(
                f"{self.label} returned non-finite forces on atom(s) {bad[:10].tolist()} "
                f"after step {self.step}; the atoms are left at step {self.step}")

    def molecular_virial(self, forces: np.ndarray,
                         stress: np.ndarray | None = None) -> np.ndarray:
        r"""The molecular virial (eV, 3x3) at the atoms as placed: atomic less intramolecular.

        ``stress`` (eV/Å³, 3x3 or ASE's Voigt order) is the calculator's stress of these
        positions when the caller already has it; otherwise it is asked through
        ``atoms.get_stress``.
        """
        atoms = self.atoms
        calc = atoms.calc if self.calc is None else self.calc
        if stress is None:
            try:
                stress = (atoms.get_stress(voigt=False, include_ideal_gas=False)
                          if self.calc is None else self.calc.get_stress(atoms))
            except PropertyNotImplementedError:
                raise PropertyNotImplementedError(
                    f"the calculator {type(calc).__name__} provides no stress, so the "
                    "pressure is unknown; use a calculator with stress (e.g. "
                    "rigidmd.lammps.LAMMPSCalculator)") from None
        stress = np.asarray(stress, dtype=float)
        if not np.isfinite(stress.sum()):
            raise NonFiniteForceError(f"calculator returned a non-finite stress "
                                      f"{stress.tolist()} after step {self.step}")
        return self.link.backend.molecular_virial(stress, self.record.volume, self.record.r,
                                                  forces, self.model)

    # ------------------------------------------------------------ trial configurations
    def save_results(self) -> tuple:
        """The calculator's results and the atoms' cell, for :meth:`restore_results`."""
        calc = self.atoms.calc
        results = dict(getattr(calc, "results", {}))
        cached = getattr(calc, "atoms", None)
        return results, None if cached is None else cached.copy(), self.atoms.cell.array.copy()

    def trial_energy(self, state: RigidState) -> float:
        """Potential energy (eV) with the atoms placed from a trial ``state`` (and its cell).

        One calculator call, energy only.  The atoms keep the trial
        positions: :meth:`restore_results` puts them and the calculator back
        on rejection, :meth:`evaluate` gives the forces on acceptance.
        """
        atoms = self.atoms
        self.link.place(state)
        if not np.array_equal(atoms.cell.array, state.cell):
            check_bodies_fit(self.model, state.cell, atoms.pbc, "a trial cell")
            atoms.set_cell(state.cell)
        energy = float(atoms.get_potential_energy())
        if not np.isfinite(energy):
            raise NonFiniteForceError(f"calculator returned a non-finite energy ({energy}) "
                                      "for a trial configuration")
        return energy

    def restore_results(self, saved: tuple, state: RigidState) -> None:
        """Put back the atoms of ``state`` and the calculator results :meth:`save_results` kept.

        No calculator call: the next force call finds its results current.
        """
        results, cached, cell = saved
        self.atoms.set_cell(cell)
        self.record.r = self.link.place(state, self.record.r)
        calc = self.atoms.calc
        if hasattr(calc, "results"):
            calc.results = results
            if cached is not None:
                calc.atoms = cached
