"""Checks of what a user hands a rigid dynamics, run before any state changes.

Each raises one ``ValueError`` (or ``TypeError``) naming the atom, the cell
vector or the parameter at fault.
"""

import copy
import os
import warnings
from pathlib import Path

import numpy as np
from ase import Atoms, units
from ase.constraints import FixCom

from rigidmd.core.backend import resolve_backend
from rigidmd.core.dof import RigidBodyDOF, kinetic_energy

__all__ = ["real_number", "check_finite", "check_output_file", "check_massless_momenta",
           "check_timestep", "check_constraints", "changed_properties", "StepSizeCheck",
           "MAX_ROTATION_PER_STEP", "MAX_ENERGY_CHANGE"]


def real_number(name: str, value, what: str) -> float:
    """``value`` as a float, or one TypeError naming ``name`` and ``what`` it must be.

    The one type rule for every number a user hands rigidmd's classes and functions (the
    configuration file has its own, :mod:`rigidmd.config.quantities`): whatever Python's
    ``float`` takes, except ``True``/``False`` and text, which ``float`` also takes
    (``pressure_au=True`` would read as 1 eV/Å³, 160 GPa; ``timestep="1"`` as 1 ASE time
    unit, about 10 fs).

    Parameters
    ----------
    name : str
        The argument's name as the message shows it, e.g. ``"temperature_K"``.
    value : object
    what : str
        What it must be, e.g. ``"a number (K)"``.

    Returns
    -------
    float
        Not checked for finiteness or sign: each caller states its own bound.
    """
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise TypeError(f"{name} must be {what}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be {what}, got {value!r}") from None


def check_timestep(timestep: float) -> float:
    """``timestep`` as a positive finite float (ASE time units), or a clear error.

    A bool or a string is refused (``"1"`` and ``True`` read as 1 ASE time unit, about
    10 fs), as ASE's ``timestep`` is a number of ASE time units."""
    dt = real_number("timestep", timestep, "a number of ASE time units (1 * ase.units.fs "
                     "for 1 fs)")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"timestep must be positive and finite, got {timestep!r}")
    return dt


def check_finite(values, quantity: str, unit: str, when: str = "") -> None:
    """Raise a ValueError naming the first atom whose ``quantity`` is NaN or infinite.

    One reduction when everything is finite (a NaN or an infinity anywhere
    makes the sum non-finite).
    """
    values = np.asarray(values, dtype=float)
    if np.isfinite(values.sum()):
        return
    bad = np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))
    what = "cell vector" if quantity == "cell" else "atom"
    raise ValueError(f"{what} {int(bad[0])} has a non-finite {quantity} "
                     f"{values[bad[0]].tolist()} ({unit}){' ' + when if when else ''}"
                     f"{f'; {len(bad)} in all' if len(bad) > 1 else ''}")


def check_massless_momenta(atoms: Atoms, when: str = "") -> None:
    """Refuse a momentum on an atom of mass 0: a virtual site only moves with its body.

    ASE's velocity tools (``MaxwellBoltzmannDistribution``, ``Stationary``,
    ``set_velocities``) give such atoms zero momentum; a non-zero one was set
    by hand and has no rigid-body meaning, so it is refused, not dropped.
    """
    masses = atoms.get_masses()
    if np.all(masses > 0):
        return
    momenta = atoms.get_momenta()
    bad = np.flatnonzero((masses == 0) & np.any(momenta != 0, axis=1))
    if bad.size:
        a = int(bad[0])
        raise ValueError(
            f"atom {a} ({atoms[a].symbol}) has mass 0 but momentum {momenta[a].tolist()} "
            f"(amu Å / ASE time){' ' + when if when else ''}: a massless atom (a virtual site) "
            "moves with its body; give it zero momentum")


def check_constraints(atoms: Atoms) -> bool:
    """Refuse ASE constraints other than FixCom; returns whether FixCom is there."""
    others = [c for c in atoms.constraints if not isinstance(c, (RigidBodyDOF, FixCom))]
    if others:
        raise ValueError(
            f"rigid-body dynamics cannot honour other ASE constraints ({others[0]!r}); "
            "remove them (rigid bodies replace bond constraints; atoms in no body are "
            "free point particles; FixCom is honoured)"
        )
    return any(isinstance(c, FixCom) for c in atoms.constraints)


