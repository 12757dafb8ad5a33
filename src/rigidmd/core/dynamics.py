r"""Rigid-body molecular dynamics as an ASE integrator.

:class:`RigidDynamics` advances rigid bodies (centre of mass and orientation
quaternion) and atoms that belong to no body (point particles) in the same
step, with forces from any ASE calculator.  It keeps ASE's interface
(``run``, ``irun``, ``attach``, logs) and composes three parts:

1. the body link (:mod:`rigidmd.core.link`): atoms ↔ body state, and the changes
   the user made to the Atoms since the last step (read only when an
   observer or the caller of :meth:`irun` could have made them);
2. the force evaluator (:mod:`rigidmd.core.forces`): one calculator call per
   step, checked, reduced to the bodies, into the per-step record
   (:mod:`rigidmd.core.record`);
3. the stepper (:mod:`rigidmd.core.stepper`): the coupling parts
   (:mod:`rigidmd.couplings.thermostats`, :mod:`rigidmd.couplings.barostats`) for half a step,
   the integrator's scheme (:mod:`rigidmd.core.schemes`), the parts' second
   halves in reverse order, the atom momenta written once; a failed step is
   undone.

The time step is read from :attr:`RigidDynamics.dt` at every step.
:class:`RigidVerlet` is the plain NVE case.  :func:`rigidmd.run.restart.load_checkpoint`
rebuilds a dynamics from a file :mod:`rigidmd.run.checkpoint` wrote.
"""

import warnings

import numpy as np
from ase import Atoms, units
from ase.constraints import FixCom
from ase.io.trajectory import TrajectoryWriter
from ase.md.logger import MDLogger
from ase.md.md import MolecularDynamics

from rigidmd.core import _numba
from rigidmd.core import observables as obs
from rigidmd.core.bodies import RigidBodies, molecule_ids, store_bodies_in_tags
from rigidmd.core.checks import (
    check_constraints,
    check_finite,
    check_massless_momenta,
    check_timestep,
)
from rigidmd.core.dof import RigidBodyDOF, kinetic_energy
from rigidmd.core.forces import ForceEvaluator, NonFiniteForceError
from rigidmd.core.link import BodyLink
from rigidmd.core.model import BodyModel
from rigidmd.core.record import StepRecord
from rigidmd.core.schemes import BUILTIN_SCHEMES, resolve_scheme
from rigidmd.core.state import STATE_FIELDS
from rigidmd.core.stepcontext import StepContext
from rigidmd.core.stepper import Stepper, remove_centre_velocity
from rigidmd.couplings.base import CouplingView, check_composition, rng_kind
from rigidmd.run.checkpoint import save_checkpoint
from rigidmd.run.logger import RigidLogger

__all__ = ["RigidDynamics", "RigidVerlet", "RigidBodyDOF", "NonFiniteForceError",
           "check_timestep"]

#: A body turning more than this per step (rad) means the step is too large.  Measured on
#: 27 TIP3P waters at 300 K over 1 ps: the largest |omega| dt is 0.07, 0.14, 0.25 and
#: 0.33 rad at 1, 2, 4 and 6 fs.
MAX_ROTATION_PER_STEP = 0.5
#: Change of the conserved energy, as a fraction of the kinetic energy, that means the
#: step is too large.  Same runs: at most 0.07 %, 0.23 %, 0.7 % and 2.5 % at 1-6 fs.
MAX_ENERGY_CHANGE = 0.1


def _observer_reads_only(function):
    """True for observers known not to change the Atoms (ASE's logger and writer)."""
    owner = getattr(function, "__self__", function)
    return (isinstance(owner, (MDLogger, TrajectoryWriter))
            or getattr(owner, "modifies_atoms", True) is False)


