r"""Rigid-body molecular dynamics as an ASE integrator.

:class:`RigidDynamics` advances rigid bodies (centre of mass and orientation
quaternion) and atoms that belong to no body (point particles) in the same
step, with forces from any ASE calculator.  A step is one pipeline:

1. changes the user made to the Atoms since the last step are read (only
   when an observer or the caller of :meth:`irun` could have made them);
2. the coupling parts (thermostats, barostats; :mod:`rigidmd.coupling`) act
   for half a step;
3. the integrator's scheme (:mod:`rigidmd.schemes`) makes the deterministic
   step, through its compiled kernel when it has one;
4. the coupling parts act for the second half step, in reverse order;
5. the atom momenta are written, once.

The time step is read from :attr:`RigidDynamics.dt` at every step.
:class:`RigidVerlet` is the plain NVE case.
"""

import warnings

import numpy as np
from ase import Atoms, units
from ase.io.trajectory import TrajectoryWriter
from ase.md.logger import MDLogger
from ase.md.md import MolecularDynamics

from rigidmd import _numba
from rigidmd import operators as ops
from rigidmd.atomslink import (
    RigidBodyDOF,
    calculate_together,
    check_finite,
    check_massless_momenta,
    kinetic_energy,
    store_bodies_in_tags,
)
from rigidmd.bodies import RigidBodies, unwrap_bodies
from rigidmd.coupling import Coupling
from rigidmd.logger import RigidLogger
from rigidmd.observables import NonFiniteForceError, RigidObservables
from rigidmd.schemes import BUILTIN_SCHEMES, StepContext, resolve_scheme
from rigidmd.state import RigidState

__all__ = ["RigidDynamics", "RigidVerlet", "RigidBodyDOF", "NonFiniteForceError"]

#: Largest rigid-fit residual (Å) accepted silently when re-reading positions.
FIT_TOLERANCE = 1e-6
#: A body turning more than this per step (rad) means the step is too large.  Measured on
#: 27 TIP3P waters at 300 K over 1 ps: the largest |omega| dt is 0.07, 0.14, 0.25 and
#: 0.33 rad at 1, 2, 4 and 6 fs.
MAX_ROTATION_PER_STEP = 0.5
#: Change of the conserved energy, as a fraction of the kinetic energy, that means the
#: step is too large.  Same runs: at most 0.07 %, 0.23 %, 0.7 % and 2.5 % at 1-6 fs.
MAX_ENERGY_CHANGE = 0.1


def check_timestep(timestep):
    """``timestep`` as a positive finite float (ASE time units), or a clear error."""
    try:
        dt = float(timestep)
    except (TypeError, ValueError):
        raise TypeError(f"timestep must be a number, got {timestep!r}") from None
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"timestep must be positive and finite, got {timestep!r}")
    return dt


