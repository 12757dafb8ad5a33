r"""Rigid-body molecular dynamics as an ASE integrator.

:class:`RigidDynamics` advances rigid bodies (centre of mass and orientation
quaternion) and atoms that belong to no body (point particles) in the same
step, with forces from any ASE calculator.  It keeps ASE's interface
(``run``, ``irun``, ``attach``, logs) and composes three parts:

1. the body link (:mod:`rigidmd.core.link`): atoms ↔ body state, and its
   change detection (:class:`~rigidmd.core.link.AtomsSync`: what the user,
   an observer or the caller of :meth:`irun` changed in the Atoms between
   steps, read before the next one);
2. the force evaluator (:mod:`rigidmd.core.forces`): one calculator call per
   step, computing what the step was told it needs (energy, stress:
   ``begin_step``), checked, reduced to the bodies, into the per-step record
   (:mod:`rigidmd.core.record`);
3. the stepper (:mod:`rigidmd.core.stepper`): the coupling parts
   (:mod:`rigidmd.couplings`) for half a step, the integrator's scheme
   (:mod:`rigidmd.core.schemes`), the parts' second halves in reverse order,
   the atom momenta written once; a failed step is undone.

The observables (``dyn.get_stress()``, ``dyn.angular_velocities``, ...) live
in :mod:`rigidmd.core.observables` (:class:`~rigidmd.core.observables.RigidObservables`,
inherited); the check for a time step that is too large is an observer
(:class:`~rigidmd.core.checks.StepSizeCheck`).  One :class:`~rigidmd.core.model.BodyModel`
serves every part; :meth:`RigidDynamics.set_state` updates it in place.

The time step is read from :attr:`RigidDynamics.dt` at every step.
:class:`~rigidmd.md.verlet.RigidVerlet` is the plain NVE case.
:func:`rigidmd.run.restart.load_checkpoint` rebuilds a dynamics from a file
:mod:`rigidmd.core.checkpoint` wrote.
"""

import warnings
from collections.abc import Sequence

import numpy as np
from ase import Atoms, units
from ase.md.md import MolecularDynamics

from rigidmd.core.backend import resolve_backend
from rigidmd.core.bodies import RigidBodies, store_bodies_in_tags
from rigidmd.core.checkpoint import save_checkpoint
from rigidmd.core.checks import (
    StepSizeCheck,
    check_constraints,
    check_finite,
    check_massless_momenta,
    check_output_file,
    check_timestep,
)
from rigidmd.core.coupling import Coupling, check_composition, export_parts, share_target
from rigidmd.core.dof import RigidBodyDOF
from rigidmd.core.forces import NonFiniteForceError
from rigidmd.core.link import AtomsSync, BodyLink
from rigidmd.core.logger import RigidLogger
from rigidmd.core.model import BodyModel
from rigidmd.core.observables import RigidObservables
from rigidmd.core.operators import remove_centre_velocity
from rigidmd.core.respa import evaluator_for, record_for, respa_for
from rigidmd.core.schemes import BUILTIN_SCHEMES, resolve_scheme, scheme_with_middle
from rigidmd.core.split import MultipleTimeStep, check_calculator_properties
from rigidmd.core.state import STATE_FIELDS
from rigidmd.core.stepcontext import StepContext
from rigidmd.core.stepper import Stepper

__all__ = ["RigidDynamics", "RigidBodyDOF", "NonFiniteForceError",
           "check_timestep"]


def observed_at(observers, step: int) -> bool:
    """Whether an observer (ASE's ``(function, interval, args, kwargs)``) that reads the
    calculator's results is due at ``step``."""
    for function, interval, _, _ in observers:
        if ((step % interval == 0 if interval > 0 else step == -interval)
                and getattr(function, "wants_properties", True)):
            return True
    return False


def check_log_pressure(log_pressure, atoms) -> None:
    """Refuse in one line a ``log_pressure`` the dynamics cannot log: not a bool (or None),
    or True without a periodic cell or with a calculator that gives no stress (which
    failed at the first step, after the log file was written).  Changes nothing."""
    if log_pressure is None:
        return
    if not isinstance(log_pressure, (bool, np.bool_)):
        raise TypeError(f"log_pressure must be True, False or None, got {log_pressure!r}")
    if not log_pressure:
        return
    if not atoms.pbc.all():
        raise ValueError(f"log_pressure=True: the pressure needs a cell periodic in x, y "
                         f"and z (pbc is {atoms.pbc.tolist()})")
    calc = atoms.calc
    if isinstance(calc, MultipleTimeStep):
        calc.check_level_properties("stress", "log_pressure=True")
        return
    implemented = getattr(calc, "implemented_properties", None)
    if implemented is not None and "stress" not in implemented:
        raise ValueError(f"log_pressure=True: the calculator {type(calc).__name__} provides "
                         f"no stress (it implements {', '.join(implemented)})")


