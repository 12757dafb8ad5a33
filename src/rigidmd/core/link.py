r"""The body link: an :class:`ase.Atoms` on one side, the rigid state on the other.

:class:`BodyLink` places the atoms from a :class:`~rigidmd.core.state.RigidState`
(massless virtual sites too), writes their momenta, reads positions and
momenta back (a best rigid fit and a projection onto rigid motion), and
notices changes made to the Atoms between steps; :class:`AtomsSync`, its change
detection for a dynamics, calls the observers, remembers what was written and
reads a change before the next step.  The backend
(:mod:`rigidmd.core.backend`: the compiled loops or the NumPy operators) is
chosen once, at construction, and carried here for every part that computes.
It never calls a calculator; an optimizer or a Monte Carlo move can use it
without a dynamics::

    link = BodyLink(atoms, geometry.model)
    state = link.initial_state(geometry)
    r = link.place(state)          # atoms.positions now hold the rigid positions
"""

import warnings

import numpy as np
from ase import Atoms
from ase.constraints import FixCom
from ase.io.trajectory import TrajectoryWriter
from ase.md.logger import MDLogger

from rigidmd.core import observables as obs
from rigidmd.core import operators as ops
from rigidmd.core.backend import Backend, resolve_backend
from rigidmd.core.bodies import molecule_ids, unwrap_bodies
from rigidmd.core.checks import check_constraints, check_finite, check_massless_momenta
from rigidmd.core.dof import RigidBodyDOF
from rigidmd.core.model import BodyGeometry, BodyModel
from rigidmd.core.state import RigidState

__all__ = ["BodyLink", "AtomsSync", "FIT_TOLERANCE"]

#: Largest rigid-fit residual (Å) accepted silently when re-reading positions.
FIT_TOLERANCE = 1e-6