def _observer_reads_only(function):
    """True for observers known not to change the Atoms (ASE's logger and writer)."""
    owner = getattr(function, "__self__", function)
    return (isinstance(owner, (MDLogger, TrajectoryWriter))
            or getattr(owner, "modifies_atoms", True) is False)


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

    While the dynamics exists, ``atoms.constraints`` holds a
    :class:`RigidBodyDOF`, so ``atoms.get_temperature()`` and the MD logger
    count rigid degrees of freedom (6 per body, 5 per linear body, 3 per
    point particle; no centre-of-mass correction, as everywhere in ASE,
    whereas LAMMPS subtracts 3).

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
        scheme of operators as a list, a :class:`~rigidmd.schemes.Scheme` or a
        YAML file.  See :mod:`rigidmd.schemes`.
    integrator_options : dict, optional
        Parameters of a built-in integrator's operators, e.g.
        ``{"tol": 1e-13, "max_iter": 100}`` for ``"rozmanov_kusalik"``.
    backend : {None, "numba", "numpy"}, optional
        ``"numba"`` runs a scheme's compiled kernel when it has one (the
        ``no_squish`` scheme, about 6 times faster per body); ``"numpy"`` runs
        its operators (:mod:`rigidmd.operators`, the readable reference
        path).  ``None`` picks numba when it is installed.  Schemes without a
        kernel always run their operators.
    couplings : sequence of rigidmd.coupling.Coupling, optional
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
        parameters do not fit the system, or other ASE constraints on the
        atoms; raised before anything is changed.

    References
    ----------
    T. F. Miller III, M. Eleftheriou, P. Pattnaik, A. Ndirango, D. Newns and
    G. J. Martyna, J. Chem. Phys. 116, 8649 (2002).
    """

    def __init__(self, atoms, timestep, bodies=None, trajectory=None, logfile=None,
                 loginterval=1, integrator="no_squish", integrator_options=None, backend=None,
                 couplings=(), log_pressure=None, **kwargs):
        # -- validate everything before touching the atoms or any file --
        if not isinstance(atoms, Atoms):
            raise TypeError(f"atoms must be an ase.Atoms, got {type(atoms).__name__}")
        self._dt = check_timestep(timestep)
        self._check_constraints(atoms)
        if backend is None:
            backend = "numba" if _numba.AVAILABLE else "numpy"
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', got {backend!r}")
        if backend == "numba" and not _numba.AVAILABLE:
            raise ValueError("backend='numba' but numba is not installed")
        check_finite(atoms.positions, "position", "Å")
        check_finite(atoms.get_momenta(), "momentum", "amu Å / ASE time")
        scheme = resolve_scheme(integrator, **(integrator_options or {}))
        rigid = RigidBodies.resolve(atoms, bodies)
        geometry = rigid.geometry(atoms)
        check_massless_momenta(atoms)
        couplings = tuple(couplings)
        for part in couplings:
            if not isinstance(part, Coupling):
                raise TypeError(f"couplings must be coupling parts (rigidmd.coupling), "
                                f"got {type(part).__name__}")
        movers = [part for part in couplings if getattr(part, "moves_cell", False)]
        if len(movers) > 1:
            raise ValueError(f"two parts move the cell ({movers[0].kind}, {movers[1].kind}); "
                             "use one barostat")
        if movers and any(getattr(part, "fixcm", False) for part in couplings):
            raise ValueError("thermostat fixcm=True with a barostat: the barostat's equations "
                             "count the centre of mass's degrees of freedom; use fixcm=False")
        self.model = geometry.model
        self.atoms = atoms
        for part in couplings:
            part.check(self)

        # -- from here on the atoms and files change --
        with warnings.catch_warnings():
            # ASE warns of every massless atom; ours are virtual sites that their bodies
            # carry (check_masses refused any other).
            warnings.filterwarnings("ignore", message="Zero mass encountered in atoms")
            super().__init__(atoms, self._dt, trajectory=trajectory, logfile=None,
                             loginterval=loginterval, **kwargs)
        self.backend = backend
        self.scheme = scheme
        self.fused = backend == "numba" and scheme.kernel is not None
        self.bodies = rigid
        self.couplings = couplings
        for part in couplings:
            part.bind(self)
        self._cell_moves = bool(movers)
        self._needs_stress = any(getattr(part, "needs_stress", False) for part in couplings)
        self._virial = None  # molecular virial at the last force call (when a part needs it)
        #: Ask the calculator for the stress with the forces on every step an observer is
        #: due (set by :class:`rigidmd.mdanalysis.StressRecorder`): one call, not two.
        self.stress_on_observed_steps = False
        model = self.model
        atoms.constraints = [RigidBodyDOF(3 * len(atoms) - self.degrees_of_freedom,
                                                self.bodies.body_ids)]
        store_bodies_in_tags(atoms, self.bodies.body_ids)
        nb, nf = model.n_bodies, model.n_free
        self.state = RigidState(
            X=geometry.com.copy(), V=np.zeros((nb, 3)), q=geometry.quaternions.copy(),
            p=np.zeros((nb, 4)), x=atoms.positions[model.free].copy(), v=np.zeros((nf, 3)),
            cell=atoms.cell.array.copy(),
        )
        self._backup = self.state.copy()
        self._ctx = StepContext(
            state=self.state, model=model, F=np.zeros((nb, 3)), tau=np.zeros((nb, 3)),
            f=np.zeros((nf, 3)), r=np.zeros((len(model.order), 3)),
            evaluate=self._evaluate_forces, calculator_forces=self._get_forces,
            positions=atoms.arrays["positions"], momenta=atoms.arrays["momenta"],
            write_momenta=not couplings, cell_motion=movers[0] if movers else None)
        self.removed_kinetic_energy = 0.0
        self._time = 0.0             # simulated time (ASE units), summed step by step
        self._forces_current = False  # forces restored from a checkpoint: no call at irun
        self._stepping = False        # inside step(): observers run after it, at nsteps + 1
        self._synced = None          # (positions, momenta) at the end of the last run
        self._changed = None         # (positions, momenta) written before a change was made
        self._driven_by_run = False  # irun consumed by run(): no caller code between steps
        self._energy_known = False   # the calculator computed the energy at the last call
        self._energy_ref = None      # (step, conserved energy) the step-size check compares to
        self._warned_step = False    # the step-size warning is given once
        self._read_momenta()
        self._write_atoms()
        if logfile:
            pressure = self._needs_stress if log_pressure is None else log_pressure
            self.attach(self.closelater(RigidLogger(self, logfile, pressure=pressure)),
                        loginterval)

    @staticmethod
    def _check_constraints(atoms):
        others = [c for c in atoms.constraints if not isinstance(c, RigidBodyDOF)]
        if others:
            raise ValueError(
                f"rigid-body dynamics cannot honour other ASE constraints ({others[0]!r}); "
                "remove them (rigid bodies replace bond constraints; atoms in no body are "
                "free point particles)"
            )

    # ------------------------------------------------------------ time step
    @property
    def dt(self):
        """The time step (ASE time units), read at every step by every path."""
        return self._dt

    @dt.setter
    def dt(self, timestep):
        dt = check_timestep(timestep)
        for part in getattr(self, "couplings", ()):
            check = getattr(part, "check_timestep", None)
            if check is not None:
                check(dt)
        self._dt = dt
        self._energy_ref = None

    def set_timestep(self, timestep):
        """Change the time step (ASE time units), as ASE's ``Langevin.set_timestep``."""
        self.dt = timestep

    def get_time(self):
        """Simulated time (ASE time units): the sum of the steps taken, whatever their size.

        ASE's ``nsteps * dt`` would misreport it after :attr:`dt` changed.
        """
        return self._time

    # ------------------------------------------------------------ ASE API
    def todict(self):
        d = super().todict()
        name = self.scheme.name if self.scheme.name in BUILTIN_SCHEMES else "custom"
        d.update(integrator=name, scheme=self.scheme.todict(), bodies_rule=self.bodies.rule,
                 n_bodies=self.model.n_bodies,
                 couplings=[part.todict() for part in self.couplings])
        return d

    def run(self, steps=50):
        """Run ``steps`` steps; see :meth:`ase.md.md.MolecularDynamics.run`."""
        self._driven_by_run = True
        try:
            return super().run(steps)
        finally:
            self._driven_by_run = False

    def irun(self, steps=50):
        """Run as a generator; see :meth:`ase.md.md.MolecularDynamics.irun`.

        Changes made to the Atoms since the last step, by observers or by the
        code that drives this generator, are read before the next step.
        """
        if not self._sync_from_atoms(self._synced) and self._forces_current:
            self._place_atoms()  # the restored forces belong to these positions
        else:
            self._evaluate_forces()
        self._forces_current = False
        try:
            for converged in super().irun(steps):
                if self._driven_by_run:
                    yield converged
                    continue
                written = self._snapshot()
                yield converged
                if self._changed is None and self._differs(written):
                    self._changed = written
        finally:
            self._synced = self._snapshot()

    def call_observers(self):
        """Call the observers due at this step, noting whether they changed the Atoms."""
        due = [function for function, interval, _, _ in self.observers
               if (interval > 0 and self.nsteps % interval == 0)
               or (interval <= 0 and self.nsteps == abs(interval))]
        if all(_observer_reads_only(function) for function in due):
            super().call_observers()
            return
        written = self._snapshot()
        super().call_observers()
        if self._changed is None and self._differs(written):
            self._changed = written

    def _snapshot(self):
        atoms = self.atoms
        return (atoms.arrays["positions"].copy(), atoms.arrays["momenta"].copy(),
                atoms.cell.array.copy())

    def _differs(self, snapshot):
        positions, momenta, cell = snapshot
        atoms = self.atoms
        return not (np.array_equal(atoms.arrays["positions"], positions)
                    and np.array_equal(atoms.arrays["momenta"], momenta)
                    and np.array_equal(atoms.cell.array, cell))

    def _refresh_properties(self):
        # Forces at the current positions were evaluated inside step() (or
        # at the start of irun); nothing to refresh.
        pass

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
        ctx, dt = self._ctx, self.dt
        self._stepping = True
        self.state.copy_into(self._backup)
        if self.fused:
            # The kernel overwrites the forces only after the force call succeeded.
            saved = (ctx.F, ctx.tau, ctx.f, ctx.scratch)
        else:
            saved = (ctx.F.copy(), ctx.tau.copy(), ctx.f.copy(), dict(ctx.scratch))
        coupled = [part.get_state() for part in self.couplings]
        try:
            half = 0.5 * dt
            for part in self.couplings:
                part.first_half(half)
            self.scheme.run(ctx, dt, fused=self.fused)
            for part in reversed(self.couplings):
                part.second_half(half)
            if not ctx.write_momenta or not self.fused:
                self._write_momenta()
            self._time += dt
        except BaseException:
            self._stepping = False
            self._backup.copy_into(self.state)
            ctx.F, ctx.tau, ctx.f, ctx.scratch = saved
            for part, variables in zip(self.couplings, coupled, strict=True):
                part.set_state(variables)
            if self._cell_moves:
                self.atoms.set_cell(self.state.cell)
            self._place_atoms()
            self._write_momenta()
            raise
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
        if self.model.n_bodies and step % 10 == 0:
            omega = np.linalg.norm(self.angular_velocities, axis=1)
            b = int(np.argmax(omega))
            if omega[b] * self.dt > MAX_ROTATION_PER_STEP:
                message = (f"body {b} turns by {omega[b] * self.dt:.2f} rad per step at step "
                           f"{step} (above {MAX_ROTATION_PER_STEP} rad)")
        if message is None and self._energy_known:
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
                          f"{self.dt / units.fs:g} fs is probably too large", stacklevel=3)

    # ------------------------------------------------------------ forces
    def _get_forces(self):
        """Call the calculator on the current positions and check the result.

        With a barostat the cell is set first, the stress is asked for in
        the same call, and the molecular virial is kept.
        """
        atoms = self.atoms
        if self._cell_moves:
            atoms.set_cell(self.state.cell)
        wanted = ["forces"]
        if self._needs_stress:
            wanted.append("stress")
        if self._observed_next():
            wanted.append("energy")  # a logger will ask: one calculator call, not two
            if self.stress_on_observed_steps and not self._needs_stress and atoms.pbc.all():
                wanted.append("stress")
        if len(wanted) > 1:
            calculate_together(atoms.calc, atoms, wanted)
        forces = np.asarray(atoms.get_forces(md=True), dtype=float)
        if forces.shape != (len(self.atoms), 3):
            raise ValueError(
                f"calculator returned forces of shape {forces.shape}, "
                f"expected {(len(self.atoms), 3)}"
            )
        # One reduction: a NaN or an infinity anywhere makes the sum non-finite.
        if not np.isfinite(forces.sum()):
            bad = np.flatnonzero(~np.isfinite(forces).all(axis=1))
            raise NonFiniteForceError(
                f"calculator returned non-finite forces on atom(s) {bad[:10].tolist()} "
                f"after step {self.nsteps}; the atoms are left at step {self.nsteps}"
            )
        self._energy_known = ("energy" in wanted
                              and "energy" in getattr(atoms.calc, "results", {}))
        if self._energy_known:
            energy = atoms.calc.results["energy"]
            if not np.isfinite(energy):
                raise NonFiniteForceError(
                    f"calculator returned a non-finite energy ({energy}) with finite forces "
                    f"after step {self.nsteps}; the atoms are left at step {self.nsteps}")
        if self._needs_stress:
            self._virial = self._molecular_virial(forces)
        return forces

    def _observed_next(self):
        """Whether an observer is due after the step being taken (or at a run's start)."""
        step = self.nsteps + 1 if self._stepping else self.nsteps
        return any((interval > 0 and step % interval == 0) or
                   (interval <= 0 and step == abs(interval))
                   for _, interval, _, _ in self.observers)

    def _evaluate_forces(self):
        """Place the atoms from the state, call the calculator, reduce to bodies."""
        self._place_atoms()
        forces = self._get_forces()
        ctx = self._ctx
        ctx.F, ctx.tau = ops.reduce_forces(forces, ctx.r, self.model)
        ctx.f = forces[self.model.free]

    # ------------------------------------------------------------ atoms <-> state
    def _place_atoms(self):
        """Write rigid positions of the current state to the atoms (and ``ctx.r``)."""
        s, m, ctx = self.state, self.model, self._ctx
        positions = self.atoms.arrays["positions"]
        if self.backend == "numba":
            # The same arithmetic as the kernel's, so a restored state gives
            # bit-identical positions.
            _numba.place(s.X, s.q, m.body_coordinates, m.bounds, m.order, ctx.r, positions)
        else:
            ctx.r, positions[m.order] = ops.place_atoms(s, m)
        positions[m.free] = s.x

    def _write_momenta(self):
        """Write rigid momenta of the current state to the atoms (positions placed already)."""
        s, m, r = self.state, self.model, self._ctx.r
        momenta = self.atoms.arrays["momenta"]
        if self.backend == "numba":
            _numba.momenta(s.V, s.q, s.p, m.inv_moments, m.bounds, m.order, m.atom_masses, r,
                           momenta)
        else:
            momenta[m.order] = m.atom_masses[:, None] * ops.atom_velocities(s, r, m)
        momenta[m.free] = m.free_masses[:, None] * s.v

    def _write_atoms(self):
        """Write positions and rigid momenta of the current state to the atoms."""
        self._place_atoms()
        self._write_momenta()
        self._synced = self._snapshot()

    def _read_momenta(self, previous=None):
        """Project the atoms' velocities onto rigid motion of the bodies.

        With ``previous`` (the momenta last written to the atoms, positions
        unchanged since), a body whose atom momenta were all scaled by one
        factor (a velocity flip, a rescaling) has its whole momentum scaled
        instead of projected afresh.  This keeps, bit for bit, the axial
        NO_SQUISH momentum of a linear body, which its atoms' velocities
        cannot express, so that flipping velocities reverses a run exactly.
        """
        s, m, atoms = self.state, self.model, self.atoms
        momenta = atoms.get_momenta()
        # Massless atoms (virtual sites) carry no momentum (check_massless_momenta).
        massive = self.masses[:, 0] > 0
        ke_atoms = 0.5 * np.sum(momenta[massive] ** 2 / self.masses[massive])
        r, _ = ops.place_atoms(s, m)
        V, L_body = ops.rigid_projection(momenta[m.order], r, s.q, m)
        p = ops.conjugate_momentum(s.q, L_body)
        if previous is not None:
            scale, uniform = ops.uniform_rescale(momenta[m.order], previous[m.order], m)
            V = np.where(uniform[:, None], scale[:, None] * s.V, V)
            p = np.where(uniform[:, None], scale[:, None] * s.p, p)
        s.V, s.p = V, p
        s.v = momenta[m.free] / m.free_masses[:, None]
        ke_rigid = self.get_translational_kinetic_energy() + self.get_rotational_kinetic_energy()
        self.removed_kinetic_energy = float(ke_atoms - ke_rigid)
        # Rigid input loses only roundoff (~1e-16 of the kinetic energy).
        if self.removed_kinetic_energy > 1e-10 * ke_atoms + 1e-12:
            warnings.warn(
                f"{type(self).__name__}: projecting the atoms' velocities onto rigid-body "
                f"motion removed {self.removed_kinetic_energy:.6g} eV of kinetic energy "
                f"({100 * self.removed_kinetic_energy / ke_atoms:.3g}% of {ke_atoms:.6g} eV)",
                stacklevel=4,
            )

    def _read_positions(self):
        """Refit centres of mass and orientations to the atoms' positions."""
        s, m, atoms = self.state, self.model, self.atoms
        x = unwrap_bodies(atoms, m.order, m.starts, m.atom_body)
        if m.n_bodies:
            X, q, residual = ops.fit_bodies(x, m)
            worst = int(np.argmax(residual))
            if residual[worst] > FIT_TOLERANCE:
                warnings.warn(
                    f"{type(self).__name__}: the atoms of body {worst} are "
                    f"{residual[worst]:.3g} Å from a rigid image of the body; they were "
                    "moved onto it",
                    stacklevel=4,
                )
            s.X, s.q = X, q
        s.x = atoms.positions[m.free].copy()

    def _sync_from_atoms(self, written):
        """Pick up changes made to the Atoms since ``written`` (positions, momenta, cell) was true.

        Returns whether anything changed.  Moved atoms are refitted and their
        forces evaluated again.
        """
        atoms = self.atoms
        if len(atoms) != self.model.n_atoms:
            raise ValueError(
                f"the atoms changed from {self.model.n_atoms} to {len(atoms)}; "
                "create a new dynamics"
            )
        if not np.array_equal(atoms.get_masses(), self.masses[:, 0]):
            raise ValueError("the atoms' masses changed; create a new dynamics")
        self._check_constraints(atoms)
        if not any(isinstance(c, RigidBodyDOF) for c in atoms.constraints):
            atoms.constraints = [RigidBodyDOF(3 * len(atoms) - self.degrees_of_freedom,
                                                self.bodies.body_ids)]
        positions, momenta, cell = written
        moved = not (np.array_equal(atoms.positions, positions)
                     and np.array_equal(atoms.cell.array, cell))
        kicked = not np.array_equal(atoms.get_momenta(), momenta)
        when = f"(set after step {self.nsteps}; nothing was changed)"
        if moved:
            check_finite(atoms.positions, "position", "Å", when)
            check_finite(atoms.cell.array, "cell", "Å", when)
        if kicked:
            check_finite(atoms.get_momenta(), "momentum", "amu Å / ASE time", when)
            check_massless_momenta(atoms, when)
        if moved:
            self.state.cell[...] = atoms.cell.array
            self._read_positions()
        if moved or kicked:
            self._read_momenta(previous=None if moved else momenta)
            self._write_atoms()
            self._ctx.scratch.clear()
        if moved:
            self._evaluate_forces()
        if moved or kicked:
            self._energy_ref = None
        return moved or kicked

    # ------------------------------------------------------------ checkpoints
    def save_checkpoint(self, path, extra=None):
        """Write everything an exact continuation needs to ``path`` (atomically).

        See :mod:`rigidmd.checkpoint`; :func:`rigidmd.load_checkpoint` continues.
        """
        from rigidmd.checkpoint import save_checkpoint

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