class RigidDynamics(MolecularDynamics):
    r"""Rigid-body molecular dynamics: an integrator scheme and optional coupling parts.

    Molecules are rigid bodies with centre of mass :math:`X`, velocity
    :math:`V`, orientation quaternion :math:`q = (w, x, y, z)` and NO_SQUISH
    conjugate momentum :math:`p = 2\,q \otimes (0, L_b)`; atoms in no body
    are point particles.  Each step of :attr:`dt` is

    .. math::
        \prod_{c} e^{\mathcal L_c \Delta t/2}\;
        e^{\mathcal L_\mathrm{scheme} \Delta t}\;
        \prod_{c\ \mathrm{reversed}} e^{\mathcal L_c \Delta t/2}

    over the coupling parts :math:`c`, a symmetric splitting.

    At construction the atoms' velocities are projected onto rigid motion
    (as LAMMPS does at setup); the kinetic energy this removes is kept in
    :attr:`removed_kinetic_energy` and a warning reports it when it is more
    than roundoff.  After every step the Atoms hold the rigid positions and
    momenta.  Positions or momenta changed between steps (by an observer, by
    code between :meth:`irun` yields, or between runs) are read again before
    the next step, keeping each body's reference frame (positions are fitted
    by the best rigid rotation).

    While the dynamics exists, ``atoms.constraints`` holds a
    :class:`RigidBodyDOF`, so ``atoms.get_temperature()`` and the MD logger
    count rigid degrees of freedom (6 per body, 5 per linear body, 3 per
    point particle), less 3 when the total momentum is held: by a
    thermostat's ``fixcm=True`` or by ASE's :class:`ase.constraints.FixCom`
    on the atoms (which this dynamics honours: the total momentum is made
    zero at the start and kept zero at every step).  Without either there is
    no centre-of-mass correction, as everywhere in ASE (LAMMPS subtracts 3).

    The dynamics is composed of three parts, each usable alone:
    :attr:`link` (a :class:`~rigidmd.core.link.BodyLink`, atoms ↔ state),
    :attr:`evaluator` (a :class:`~rigidmd.core.forces.ForceEvaluator`, filling the
    per-step :attr:`record`) and :attr:`stepper` (a
    :class:`~rigidmd.core.stepper.Stepper`, the step and its rollback).
    :meth:`get_state` and :meth:`set_state` export and restore everything an
    exact continuation needs (:mod:`rigidmd.run.checkpoint` writes it to a file).

    Parameters
    ----------
    atoms : ase.Atoms
        The system, with a calculator attached.
    timestep : float
        Time step in ASE time units (``1 * ase.units.fs`` for 1 fs).
    bodies : None, str, RigidBodies, array_like, or list of lists, optional
        Which atoms form which body; see :meth:`RigidBodies.resolve`.
        ``None`` (default) uses covalent connectivity; ``"mol-id"`` the
        ``mol-id`` array of a LAMMPS data file; ``"tags"`` the tags.
    trajectory : str or ase.io.Trajectory, optional
        Write frames here every ``loginterval`` steps.  Each frame carries the
        bodies in its tags (body ``b`` has tag ``b + 1``, free atoms -1).  A
        frame read back does not know it is rigid, so its
        ``get_temperature()`` counts 3 degrees of freedom per atom; use
        :func:`rigidmd.rigid_temperature` for the temperature the log shows.
    logfile : str or file, optional
        MD log (``"-"`` for stdout).
    loginterval : int, default 1
        Interval of the trajectory and log, in steps.
    integrator : str, list or Scheme, default ``"no_squish"``
        The rotational integrator: ``"no_squish"`` (LAMMPS ``fix rigid/nve``),
        ``"richardson"`` (LAMMPS ``fix rigid``), ``"rozmanov_kusalik"``
        (RMPCDMD), ``"pcdm"`` (Zhao & van Wachem, two force calls per step),
        ``"exadem"`` (first order; a DEM scheme, not for molecules); or a
        scheme of operators as a list, a :class:`~rigidmd.core.schemes.Scheme` or a
        YAML file.  See :mod:`rigidmd.core.schemes`.
    integrator_options : dict, optional
        Parameters of a built-in integrator's operators, e.g.
        ``{"tol": 1e-13, "max_iter": 100}`` for ``"rozmanov_kusalik"``.
    backend : {None, "numba", "numpy"}, optional
        ``"numba"`` runs a scheme's compiled kernel when it has one (the
        ``no_squish`` scheme, about 6 times faster per body); ``"numpy"`` runs
        its operators (:mod:`rigidmd.core.operators`, the readable reference
        path).  ``None`` picks numba when it is installed.  Schemes without a
        kernel always run their operators.
    couplings : sequence of rigidmd.couplings.base.Coupling, optional
        Thermostat and barostat parts, applied in this order before the
        scheme's step and in reverse order after it.
    **kwargs
        Passed to :class:`ase.md.md.MolecularDynamics` (e.g. ``append_trajectory``).

    Raises
    ------
    TypeError
        ``atoms`` is not an :class:`ase.Atoms`, or a coupling is not a part.
    ValueError
        A bad body definition, mass, geometry or time step, a coupling whose
        parameters do not fit the system, parts with different target
        temperatures, or ASE constraints other than ``FixCom`` on the atoms;
        raised before anything is changed.

    References
    ----------
    T. F. Miller III, M. Eleftheriou, P. Pattnaik, A. Ndirango, D. Newns and
    G. J. Martyna, J. Chem. Phys. 116, 8649 (2002).
    """

    def __init__(self, atoms: Atoms, timestep: float, bodies=None, trajectory=None,
                 logfile=None, loginterval: int = 1, integrator="no_squish",
                 integrator_options: dict | None = None, backend: str | None = None,
                 couplings=(), log_pressure: bool | None = None, **kwargs):
        # -- validate everything before touching the atoms or any file --
        if not isinstance(atoms, Atoms):
            raise TypeError(f"atoms must be an ase.Atoms, got {type(atoms).__name__}")
        self._dt = check_timestep(timestep)
        fixcom = check_constraints(atoms)
        backend = _numba.resolve_backend(backend)
        check_finite(atoms.positions, "position", "Å")
        check_finite(atoms.get_momenta(), "momentum", "amu Å / ASE time")
        scheme = resolve_scheme(integrator, **(integrator_options or {}))
        rigid = RigidBodies.resolve(atoms, bodies)
        geometry = rigid.geometry(atoms)
        check_massless_momenta(atoms)
        couplings = tuple(couplings)
        mover = check_composition(couplings, fixcom)
        model = geometry.model
        for part in couplings:
            part.check(atoms, model, self._dt)
        # -- from here on the atoms and files change --
        with warnings.catch_warnings():  # ASE warns of massless atoms: ours are carried sites
            warnings.filterwarnings("ignore", message="Zero mass encountered in atoms")
            super().__init__(atoms, self._dt, trajectory=trajectory, logfile=None,
                             loginterval=loginterval, **kwargs)
        self.backend = backend
        self.scheme = scheme
        self.fused = backend == "numba" and scheme.kernel is not None
        self.bodies = rigid
        self.model = model
        self.couplings = couplings
        self.fixcom = fixcom
        #: Whether the total momentum is held (FixCom, or a thermostat's fixcm).
        self.holds_momentum = fixcom or any(part.fixcm for part in couplings)
        self.needs_energy = any(part.needs_energy for part in couplings)
        self._mark_atoms()
        store_bodies_in_tags(atoms, rigid.body_ids)
        self.link = BodyLink(atoms, model, backend)
        self.state = self.link.initial_state(geometry)
        self.record = StepRecord(self.state, model)
        self.evaluator = ForceEvaluator(self.link, self.record,
                                        stress=any(part.needs_stress for part in couplings),
                                        cell_moves=mover is not None)
        self.view = CouplingView(self.state, model, self.record, self.evaluator, 0, fixcom)
        #: The stress with the forces when an observer is due (``StressRecorder`` sets it).
        self.stress_on_observed_steps = False
        for part in couplings:
            part.bind(self.view)
        context = StepContext(
            self.state, model, self.record, self.evaluator,
            positions=atoms.arrays["positions"], momenta=atoms.arrays["momenta"],
            write_momenta=not couplings and not fixcom, cell_motion=mover, view=self.view)
        self.stepper = Stepper(scheme, context, couplings, self.view, self.link,
                               fused=self.fused, fixcom=fixcom)
        self._forces_current = False  # forces restored from a checkpoint: no call at irun
        self._stepping = False        # inside step(): observers run after it, at nsteps + 1
        self._synced = None          # (positions, momenta, cell) at the end of the last run
        self._changed = None         # (positions, momenta, cell) written before a change
        self._driven_by_run = False  # irun consumed by run(): no caller code between steps
        self._energy_ref = None      # (step, conserved energy) the step-size check compares to
        self._warned_step = False    # the step-size warning is given once
        self.link.read_momenta(self.state, owner=type(self).__name__)
        if fixcom:
            remove_centre_velocity(self.state, model)
        self._write_atoms()
        if logfile:
            pressure = self.evaluator.stress if log_pressure is None else log_pressure
            self.attach(self.closelater(RigidLogger(self, logfile, pressure=pressure)),
                        loginterval)

    def _mark_atoms(self):
        """Put the rigid degree-of-freedom marker in ``atoms.constraints`` (FixCom kept)."""
        removed = 3 * len(self.atoms) - self.model.degrees_of_freedom
        if self.holds_momentum and not self.fixcom:
            removed += 3  # fixcm keeps the total momentum; FixCom counts its own 3
        marker = RigidBodyDOF(removed, molecule_ids(self.bodies.body_ids))
        kept = [c for c in self.atoms.constraints if isinstance(c, FixCom)]
        self.atoms.constraints = kept + [marker]

    # ------------------------------------------------------------ time step
    @property
    def dt(self) -> float:
        """The time step (ASE time units), read at every step by every path."""
        return self._dt

    @dt.setter
    def dt(self, timestep):
        dt = check_timestep(timestep)
        for part in getattr(self, "couplings", ()):
            part.check_timestep(dt)
        self._dt = dt
        self._energy_ref = None

    def set_timestep(self, timestep: float) -> None:
        """Change the time step (ASE time units), as ASE's ``Langevin.set_timestep``."""
        self.dt = timestep

    def get_time(self) -> float:
        """Simulated time (ASE units): the sum of the steps taken (not ``nsteps * dt``)."""
        return self.stepper.time

    def set_temperature(self, temperature=None, *, temperature_K=None) -> None:
        """Change the target temperature of every part that has one (``temperature_K`` in K).

        As ASE's thermostats; a thermostat and a barostat keep one target.
        Every part checks the value before any changes.
        """
        value = self._process_temperature(temperature, temperature_K, "K")
        parts = [part for part in self.couplings if hasattr(part, "set_temperature")]
        if not parts:
            raise ValueError(f"{type(self).__name__} has no part with a target temperature")
        saved = [part.temperature_K for part in parts]
        try:
            for part in parts:
                part.set_temperature(value)
        except (TypeError, ValueError):
            for part, old in zip(parts, saved, strict=True):
                part.temperature_K = old
            raise
        self._energy_ref = None  # the chains' energy jumps with the target: a new reference

    # ------------------------------------------------------------ ASE API
    def todict(self) -> dict:
        d = super().todict()
        name = self.scheme.name if self.scheme.name in BUILTIN_SCHEMES else "custom"
        d.update(integrator=name, scheme=self.scheme.todict(), bodies_rule=self.bodies.rule,
                 n_bodies=self.model.n_bodies,
                 couplings=[part.todict() for part in self.couplings])
        return d

    def run(self, steps: int = 50) -> bool:
        """Run ``steps`` steps; see :meth:`ase.md.md.MolecularDynamics.run`."""
        self._driven_by_run = True
        try:
            return super().run(steps)
        finally:
            self._driven_by_run = False

    def irun(self, steps: int = 50):
        """Run as a generator; see :meth:`ase.md.md.MolecularDynamics.irun`.

        Changes made to the Atoms since the last step, by observers or by the
        code that drives this generator, are read before the next step.
        """
        if not self._sync_from_atoms(self._synced) and self._forces_current:
            self.record.r = self.link.place(self.state, self.record.r)  # the restored forces'
        else:
            self._evaluate_forces()
        self._forces_current = False
        try:
            for converged in super().irun(steps):
                if self._driven_by_run:
                    yield converged
                    continue
                written = self.link.snapshot()
                yield converged
                if self._changed is None and self.link.differs(written):
                    self._changed = written
        finally:
            self._synced = self.link.snapshot()

    def call_observers(self):
        """Call the observers due at this step, noting whether they changed the Atoms."""
        if not self.observers:
            return
        due = [function for function, interval, _, _ in self.observers
               if (interval > 0 and self.nsteps % interval == 0)
               or (interval <= 0 and self.nsteps == abs(interval))]
        if all(_observer_reads_only(function) for function in due):
            super().call_observers()
            return
        written = self.link.snapshot()
        super().call_observers()
        if self._changed is None and self.link.differs(written):
            self._changed = written

    def _refresh_properties(self):
        pass  # the forces of the current positions were evaluated in step() or at irun's start

    # ------------------------------------------------------------ the step
    def step(self):
        """Advance one step of :attr:`dt`: coupling halves around the scheme's step.

        If anything fails (the calculator, an iteration, a coupling part),
        the state, forces, coupling variables and atoms are put back as they
        were at the start of the step.
        """
        if self._changed is not None:
            written, self._changed = self._changed, None
            self._sync_from_atoms(written)
        self._stepping = True
        evaluator = self.evaluator
        evaluator.step = self.nsteps
        observed = self._observed_next() if self.observers else False
        evaluator.want_energy = self.needs_energy or observed
        evaluator.want_stress = self.stress_on_observed_steps and observed
        try:
            self.stepper.step(self._dt, self.nsteps)
        finally:
            self._stepping = False
        if not self._warned_step:
            self._check_step_size()

    def _check_step_size(self):
        """Warn once when the time step is evidently too large.

        Two signs, both cheap: a body turning by more than
        :data:`MAX_ROTATION_PER_STEP` rad in one step (checked every 10
        steps), and a conserved energy that moved by more than
        :data:`MAX_ENERGY_CHANGE` of the kinetic energy since the first step
        at which the energy was computed (only at steps where an observer
        made the calculator compute it anyway).
        """
        step = self.nsteps + 1
        message = None
        if step % 10 == 0 and self.model.n_bodies:
            b, speed = self.link.largest_angular_speed(self.state)
            if speed * self._dt > MAX_ROTATION_PER_STEP:
                message = (f"body {b} turns by {speed * self._dt:.2f} rad per step at step "
                           f"{step} (above {MAX_ROTATION_PER_STEP} rad)")
        if message is None and self.evaluator.energy_known:
            energy = self.get_conserved_energy()
            if self._energy_ref is None:
                self._energy_ref = (step, energy)
            else:
                first, reference = self._energy_ref
                change = energy - reference
                kinetic = kinetic_energy(self.atoms)
                if abs(change) > MAX_ENERGY_CHANGE * kinetic + 1e-6:
                    message = (f"the conserved energy changed by {change:+.4g} eV from step "
                               f"{first} to step {step}, {abs(change) / kinetic:.0%} of the "
                               f"kinetic energy ({kinetic:.4g} eV)")
        if message is not None:
            self._warned_step = True
            warnings.warn(f"{type(self).__name__}: {message}: the time step "
                          f"{self._dt / units.fs:g} fs is probably too large", stacklevel=3)

    def _observed_next(self):
        """Whether an observer is due after the step being taken (or at a run's start)."""
        step = self.nsteps + 1 if self._stepping else self.nsteps
        return any((interval > 0 and step % interval == 0) or
                   (interval <= 0 and step == abs(interval))
                   for _, interval, _, _ in self.observers)

    def _evaluate_forces(self):
        """Place the atoms from the state, call the calculator, reduce to bodies."""
        self.evaluator.step = self.nsteps
        observed = self._observed_next()
        self.evaluator.want_energy, self.evaluator.want_stress = (
            self.needs_energy or observed, self.stress_on_observed_steps and observed)
        self.evaluator.evaluate(self.state)

    def _write_atoms(self):
        """Write positions and rigid momenta of the current state to the atoms."""
        self.record.r = self.link.place(self.state, self.record.r)
        self.link.write_momenta(self.state, self.record.r)
        self._synced = self.link.snapshot()

    def _sync_from_atoms(self, written):
        """Pick up changes made to the Atoms since ``written`` (positions, momenta, cell) was true.

        Returns whether anything changed.  Moved atoms are refitted and their
        forces evaluated again.
        """
        atoms, link = self.atoms, self.link
        link.check_unchanged_system()
        fixcom = check_constraints(atoms)
        if fixcom != self.fixcom:
            raise ValueError("FixCom was added to or removed from the atoms; create a new "
                             "dynamics")
        if not any(isinstance(c, RigidBodyDOF) for c in atoms.constraints):
            self._mark_atoms()
        moved, kicked = link.changes_since(written, f"(set after step {self.nsteps}; "
                                                    "nothing was changed)")
        owner = type(self).__name__
        if moved:
            link.read_positions(self.state, owner=owner)
            self.record.cell_changed()
        if moved or kicked:
            link.read_momenta(self.state, previous=None if moved else written[1], owner=owner)
            if self.fixcom:
                remove_centre_velocity(self.state, self.model)
            self.record.velocities_changed()
            self._write_atoms()
            self.record.scratch.clear()
        if moved:
            self._evaluate_forces()
        if moved or kicked:
            self._energy_ref = None
        return moved or kicked

    @property
    def removed_kinetic_energy(self) -> float:
        """Kinetic energy (eV) the last projection onto rigid motion removed."""
        return self.link.removed_kinetic_energy

    # ------------------------------------------------------------ observables (thin)
    @property
    def degrees_of_freedom(self) -> int:
        """Rigid degrees of freedom: 6 per body, 5 per linear body, 3 per point particle."""
        return self.model.degrees_of_freedom

    @property
    def translational_dof(self) -> int:
        """Centre-of-mass and point-particle degrees of freedom: 3 each."""
        return self.model.translational_dof

    @property
    def rotational_dof(self) -> int:
        """Rotational degrees of freedom: 3 per body, 2 per linear body."""
        return self.model.rotational_dof

    @property
    def com_positions(self) -> np.ndarray:
        """Centres of mass of the bodies (Å), unwrapped, shape (n_bodies, 3)."""
        return self.state.X.copy()

    @property
    def com_velocities(self) -> np.ndarray:
        """Centre-of-mass velocities (Å per ASE time unit), shape (n_bodies, 3)."""
        return self.state.V.copy()

    @property
    def quaternions(self) -> np.ndarray:
        """Orientations ``(w, x, y, z)``, body to lab frame, shape (n_bodies, 4)."""
        return self.state.q.copy()

    @property
    def moments_of_inertia(self) -> np.ndarray:
        """Principal moments (amu Å²), ascending, shape (n_bodies, 3)."""
        return self.model.moments.copy()

    @property
    def angular_momenta(self) -> np.ndarray:
        """Lab angular momenta about the centres of mass (amu Å² / ASE time), (n_bodies, 3)."""
        return obs.angular_momenta(self.state, self.model)

    @property
    def angular_velocities(self) -> np.ndarray:
        """Lab-frame angular velocities (rad / ASE time), shape (n_bodies, 3)."""
        return obs.angular_velocities(self.state, self.model)

    @property
    def translational_kinetic_energies(self) -> np.ndarray:
        r"""Per-body :math:`\tfrac12 M |V|^2` (eV), shape (n_bodies,)."""
        return obs.translational_kinetic_energies(self.state, self.model)

    @property
    def rotational_kinetic_energies(self) -> np.ndarray:
        r"""Per-body rotational energy :math:`\tfrac12 \sum_k L_{b,k}^2 / I_k` (eV), (n_bodies,)."""
        return obs.rotational_kinetic_energies(self.state, self.model)

    def get_angular_momentum(self) -> np.ndarray:
        r"""Total angular momentum about the origin (amu Å² / ASE time), shape (3,).

        For a linear body this includes the axial component that NO_SQUISH's
        splitting builds up (as in LAMMPS), which atom velocities cannot show;
        this total, not the atoms' :math:`\sum_i x_i \times p_i`, is what the
        integrator conserves (:func:`rigidmd.core.observables.total_angular_momentum`).
        """
        return obs.total_angular_momentum(self.state, self.model)

    def get_translational_kinetic_energy(self) -> float:
        """Kinetic energy of the centres of mass plus that of the point particles (eV)."""
        return float(self.translational_kinetic_energies.sum()
                     + obs.free_kinetic_energy(self.state, self.model))

    def get_rotational_kinetic_energy(self) -> float:
        """Rotational kinetic energy of all bodies (eV)."""
        return obs.rotational_kinetic_energy(self.state, self.model)

    def get_volume(self) -> float:
        """Volume of the cell (Å³); a clear error for a cell that is not periodic."""
        if not self.atoms.pbc.all():
            raise ValueError("the volume and pressure need a cell periodic in all three "
                             f"directions; atoms.pbc is {self.atoms.pbc.tolist()}")
        return self.record.volume

    def get_density(self) -> float:
        """Mass density (g/cm³)."""
        grams = self.atoms.get_masses().sum() / units.kg * 1e3
        return float(grams / (self.get_volume() * 1e-24))

    def molecular_virial(self) -> np.ndarray:
        r"""Molecular virial :math:`\sum_b X_b \otimes F_b + \sum_{free} x\otimes f` (eV, 3x3).

        The calculator's atomic virial :math:`-V\sigma` less the
        intramolecular part :math:`\sum_b\sum_{i\in b} d_i \otimes f_i`
        (symmetrised), at the current positions: the per-step record's under
        a barostat, else asked of the calculator now.
        """
        if self.evaluator.stress and self.record.virial is not None:
            return self.record.virial
        self.get_volume()  # a clear error for a cell that is not periodic
        forces = np.asarray(self.atoms.get_forces(md=True), dtype=float)
        return self.evaluator.molecular_virial(forces)

    def get_stress(self, include_ideal_gas: bool = True, voigt: bool = True) -> np.ndarray:
        r"""Molecular stress (eV/Å³) in ASE's sign convention and Voigt order.

        :math:`\sigma = -(\mathsf W + \mathsf K)/V` with the positional part
        :math:`\mathsf W` from :meth:`molecular_virial` and the kinetic tensor
        :math:`\mathsf K` of the centres of mass and point particles (only with
        ``include_ideal_gas``); see :func:`rigidmd.core.observables.stress_tensor`.
        Centres of mass, not atoms, carry the pressure of rigid molecules; the
        atomic pressure including the constraint forces has the same trace.

        Raises
        ------
        ase.calculators.calculator.PropertyNotImplementedError
            The calculator provides no stress (the message names it).
        ValueError
            The cell is not periodic in all three directions.
        """
        volume = self.get_volume()
        kinetic = self.record.kinetic_tensor if include_ideal_gas else None
        sigma = obs.stress_tensor(self.molecular_virial(), kinetic, volume)
        return obs.voigt(sigma) if voigt else sigma

    def get_pressure(self) -> float:
        """Instantaneous molecular pressure, minus a third of the stress trace (eV/Å³)."""
        return float(-np.trace(self.get_stress(voigt=False)) / 3.0)

    def get_conserved_energy(self) -> float:
        """Total energy plus every coupling part's term (eV): what the dynamics conserves.

        For NVE this is the total energy; a stochastic thermostat subtracts the
        energy it put in, Nosé–Hoover chains add their own energy.
        """
        energy = self.atoms.get_potential_energy() + kinetic_energy(self.atoms)
        return float(energy + sum(part.energy(self.view) for part in self.couplings))

    # ------------------------------------------------------------ state export
    def get_state(self) -> dict:
        """Everything an exact continuation needs, as plain data (copies).

        Keys: ``nsteps``, ``time``, ``dt``, ``scheme``, ``scheme_name``,
        ``backend``, ``bodies_rule``, ``body_ids``, ``model`` (the body
        model's arrays: the reference frames), ``state`` (the rigid state's
        arrays), ``record`` (forces, torques, virial, scratch values and the
        quantities the per-step record holds) and ``couplings`` (each part's
        kind, parameters, variables and random-number generator).  The atoms
        themselves are ``dyn.atoms``.
        """
        model = self.model
        parts = []
        for part in self.couplings:
            rng = getattr(part, "rng", None)
            owner = None if rng is None else next(
                i for i, other in enumerate(self.couplings) if getattr(other, "rng", None) is rng)
            parts.append({"class": type(part).__name__, "parameters": part.todict(),
                          "state": part.get_state(), "rng_owner": owner,
                          "rng": None if rng is None else rng_kind(rng)})
        return {
            "nsteps": int(self.nsteps), "time": float(self.stepper.time), "dt": float(self._dt),
            "scheme": self.scheme.todict(), "scheme_name": self.scheme.name,
            "backend": self.backend, "bodies_rule": self.bodies.rule,
            "body_ids": self.bodies.body_ids.copy(),
            "model": {name: getattr(model, name).copy() for name in BodyModel.STORED},
            "n_atoms": int(model.n_atoms),
            "state": {name: getattr(self.state, name).copy() for name in STATE_FIELDS},
            "record": self.record.get_state(),
            "couplings": parts,
        }

    def set_state(self, saved: dict) -> None:
        """Continue from what :meth:`get_state` returned (of a dynamics of these atoms).

        The stored body model and state replace what the constructor
        measured; the atoms are placed from them and the stored forces are
        used at the next step without a calculator call.
        """
        model = BodyModel(n_atoms=saved["n_atoms"], **saved["model"])
        self.model = model
        for holder in (self.link, self.record, self.view, self.evaluator):
            holder.model = model
        self.stepper.context.use_model(model)
        for name in STATE_FIELDS:
            np.copyto(getattr(self.state, name), saved["state"][name])
        self.record.set_state(saved["record"])
        self.stepper.set_state({"time": saved["time"],
                                "couplings": [part["state"] for part in saved["couplings"]]})
        self.nsteps = saved["nsteps"]
        self.bodies.rule = saved["bodies_rule"]
        self.atoms.set_cell(self.state.cell)
        self._write_atoms()
        self._forces_current = True

    def save_checkpoint(self, path, extra: dict | None = None) -> None:
        """Write everything an exact continuation needs to ``path`` (atomically).

        See :mod:`rigidmd.run.checkpoint`; :func:`rigidmd.load_checkpoint` continues.
        """
        save_checkpoint(self, path, extra)