class BodyLink:
    """Atoms ↔ rigid state, with the backend chosen once.

    Parameters
    ----------
    atoms : ase.Atoms
        Written in place: ``atoms.arrays["positions"]`` and ``["momenta"]``.
    model : BodyModel
    backend : {None, "numba", "numpy"} or Backend
        See :func:`rigidmd.core.backend.resolve_backend`.

    Attributes
    ----------
    atoms, model
    backend : rigidmd.core.backend.Backend
        The backend every part that computes for this link runs on (the record,
        the force evaluator, the stepper and the coupling parts read it here).
    removed_kinetic_energy : float
        Kinetic energy (eV) the last :meth:`read_momenta` removed by projecting
        the atoms' velocities onto rigid motion.
    """

    def __init__(self, atoms: Atoms, model: BodyModel, backend: "str | Backend | None" = None):
        self.atoms, self.model = atoms, model
        self.backend = resolve_backend(backend)
        self.masses = atoms.get_masses()
        self.removed_kinetic_energy = 0.0

    def initial_state(self, geometry: BodyGeometry) -> RigidState:
        """The state of measured bodies at rest (velocities are read by :meth:`read_momenta`)."""
        m, atoms = self.model, self.atoms
        return RigidState(
            X=geometry.com.copy(), V=np.zeros((m.n_bodies, 3)), q=geometry.quaternions.copy(),
            p=np.zeros((m.n_bodies, 4)), x=atoms.positions[m.free].copy(),
            v=np.zeros((m.n_free, 3)), cell=atoms.cell.array.copy())

    # ------------------------------------------------------------ state -> atoms
    def place(self, state: RigidState, r: np.ndarray | None = None) -> np.ndarray:
        """Write the rigid positions of ``state`` to the atoms; returns the lab displacements.

        ``r`` (shape (n_body_atoms, 3)) is filled in place on the compiled
        path, whose arithmetic is the kernel's, so a restored state gives
        bit-identical positions.
        """
        m = self.model
        positions = self.atoms.arrays["positions"]
        r = self.backend.place(state, m, r, positions)
        positions[m.free] = state.x
        return r

    def write_momenta(self, state: RigidState, r: np.ndarray) -> None:
        """Write the rigid momenta of ``state`` to the atoms (positions placed with ``r``)."""
        m = self.model
        momenta = self.atoms.arrays["momenta"]
        self.backend.write_momenta(state, m, r, momenta)
        if m.n_free:
            momenta[m.free] = m.free_masses[:, None] * state.v

    def largest_angular_speed(self, state: RigidState) -> tuple[int, float]:
        """The body turning fastest and its :math:`|\\omega|` (rad / ASE time), on the backend.

        See :func:`rigidmd.core.observables.largest_angular_speed`; the compiled
        loop gives the same numbers without two dozen array operations.
        """
        return self.backend.largest_angular_speed(state, self.model)

    # ------------------------------------------------------------ atoms -> state
    def read_momenta(self, state: RigidState, previous: np.ndarray | None = None,
                     owner: str = "RigidDynamics") -> float:
        """Project the atoms' velocities onto rigid motion of the bodies; returns the KE removed.

        With ``previous`` (the momenta last written to the atoms, positions
        unchanged since), a body whose atom momenta were all scaled by one
        factor (a velocity flip, a rescaling) has its whole momentum scaled
        instead of projected afresh.  This keeps, bit for bit, the axial
        NO_SQUISH momentum of a linear body, which its atoms' velocities
        cannot express, so that flipping velocities reverses a run exactly.
        A removal above roundoff is reported by a warning naming ``owner``.
        """
        m, atoms = self.model, self.atoms
        momenta = atoms.get_momenta()
        # Massless atoms (virtual sites) carry no momentum (check_massless_momenta).
        massive = self.masses > 0
        ke_atoms = 0.5 * np.sum(momenta[massive] ** 2 / self.masses[massive, None])
        r, _ = ops.place_atoms(state, m)
        V, L_body = ops.rigid_projection(momenta[m.order], r, state.q, m)
        p = ops.conjugate_momentum(state.q, L_body)
        if previous is not None:
            scale, uniform = ops.uniform_rescale(momenta[m.order], previous[m.order], m)
            V = np.where(uniform[:, None], scale[:, None] * state.V, V)
            p = np.where(uniform[:, None], scale[:, None] * state.p, p)
        state.V, state.p = V, p
        state.v = momenta[m.free] / m.free_masses[:, None]
        ke_rigid = (float(obs.translational_kinetic_energies(state, m).sum()
                          + obs.free_kinetic_energy(state, m))
                    + obs.rotational_kinetic_energy(state, m))
        removed = float(ke_atoms - ke_rigid)
        self.removed_kinetic_energy = removed
        # Rigid input loses only roundoff (~1e-16 of the kinetic energy).
        if removed > 1e-10 * ke_atoms + 1e-12:
            warnings.warn(
                f"{owner}: projecting the atoms' velocities onto rigid-body motion removed "
                f"{removed:.6g} eV of kinetic energy ({100 * removed / ke_atoms:.3g}% of "
                f"{ke_atoms:.6g} eV)", stacklevel=5)
        return removed

    def read_positions(self, state: RigidState, owner: str = "RigidDynamics") -> None:
        """Refit centres of mass and orientations to the atoms' positions (and the cell)."""
        m, atoms = self.model, self.atoms
        state.cell = atoms.cell.array
        x = unwrap_bodies(atoms, m.order, m.starts, m.atom_body)
        if m.n_bodies:
            X, q, residual = ops.fit_bodies(x, m)
            worst = int(np.argmax(residual))
            if residual[worst] > FIT_TOLERANCE:
                warnings.warn(
                    f"{owner}: the atoms of body {worst} are {residual[worst]:.3g} Å from a "
                    "rigid image of the body; they were moved onto it", stacklevel=5)
            state.X, state.q = X, q
        state.x = atoms.positions[m.free].copy()

    # ------------------------------------------------------------ changes between steps
    def snapshot(self) -> tuple:
        """Copies of the atoms' positions, momenta and cell, to compare with later."""
        atoms = self.atoms
        return (atoms.arrays["positions"].copy(), atoms.arrays["momenta"].copy(),
                atoms.cell.array.copy())

    def differs(self, snapshot: tuple) -> bool:
        """Whether positions, momenta or cell differ from ``snapshot``."""
        positions, momenta, cell = snapshot
        atoms = self.atoms
        return not (np.array_equal(atoms.arrays["positions"], positions)
                    and np.array_equal(atoms.arrays["momenta"], momenta)
                    and np.array_equal(atoms.cell.array, cell))

    def check_unchanged_system(self) -> None:
        """Refuse atoms added or removed, or masses changed, since construction."""
        atoms = self.atoms
        if len(atoms) != self.model.n_atoms:
            raise ValueError(f"the atoms changed from {self.model.n_atoms} to {len(atoms)}; "
                             "create a new dynamics")
        if not np.array_equal(atoms.get_masses(), self.masses):
            raise ValueError("the atoms' masses changed; create a new dynamics")

    def changes_since(self, written: tuple, when: str) -> tuple[bool, bool]:
        """(moved, kicked): what changed since ``written``, checked finite; nothing is read yet."""
        atoms = self.atoms
        positions, momenta, cell = written
        moved = not (np.array_equal(atoms.positions, positions)
                     and np.array_equal(atoms.cell.array, cell))
        kicked = not np.array_equal(atoms.get_momenta(), momenta)
        if moved:
            check_finite(atoms.positions, "position", "Å", when)
            check_finite(atoms.cell.array, "cell", "Å", when)
        if kicked:
            new = atoms.get_momenta()
            check_finite(new, "momentum", "amu Å / ASE time", when)
            check_massless_momenta(atoms, when)
            if not new.any() and momenta.any() and not self.masses.all():
                warnings.warn(
                    "every momentum was set to zero between steps, and the atoms have massless "
                    "sites: ASE's Stationary, ZeroRotation and force_temperature read a NaN "
                    "temperature there and zero the momenta; rigidmd.rigid_stationary and "
                    "rigidmd.rigid_zero_rotation do what they mean (going on from rest)",
                    stacklevel=4)
        return moved, kicked