class RigidDynamics(RigidObservables, MolecularDynamics):
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

    Until the dynamics is closed (:meth:`close`, or the end of its ``with``
    block), ``atoms.constraints`` holds a :class:`RigidBodyDOF`, so
    ``atoms.get_temperature()`` and the MD logger
    count rigid degrees of freedom (6 per body, 5 per linear body, 3 per
    point particle), less 3 when the total momentum is held: by a
    thermostat's ``fixcm=True`` or by ASE's :class:`ase.constraints.FixCom`
    on the atoms (which this dynamics honours: the total momentum is made
    zero at the start and kept zero at every step).  Without either there is
    no centre-of-mass correction, as everywhere in ASE (LAMMPS subtracts 3).

    The parts, each usable alone: :attr:`link` (atoms ↔ state) with
    :attr:`sync` (its change detection), :attr:`evaluator` (filling the
    per-step :attr:`record`) and :attr:`stepper` (the step and its rollback).
    :meth:`get_state` and :meth:`set_state` export and restore everything an
    exact continuation needs (:mod:`rigidmd.core.checkpoint` writes it to a file).

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
        ``"exadem"`` (first order; a DEM scheme, not for molecules), ``"baoab"``
        (NO_SQUISH cut in two around the parts' middle action; the default
        ``"no_squish"`` becomes it when a part acts there); or a
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
    couplings : sequence of rigidmd.core.coupling.Coupling, optional
        Thermostat and barostat parts, applied in this order before the
        scheme's step and in reverse order after it.
    log_pressure : bool, optional
        Whether the log has the molecular pressure (``P[bar]``); default: when a
        part reads the stress (a barostat).  True needs a cell periodic in x, y and
        z and a calculator that gives the stress.
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
        backend = resolve_backend(backend)
        check_finite(atoms.positions, "position", "Å")
        check_finite(atoms.get_momenta(), "momentum", "amu Å / ASE time")
        scheme = resolve_scheme(integrator, **(integrator_options or {}))
        rigid = RigidBodies.resolve(atoms, bodies)
        geometry = rigid.geometry(atoms)
        check_massless_momenta(atoms)
        couplings = tuple(couplings)
        mover = check_composition(couplings, fixcom)
        middle = tuple(part for part in couplings if part.acts_in_middle)
        scheme = scheme_with_middle(scheme, integrator, [part.kind for part in middle])
        check_calculator_properties(atoms.calc, couplings)
        check_log_pressure(log_pressure, atoms)
        model, (split, respa) = geometry.model, respa_for(atoms.calc, scheme, backend)
        for part in couplings:
            part.check(atoms, model, self._dt)
        for name, path in (("trajectory", trajectory), ("logfile", logfile)):
            check_output_file(name, path)
        # -- from here on the atoms and files change --
        with warnings.catch_warnings():  # ASE warns of massless atoms: ours are carried sites
            warnings.filterwarnings("ignore", message="Zero mass encountered in atoms")
            super().__init__(atoms, self._dt, trajectory=trajectory, logfile=None,
                             loginterval=loginterval, **kwargs)
        self.backend = backend.name
        self.scheme = scheme
        #: Whether the scheme runs as its fused compiled kernel (the inner steps' under r-RESPA).
        self.fused = backend.scheme_kernel(scheme) is not None
        self.bodies = rigid
        self.model = model
        self.couplings = couplings
        self.fixcom = fixcom
        self.needs_energy = any(part.needs_energy for part in couplings)
        self.link = BodyLink(atoms, model, backend)
        self.state = self.link.initial_state(geometry)
        self.record = record_for(split, self.state, model, self.link)
        self.evaluator = evaluator_for(split, self.link, self.record,
                                        stress=any(part.needs_stress for part in couplings),
                                        cell_moves=mover is not None)
        #: The one view of a step: the scheme's operators and the coupling parts read it.
        self.view = context = StepContext(
            self.state, model, self.record, self.evaluator,
            positions=atoms.arrays["positions"], momenta=atoms.arrays["momenta"],
            write_momenta=not couplings and not fixcom, cell_motion=mover, middle=middle,
            fixcom=fixcom)
        #: The stress with the forces when an observer is due (``StressRecorder`` sets it).
        self.stress_on_observed_steps = False
        for part in couplings:
            part.bind(self.view)
        #: The target temperature, held once for every part that has one.
        self.target = share_target(couplings)
        #: Whether the total momentum is held (FixCom, or a thermostat's fixcm).
        self.holds_momentum = fixcom or any(part.fixcm for part in couplings)
        self.sync = AtomsSync(self.link, self.state, self.record, rigid.body_ids, fixcom,
                              self.holds_momentum)
        self.sync.mark_atoms()
        store_bodies_in_tags(atoms, rigid.body_ids)
        self._split = split  # the MultipleTimeStep the steps integrate by r-RESPA, or None
        self.stepper = Stepper(respa or scheme, context, couplings, self.link,
                               kernel=backend.scheme_kernel(respa or scheme), fixcom=fixcom)
        self._driven_by_run = False  # irun consumed by run(): no caller code between steps
        self._in_run = False  # inside irun (or run): a step by hand starts as a run does
        self.link.read_momenta(self.state, owner=type(self).__name__)
        if fixcom:
            remove_centre_velocity(self.state, model)
        self.sync.write_atoms()
        #: The observer that warns of a time step evidently too large.
        self.step_check = StepSizeCheck(self)
        self.attach(self.step_check, interval=StepSizeCheck.interval)
        if logfile:
            pressure = self.evaluator.stress if log_pressure is None else log_pressure
            self.attach(self.closelater(RigidLogger(self, logfile, pressure=pressure)),
                        loginterval)

    def close(self) -> None:
        """Close the trajectory and log (ASE's ``close``) and take the :class:`RigidBodyDOF`
        marker off the Atoms: an ASE dynamics run on them afterwards counts their own
        degrees of freedom (with the marker, ASE's ``Bussi`` aimed at 24 instead of 36 for
        4 waters).  A later run of this dynamics puts it back."""
        super().close()
        atoms = self.atoms
        kept = [c for c in atoms.constraints if not isinstance(c, RigidBodyDOF)]
        if len(kept) != len(atoms.constraints):
            atoms.constraints = kept

    #: The coupling parts' types a class is built around, in order (None: any parts);
    #: :meth:`from_parts` checks them.
    part_types: tuple | None = None

    @classmethod
    def from_parts(cls, atoms: Atoms, timestep: float, couplings: Sequence[Coupling] = (),
                   **kwargs) -> "RigidDynamics":
        """A dynamics of this class around ready coupling parts (a checkpoint's).

        The class's own constructor builds its parts from ASE-style arguments
        (``temperature_K``, ``taut``, ...); this builds it around parts that
        exist, as :func:`rigidmd.load_checkpoint` does, so that the class's
        methods and properties (``thermostat_work``, ``set_friction``, ...)
        work on them.

        Parameters
        ----------
        atoms : ase.Atoms
        timestep : float
            ASE time units.
        couplings : sequence of rigidmd.core.coupling.Coupling
            The parts, in the order the class holds them (thermostat, then barostat).
        **kwargs
            As for :class:`RigidDynamics` (``bodies``, ``integrator``, ``backend``,
            ``trajectory``, ...), without ``couplings``.

        Raises
        ------
        ValueError
            The parts are not those the class is built around (:attr:`part_types`).
        """
        parts = tuple(couplings)
        cls.check_parts(parts)
        dyn = cls.__new__(cls)
        cls._assemble(dyn, atoms, timestep, parts, **kwargs)
        return dyn

    @classmethod
    def check_parts(cls, parts: Sequence[Coupling]) -> None:
        """Refuse coupling parts that are not those the class is built around (ValueError,
        one line naming both); any parts for a class whose :attr:`part_types` is None."""
        expected, parts = cls.part_types, tuple(parts)
        if expected is None:
            return
        if len(parts) != len(expected) or not all(
                isinstance(part, kind) for part, kind in zip(parts, expected, strict=True)):
            have = ", ".join(type(part).__name__ for part in parts) or "none"
            want = ", ".join(kind.__name__ for kind in expected) or "none"
            raise ValueError(f"{cls.__name__} is built around the parts {want}; got {have}")

    def _assemble(self, atoms, timestep, parts, **kwargs):
        """Initialise around the ready ``parts`` (:meth:`from_parts`); a base whose
        constructor takes its parts otherwise overrides it."""
        RigidDynamics.__init__(self, atoms, timestep, couplings=parts, **kwargs)

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
        if hasattr(self, "step_check"):
            self.step_check.reset()

    def set_timestep(self, timestep: float) -> None:
        """Change the time step (ASE time units), as ASE's ``Langevin.set_timestep``."""
        self.dt = timestep

    def get_time(self) -> float:
        """Simulated time (ASE units): the sum of the steps taken (not ``nsteps * dt``)."""
        return self.stepper.time

    def set_temperature(self, temperature_K=None, *, temperature=None) -> None:
        """Change the target temperature of every part that has one (``temperature_K`` in K).

        ``temperature_K`` by name or first, as ASE's ``LangevinBAOAB`` and ``Andersen``
        take it; a thermostat and a barostat keep one target.  Every part checks the
        value before any changes.  ``temperature=`` is refused: ASE's thermostats read
        it in eV (``Langevin``) or in K (``NVTBerendsen``), and a ported call would be
        read wrong by a factor of 11604 either way.
        """
        if temperature is not None:
            raise TypeError(f"{type(self).__name__}.set_temperature: give temperature_K= "
                            f"(K), not temperature= (ASE's thermostats read that in eV or in "
                            f"K, depending on the class)")
        if temperature_K is None:
            raise TypeError(f"{type(self).__name__}.set_temperature: temperature_K (K) is "
                            "missing")
        value = temperature_K
        if not self.target.parts:
            raise ValueError(f"{type(self).__name__} has no part with a target temperature")
        self.target.set_temperature(value)  # checked by every part before it changes
        self.step_check.reset()  # the chains' energy jumps with the target: a new reference

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
        code that drives this generator, are read before the next step
        (:class:`~rigidmd.core.link.AtomsSync`).
        """
        if self.sync.start(self._evaluate_forces, self.nsteps, type(self).__name__):
            self.step_check.reset()
        steps = self._steps(steps)
        if not self._driven_by_run:  # code runs between the items: watch for its changes
            steps = self.sync.watch(steps)
        self._in_run = True
        try:
            yield from steps
        finally:
            self._in_run = False
            self.sync.finish_run()

    def _steps(self, steps):
        """ASE's ``irun`` loop and its calls, in its order: a subclass's overrides are called."""
        self.max_steps = self.nsteps + steps
        if self.nsteps == 0:
            self._refresh_properties()
            self.log()
            self.call_observers()
        yield self.nsteps == self.max_steps
        while self.nsteps < self.max_steps:
            self.step()
            self.nsteps += 1
            self._refresh_properties()
            self.log()
            self.call_observers()
            yield self.nsteps == self.max_steps

    def _refresh_properties(self):
        """Nothing to refresh (ASE's asks for the forces): the step computed what the
        observers due read.  A subclass may override it, as in ASE."""

    def call_observers(self):
        """Call the observers due at this step, noting whether they changed the Atoms."""
        self.sync.call_observers(self.observers, self.nsteps)

    # ------------------------------------------------------------ the step
    def step(self):
        """Advance one step of :attr:`dt`: coupling halves around the scheme's step.

        If anything fails (the calculator, an iteration, a coupling part),
        the state, forces, coupling variables and atoms are put back as they
        were at the start of the step.

        Called by hand (``for _ in range(n): dyn.step()``, outside :meth:`run`
        and :meth:`irun`), each step starts as a run does: it reads what was
        changed on the Atoms and has forces for the positions it starts from
        (the calculator is asked only when its results are not those), as
        ASE's ``step()`` asks for the forces it starts from; ``nsteps`` and the
        observers are :meth:`irun`'s, as in ASE.
        """
        if self._split is None and isinstance(self.atoms.calc, MultipleTimeStep):
            raise ValueError("MultipleTimeStep: the atoms were given a split after the "
                             f"{type(self).__name__} was made, which sets up its r-RESPA "
                             "steps; make a new dynamics for it")
        if not self._in_run:
            if self.sync.start(self._evaluate_forces, self.nsteps, type(self).__name__):
                self.step_check.reset()
            try:
                self._advance()
            finally:
                self.sync.finish_run()
            return
        if self.sync.changed is not None and self.sync.before_step(
                self._evaluate_forces, self.nsteps, type(self).__name__):
            self.step_check.reset()
        self._advance()

    def _advance(self):
        observed = observed_at(self.observers, self.nsteps + 1)
        self.stepper.step(self._dt, self.nsteps, self.needs_energy or observed,
                          self.stress_on_observed_steps and observed)

    def _evaluate_forces(self):
        """Place the atoms from the state, call the calculator, reduce to bodies."""
        observed = observed_at(self.observers, self.nsteps)
        self.evaluator.begin_step(self.nsteps, energy=self.needs_energy or observed,
                                  stress=self.stress_on_observed_steps and observed)
        self.evaluator.evaluate(self.state)

    # ------------------------------------------------------------ state export
    def get_state(self) -> dict:
        """Everything an exact continuation needs, as plain data (copies).

        Keys: ``classes`` (the names of this dynamics' class and of its bases
        down to ``RigidDynamics``, most derived first: what
        :func:`rigidmd.load_checkpoint` rebuilds), ``nsteps``, ``time``, ``dt``,
        ``scheme``, ``scheme_name``, ``backend``, ``bodies_rule``, ``body_ids``,
        ``model`` (the body model's arrays: the reference frames), ``state`` (the
        rigid state's arrays), ``record`` (forces, torques, virial, scratch
        values, the quantities the per-step record holds, and ``forces_known``:
        False before the first force call) and ``couplings`` (each part's kind,
        parameters, variables and random-number generator), ``split`` (``None``,
        or ``{"substeps": k}`` for a :class:`~rigidmd.MultipleTimeStep`).  The
        atoms themselves are ``dyn.atoms``.

        Changes made to the Atoms since the last step (momenta set, positions moved) are
        read first, as the next step would read them: the state holds them.
        """
        name = type(self).__name__
        if self._in_run:  # (an observer's checkpoint: a change noted at this step)
            changed = self.sync.before_step(self._evaluate_forces, self.nsteps, name)
        else:
            changed = self.sync.sync(self.sync.synced, self._evaluate_forces, self.nsteps, name)
        if changed:
            self.step_check.reset()
        model = self.model
        return {
            "classes": [cls.__name__ for cls in type(self).__mro__
                        if issubclass(cls, RigidDynamics)],
            "nsteps": int(self.nsteps), "time": float(self.stepper.time), "dt": float(self._dt),
            "scheme": self.scheme.todict(), "scheme_name": self.scheme.name,
            "backend": self.backend, "bodies_rule": self.bodies.rule,
            "body_ids": self.bodies.body_ids.copy(),
            "model": {name: getattr(model, name).copy() for name in BodyModel.STORED},
            "n_atoms": int(model.n_atoms),
            "state": {name: getattr(self.state, name).copy() for name in STATE_FIELDS},
            "record": self.record.get_state(),
            "couplings": export_parts(self.couplings),
            # r-RESPA's inner steps per step, or None: a continuation splits alike
            "split": None if self._split is None else {"substeps": int(self._split.substeps)},
        }

    def set_state(self, saved: dict) -> None:
        """Continue from what :meth:`get_state` returned (of a dynamics of these atoms).

        The stored body model and state replace what the constructor
        measured; the atoms are placed from them and the stored forces are
        used at the next step without a calculator call.  A state exported
        before the first force call (``record["forces_known"]`` False) has no
        forces: the next run's start calls the calculator, as the original's
        would have.

        Refused in one line, before anything changes, when the state is not of this
        dynamics: another class, scheme or time step, other coupling parts or
        parameters (a target temperature set since), other bodies or masses.  A
        state of a run split otherwise (another ``substeps``, a split or none) is
        continued, with a warning: a split's ``substeps`` may change between runs.
        """
        self._check_restorable(saved)
        self.model.update_from(BodyModel(n_atoms=saved["n_atoms"], **saved["model"]))
        for name in STATE_FIELDS:  # assignments: the state's versions move
            setattr(self.state, name, saved["state"][name])
        self.record.set_state(saved["record"])
        self.stepper.set_state({"time": saved["time"],
                                "couplings": [part["state"] for part in saved["couplings"]]})
        self.nsteps = saved["nsteps"]
        self.bodies.rule = saved["bodies_rule"]
        self.atoms.set_cell(self.state.cell)
        self.sync.write_atoms()
        self.sync.restored(self.record.forces_known)

    def _check_restorable(self, saved: dict) -> None:
        """Refuse a state :meth:`set_state` would continue wrongly (ValueError, one line)."""
        name = type(self).__name__
        where = f"{name}.set_state"
        try:
            # (a checkpoint written before the class was stored names none: any class)
            classes = list(saved.get("classes") or [name])
            kind = classes[0]
            parts = [(part["class"], part["parameters"]) for part in saved["couplings"]]
            dt, scheme = float(saved["dt"]), saved["scheme_name"]
            body_ids = np.asarray(saved["body_ids"])
            masses = np.asarray(saved["model"]["mass"], dtype=float)
        except (KeyError, TypeError, IndexError, ValueError) as err:
            raise ValueError(f"{where}: not a state of a rigidmd dynamics (no {err})") from None
        # The same class, or one of the two derived from the other (a user's subclass, as
        # load_checkpoint's dynamics_class= gives it): the parts decide below.
        if name not in classes and kind not in {cls.__name__ for cls in type(self).__mro__}:
            raise ValueError(f"{where}: the state is of a {kind}; continue it with "
                             f"rigidmd.load_checkpoint or a {kind}")
        mine = [(type(part).__name__, part.todict()) for part in self.couplings]
        if [p[0] for p in parts] != [p[0] for p in mine]:
            raise ValueError(f"{where}: the state's coupling parts are "
                             f"{', '.join(p[0] for p in parts) or 'none'}, this dynamics' "
                             f"{', '.join(p[0] for p in mine) or 'none'}")
        for (part, stored), (_, own) in zip(parts, mine, strict=True):
            for key in sorted(set(stored) | set(own)):
                if not _same_value(stored.get(key), own.get(key)):
                    raise ValueError(f"{where}: the {part}'s {key} is {own.get(key)!r} here "
                                     f"and {stored.get(key)!r} in the state; set it back, or "
                                     "continue with rigidmd.load_checkpoint")
        if scheme != self.scheme.name:
            raise ValueError(f"{where}: the state is of the {scheme} scheme, this dynamics "
                             f"integrates with {self.scheme.name}")
        if dt != self._dt:
            raise ValueError(f"{where}: the state's time step is {dt / units.fs:.10g} fs, "
                             f"this dynamics' {self._dt / units.fs:.10g} fs; set_timestep "
                             "back first")
        if "split" in saved:  # (states written before it was stored: not said)
            stored = saved["split"] and int(saved["split"]["substeps"])
            own = self._split and int(self._split.substeps)
            if stored != own:  # allowed, as substeps may change between runs: said
                def said(k):
                    return f"split by r-RESPA with {k} substeps" if k else "not split"

                warnings.warn(f"{where}: the state's run was {said(stored)}, this dynamics' "
                              f"is {said(own)}: it continues with other forces per step than "
                              "it was made with", stacklevel=3)
        if body_ids.shape != self.bodies.body_ids.shape or not np.array_equal(
                body_ids, self.bodies.body_ids):
            raise ValueError(f"{where}: the state's bodies are not this dynamics' (another "
                             "number of atoms, or atoms in other bodies)")
        if not np.allclose(masses, self.model.mass, rtol=1e-12, atol=0):
            body = int(np.argmax(np.abs(masses - self.model.mass)))  # (same bodies: shapes)
            raise ValueError(f"{where}: body {body} weighs {masses[body]:.6g} amu in the "
                             f"state and {self.model.mass[body]:.6g} amu on these atoms")

    def save_checkpoint(self, path, extra: dict | None = None) -> None:
        """Write everything an exact continuation needs to ``path`` (atomically).

        See :mod:`rigidmd.core.checkpoint`; :func:`rigidmd.load_checkpoint` continues.
        """
        save_checkpoint(self, path, extra)


def _same_value(a, b) -> bool:
    """Whether two parameters (numbers, strings, arrays, nested lists and dicts) are equal."""
    if isinstance(a, dict) or isinstance(b, dict):
        return (isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys()
                and all(_same_value(a[k], b[k]) for k in a))
    if isinstance(a, (list, tuple, np.ndarray)) or isinstance(b, (list, tuple, np.ndarray)):
        try:
            return bool(np.array_equal(np.asarray(a, dtype=object), np.asarray(b, dtype=object)))
        except (ValueError, TypeError):
            return False
    return a == b or (a != a and b != b)  # (NaN parameters are equal to themselves)