def quick_check_state(calc, atoms: Atoms, tol: float, ase_check_state):
    """A calculator's ``check_state`` through :func:`changed_properties` where it can.

    ``ase_check_state``: ASE's own (the calculator's ``super().check_state``),
    asked when there is nothing to compare with, with ``ignored_changes``, or
    when the atoms differ in size or in the arrays they carry.
    """
    if calc.atoms is None or calc.ignored_changes:
        return ase_check_state(atoms, tol)
    changes = changed_properties(calc.atoms, atoms, tol)
    return ase_check_state(atoms, tol) if changes is None else changes


def copy_atoms(atoms: Atoms, previous: Atoms | None = None) -> Atoms:
    """``atoms.copy()``, written into ``previous`` (an earlier such copy) when it fits.

    What a calculator keeps of the atoms it computed (``calc.atoms``, compared by
    ``check_state``) at every call.  ``Atoms.copy`` builds a new object (0.013 ms
    on 648 atoms here, 0.03 ms inside a 216-water step, a tenth of rigidmd's own
    share of it); ``previous`` with the same arrays (names, shapes, dtypes) gets
    the arrays, cell, pbc, cell displacement, info and constraints instead, when
    both are plain :class:`ase.Atoms`.  Only a calculator's own copy, which nobody
    else holds, may be given.

    Returns
    -------
    ase.Atoms
        ``previous`` rewritten, or a new copy.
    """
    if type(atoms) is not Atoms or type(previous) is not Atoms:
        return atoms.copy()  # (a subclass may copy more than ASE's Atoms.copy does)
    old, new = previous.arrays, atoms.arrays
    if old.keys() != new.keys() or any(old[name].shape != a.shape or old[name].dtype != a.dtype
                                       for name, a in new.items()):
        return atoms.copy()
    for name, a in new.items():
        np.copyto(old[name], a)
    np.copyto(previous.cell.array, atoms.cell.array)
    np.copyto(previous.pbc, atoms.pbc)
    previous.set_celldisp(atoms.get_celldisp())
    previous.info = dict(atoms.info)
    previous.constraints = copy.deepcopy(atoms.constraints)
    return previous


def changed_properties(old: Atoms, atoms: Atoms, tol: float = 1e-15):
    """ASE's ``compare_atoms`` for atoms of the same size and arrays, in a few array operations.

    Parameters
    ----------
    old, atoms : ase.Atoms
        The atoms of the last calculation and the atoms asked about.
    tol : float
        Each of ASE's ``all_changes`` counts as changed unless its arrays are equal
        or ``numpy.allclose(old, new, rtol=tol, atol=tol)`` (an infinity is close only
        to itself).  ASE 3.29's ``compare_atoms`` takes ``tol`` as an absolute
        tolerance alone: a change under ``tol`` relative (a rounding of a coordinate)
        counts as a change there and not here.

    Returns
    -------
    list of str or None
        The changed properties, as ASE's ``compare_atoms`` finds them; None when
        the atoms differ in size or in the arrays they carry (ask ASE then).
    """
    from ase.calculators.calculator import all_changes

    if len(old) != len(atoms) or set(old.arrays) != set(atoms.arrays):
        return None
    pairs = [("cell", old.cell.array, atoms.cell.array), ("pbc", old.pbc, atoms.pbc)]
    pairs += [(name, old.arrays[name], atoms.arrays[name]) for name in all_changes
              if name in old.arrays]
    changes, backend = [], resolve_backend(None)
    for name, a, b in pairs:
        if a.shape != b.shape:
            changes.append(name)
        elif a.dtype == b.dtype == np.float64:
            # On the default backend: one compiled pass when numba is installed.
            if not backend.equal_or_close(a, b, tol):
                changes.append(name)
        elif not np.array_equal(a, b) and (a.dtype == bool or not np.allclose(a, b, tol, tol)):
            changes.append(name)
    return changes


#: A body turning more than this per step (rad) means the step is too large.  Measured on
#: 27 TIP3P waters at 300 K over 1 ps: the largest |omega| dt is 0.07, 0.14, 0.25 and
#: 0.33 rad at 1, 2, 4 and 6 fs.
MAX_ROTATION_PER_STEP = 0.5
#: Change of the conserved energy, as a fraction of the kinetic energy, that means the
#: step is too large.  Same runs: at most 0.07 %, 0.23 %, 0.7 % and 2.5 % at 1-6 fs.
MAX_ENERGY_CHANGE = 0.1