def _observer_reads_only(function) -> bool:
    """True for observers known not to change the Atoms (ASE's logger and writer, ours)."""
    owner = getattr(function, "__self__", function)
    return (isinstance(owner, (MDLogger, TrajectoryWriter))
            or getattr(owner, "modifies_atoms", True) is False)


class AtomsSync:
    """The body link's change detection: what was written to the Atoms, and what changed since.

    A dynamics writes the atoms once per step (:meth:`write_atoms`).  Code
    that runs between steps (an observer, the caller of ``irun``, a user
    between two ``run`` calls) may change positions, momenta or the cell;
    this object notices it (a snapshot before the code, compared after it)
    and reads the change into the state before the next step
    (:meth:`sync`), refitting moved bodies.  Observers known to only read
    (ASE's logger and trajectory writer, objects with ``modifies_atoms =
    False``) cost no snapshot.

    Parameters
    ----------
    link : BodyLink
    state : rigidmd.core.state.RigidState
    record : rigidmd.core.record.StepRecord
    body_ids : numpy.ndarray of int
        Each atom's body (-1: free), for the degree-of-freedom marker.
    fixcom : bool
        ASE's ``FixCom`` is on the atoms (the total momentum is held at zero).
    holds_momentum : bool
        The total momentum is held (``FixCom`` or a thermostat's ``fixcm``).
    """

    def __init__(self, link: BodyLink, state: RigidState, record, body_ids: np.ndarray,
                 fixcom: bool, holds_momentum: bool):
        self.link, self.state, self.record = link, state, record
        self.body_ids, self.fixcom, self.holds_momentum = body_ids, fixcom, holds_momentum
        self.synced = None        # (positions, momenta, cell) at the end of the last run
        self.changed = None       # (positions, momenta, cell) written before a change
        self.forces_current = False  # forces restored from a checkpoint: no call at a start
        #: The calculator whose forces the record held when the last run ended (None before
        #: the first run ends): at the next start its forces are still the record's if it
        #: holds results for the atoms as they are (:meth:`forces_still_current`).
        self.calculator = None
        self.reads_only = {}  # observer -> whether it is known to only read the Atoms
        #: This dynamics' degree-of-freedom marker (:meth:`mark_atoms`); None before.
        self.marker = None

    def mark_atoms(self) -> None:
        """Put the rigid degree-of-freedom marker in ``atoms.constraints`` (FixCom kept)."""
        atoms, model = self.link.atoms, self.link.model
        removed = 3 * len(atoms) - model.degrees_of_freedom
        held = 3 if self.holds_momentum and not self.fixcom else 0
        # (fixcm keeps the total momentum; FixCom counts its own 3)
        marker = RigidBodyDOF(removed + held, molecule_ids(self.body_ids), held)
        kept = [c for c in atoms.constraints if isinstance(c, FixCom)]
        atoms.constraints = kept + [marker]
        self.marker = marker

    def write_atoms(self) -> None:
        """Write positions and rigid momenta of the state to the atoms, and remember them."""
        record, link = self.record, self.link
        record.r = link.place(self.state, record.r)
        link.write_momenta(self.state, record.r)
        self.synced = link.snapshot()

    def sync(self, written: tuple, evaluate, step: int, owner: str = "RigidDynamics") -> bool:
        """Read changes made to the Atoms since ``written`` (positions, momenta, cell) was true.

        Moved atoms are refitted and ``evaluate()`` gives their forces; ``step``
        (steps completed) is for the messages.
        Returns whether anything changed.
        """
        link, state, record = self.link, self.state, self.record
        atoms = link.atoms
        link.check_unchanged_system()
        if check_constraints(atoms) != self.fixcom:
            raise ValueError("FixCom was added to or removed from the atoms; create a new "
                             "dynamics")
        if not any(c is self.marker for c in atoms.constraints):
            # absent, or another dynamics' (its count of degrees of freedom and its
            # molecules): the atoms carry this dynamics' own while it runs
            self.mark_atoms()
        moved, kicked = link.changes_since(written, f"(set after step {step}; nothing was "
                                                    "changed)")
        # The state's assignments move its versions: the record's sums follow.
        if moved:
            link.read_positions(state, owner=owner)
        if moved or kicked:
            link.read_momenta(state, previous=None if moved else written[1], owner=owner)
            if self.fixcom:
                ops.remove_centre_velocity(state, link.model)
            self.write_atoms()
            record.scratch.clear()
        if moved:
            evaluate()
        return moved or kicked

    def start(self, evaluate, step: int, owner: str = "RigidDynamics") -> bool:
        """At a run's start: read changes since the last run, and have current forces.

        Returns whether the atoms had changed.
        """
        changed = self.sync(self.synced, evaluate, step, owner)
        if not changed and self.forces_current:
            self.record.r = self.link.place(self.state, self.record.r)  # the restored forces'
        elif changed or not self.forces_still_current():
            evaluate()
        self.forces_current = False
        self.record.forces_known = True
        return changed

    def restored(self, forces_known: bool) -> None:
        """A state was restored (``set_state``), its atoms written: the next start uses its
        forces when it had them (no calculator call), and calls the calculator when it
        had none (exported before the first force call), as the original's start would."""
        self.forces_current = forces_known
        if not forces_known:
            self.calculator = None  # whatever the calculator holds is not the record's

    def finish_run(self) -> None:
        """At a run's end (or its interruption): what was written, and whose forces those are."""
        self.synced = self.link.snapshot()
        self.calculator = self.link.atoms.calc

    def forces_still_current(self) -> bool:
        """Whether the record's forces are those of the calculator for the atoms as they are.

        True when the calculator that computed them at the last run's end is still the
        atoms' and still holds forces for these atoms (ASE's ``check_state``: positions,
        cell, numbers, charges): a new calculator, ``calc.reset()``, changed parameters
        (ASE's ``set`` resets the results) or moved atoms make it False.  Then a run's
        start need not call the calculator again, as ASE's dynamics ask the calculator,
        whose cache answers: ``run(10); run(10)`` is ``run(20)`` bit for bit on both
        backends (a new call, with NumPy's reduction of the forces to the bodies, would
        differ from the compiled kernel's in the last bit).
        """
        calc = self.link.atoms.calc
        if calc is None or calc is not self.calculator:
            return False
        return _holds_forces(calc, self.link.atoms)

    def watch(self, steps):
        """Pass on the items of ``steps`` (a run's generator), noting changes made between them.

        For a generator whose caller runs code between the items (``irun``
        driven by hand); ``run()`` runs none and needs no watch.
        """
        link = self.link
        for item in steps:
            written = link.snapshot()
            yield item
            if self.changed is None and link.differs(written):
                self.changed = written

    def call_observers(self, observers, step: int) -> None:
        """Call the ``observers`` (ASE's ``(function, interval, args, kwargs)``) due at ``step``,
        noting a change they make to the Atoms (a snapshot only when one of them may)."""
        due, reads_only, watch = [], self.reads_only, False
        for observer in observers:
            interval = observer[1]
            if step % interval == 0 if interval > 0 else step == -interval:
                due.append(observer)
                function = observer[0]
                known = reads_only.get(function)
                if known is None:
                    known = reads_only[function] = _observer_reads_only(function)
                watch = watch or not known
        if watch:
            self.call(due)
        else:
            for function, _, args, kwargs in due:
                function(*args, **kwargs)

    def call(self, due) -> None:
        """Call the observers ``due`` (``(function, interval, args, kwargs)``), noting a change
        they make to the Atoms."""
        written = self.link.snapshot()
        for function, _, args, kwargs in due:
            function(*args, **kwargs)
        if self.changed is None and self.link.differs(written):
            self.changed = written

    def before_step(self, evaluate, step: int, owner: str = "RigidDynamics") -> bool:
        """Read a change noted since the last step (see :meth:`watch`); whether there was one."""
        if self.changed is None:
            return False
        written, self.changed = self.changed, None
        return self.sync(written, evaluate, step, owner)


def _holds_forces(calc, atoms) -> bool:
    """Whether ``calc`` holds forces for ``atoms`` as they are (ASE's ``check_state``).

    A split calculator (:class:`~rigidmd.core.split.MultipleTimeStep`, which has
    ``levels``) holds no results of its own: the r-RESPA step calls its levels, so it
    holds them when every level does (for ``full=``, the slow level's own results, those
    of the full model less the fast one).
    """
    levels = getattr(calc, "levels", None)
    if levels is not None:
        return all(_holds_forces(level, atoms) for _, level in levels)
    results = getattr(calc, "results", None)
    check_state = getattr(calc, "check_state", None)
    if not results or "forces" not in results or check_state is None:
        return False
    return not check_state(atoms)