class RigidVerlet(RigidDynamics):
    r"""NVE rigid-body molecular dynamics (NO_SQUISH quaternion velocity Verlet by default).

    One step of ``timestep`` with the default integrator is (Miller et al.
    2002; LAMMPS ``fix rigid/nve``)

    1. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`, :math:`X \mathrel{+}= \Delta t\,V`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    2. free rotation :math:`R_3(\tfrac{\Delta t}{2}) R_2(\tfrac{\Delta t}{2})
       R_1(\Delta t) R_2(\tfrac{\Delta t}{2}) R_3(\tfrac{\Delta t}{2})`;
    3. atoms placed at :math:`x_i = X + R(q)\,d_i`, one force call;
    4. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    5. atom momenta :math:`m_i (V + \omega \times (x_i - X))`.

    It is symplectic, time reversible and second order, with one force
    evaluation per step.  Parameters as :class:`RigidDynamics`, without
    ``couplings``.
    """

    def __init__(self, atoms, timestep, bodies=None, trajectory=None, logfile=None,
                 loginterval=1, integrator="no_squish", integrator_options=None, backend=None,
                 **kwargs):
        if "couplings" in kwargs:
            raise TypeError("RigidVerlet is NVE and takes no couplings; use RigidDynamics "
                            "or a thermostat class")
        super().__init__(atoms, timestep, bodies=bodies, trajectory=trajectory,
                         logfile=logfile, loginterval=loginterval, integrator=integrator,
                         integrator_options=integrator_options, backend=backend, **kwargs)