class StepSizeCheck:
    """An observer that warns once when the time step is evidently too large.

    Two signs, both cheap: a body turning by more than
    :data:`MAX_ROTATION_PER_STEP` rad in one step (checked every 10 steps),
    and a conserved energy that moved by more than :data:`MAX_ENERGY_CHANGE`
    of the kinetic energy since the first step at which the energy was known
    (computed because another observer was due at that step).  A dynamics
    attaches one at every step; it reads only (``modifies_atoms``) and asks
    the calculator for nothing (``wants_properties``).

    Parameters
    ----------
    dyn : rigidmd.core.dynamics.RigidDynamics
        Read through its public attributes: ``nsteps``, ``dt``, ``model``,
        ``state``, ``link``, ``evaluator``, ``atoms``, ``get_conserved_energy()``.
    """

    modifies_atoms = False
    wants_properties = False
    #: Steps between calls (the rotation is checked every 10 steps).
    interval = 1

    def __init__(self, dyn):
        self.dyn, self.evaluator = dyn, dyn.evaluator
        self.reference = None  # (step, conserved energy) compared to
        self.warned = False

    def reset(self) -> None:
        """Forget the energy reference (the time step, the target or the atoms changed)."""
        self.reference = None

    def __call__(self) -> None:
        dyn = self.dyn
        step = dyn.nsteps
        rotation = step % 10 == 0
        if self.warned or step == 0 or not (rotation or self.evaluator.energy_known):
            return  # step 0: no step taken yet; else nothing to check at this step
        dt, message, turned = dyn.dt, None, False
        # Under a force split the bodies turn in the inner steps: the rotation is theirs.
        split = getattr(self.evaluator, "split", None)
        if split is not None:
            dt = dt / split.substeps
        if rotation and dyn.model.n_bodies:
            b, speed = dyn.link.largest_angular_speed(dyn.state)
            if speed * dt > MAX_ROTATION_PER_STEP:
                message = (f"body {b} turns by {speed * dt:.2f} rad per "
                           f"{'step' if split is None else 'inner step'} at step "
                           f"{step} (above {MAX_ROTATION_PER_STEP} rad)")
                turned = True
        if message is None and dyn.evaluator.energy_known:
            energy = dyn.get_conserved_energy()
            if self.reference is None:
                self.reference = (step, energy)
            else:
                first, reference = self.reference
                change = energy - reference
                kinetic = kinetic_energy(dyn.atoms)
                if abs(change) > MAX_ENERGY_CHANGE * kinetic + 1e-6:
                    message = (f"the conserved energy changed by {change:+.4g} eV from step "
                               f"{first} to step {step}, {abs(change) / kinetic:.0%} of the "
                               f"kinetic energy ({kinetic:.4g} eV)")
        if message is not None:
            self.warned = True
            if split is None:
                cause = f": the time step {dt / units.fs:g} fs is probably too large"
            elif turned:
                cause = (f": the inner step (timestep / {split.substeps}) {dt / units.fs:g} "
                         "fs is probably too large")
            else:  # the slow forces' outer step, or the fast forces' inner step
                cause = (f": the outer step {dyn.dt / units.fs:g} fs (the slow forces; "
                         f"resonances past a third of their fastest period) or the inner "
                         f"step {dt / units.fs:g} fs is probably too large")
            warnings.warn(f"{type(dyn).__name__}: {message}{cause}", stacklevel=5)


def check_output_file(name: str, path) -> None:
    """Refuse a ``trajectory`` or ``logfile`` path that cannot be written (a folder that does
    not exist, one not writable, a folder given as the file), before the constructor changes
    anything: it used to fail after the atoms' momenta, tags and constraints had changed
    and ASE had already replaced the trajectory file.  Open files and ``"-"`` pass."""
    if not isinstance(path, (str, os.PathLike)) or str(path) == "-":
        return
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise FileNotFoundError(f"{name}: the folder {folder} does not exist (for {path})")
    if path.is_dir():
        raise IsADirectoryError(f"{name}: {path} is a folder; give a file name")
    if not os.access(path if path.exists() else folder, os.W_OK):
        raise PermissionError(f"{name}: {path} cannot be written (permission denied)")
