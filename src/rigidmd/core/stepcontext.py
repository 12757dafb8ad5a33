r"""The one view of a step, the operators' adapters, the fused driver.

:class:`StepContext` hands the operators of a :class:`~rigidmd.core.schemes.Scheme`
and the coupling parts (as :class:`rigidmd.core.coupling.CouplingView`, the same
class) the state, the body model, the per-step record (forces, torques, scratch
values), a force evaluator, the step number and, under a barostat, the part
whose drift moves the cell.  The ``apply_*`` functions adapt each operator of
:mod:`rigidmd.core.operators` to that context (``apply_drift(ctx, h)`` runs
:func:`rigidmd.core.operators.drift` or :func:`rigidmd.core.operators.affine_drift`);
:func:`fused_no_squish` is the ``no_squish`` scheme as two compiled loops.
Nothing here reaches back to the dynamics.
"""

from dataclasses import dataclass, field

import numpy as np

from rigidmd.core import _numba
from rigidmd.core import observables as obs
from rigidmd.core import operators as ops
from rigidmd.core.forces import ForceEvaluator, NonFiniteForceError
from rigidmd.core.model import BodyModel
from rigidmd.core.record import StepRecord
from rigidmd.core.state import RigidState

__all__ = ["StepContext", "fused_no_squish", "fused_baoab", "BAOAB_OPERATORS"]


@dataclass(eq=False)  # compared by identity: it holds arrays, and itself as its view
class StepContext:
    """One view of a step: what the scheme's operators and the coupling parts read and write.

    The scheme's operators get it as ``ctx``, the coupling parts as ``view``
    (:class:`rigidmd.core.coupling.CouplingView` is this class): the state, the body
    model, the per-step record, the force evaluator, the step number, and the
    barostat's cell move (:meth:`cell_move`, whose note :attr:`cell_note` keeps for the
    barostat's second half).  The time step is not stored here:
    :meth:`rigidmd.core.schemes.Scheme.run` receives it at every step, so a changed
    ``dyn.dt`` takes effect at once on every path.

    Attributes
    ----------
    state : rigidmd.core.state.RigidState
        The state the step advances.  Assigning a field (``state.V = ...``) moves its
        version; a part or a kernel that writes in place calls ``state.touched(...)``,
        and one that scales the velocities in place by a known factor calls
        ``record.scaled(...)`` (see :mod:`rigidmd.core.state`).
    model : rigidmd.core.model.BodyModel
    record : rigidmd.core.record.StepRecord
        Forces ``F``, torques ``tau``, free-atom forces ``f``, lab displacements ``r``,
        virial and energy of the last force call; volume, kinetic tensor and rotational
        energy computed at most once per version of the state; and ``scratch``: values
        an operator hands to a later one (exaDEM's accelerations, PCDM's start-of-step
        values), kept across steps.
    evaluator : rigidmd.core.forces.ForceEvaluator
        ``evaluate(state)`` places the atoms, calls the calculator and fills the
        record; ``calculator_forces(state)`` calls it on the atoms as the fused kernel
        placed them; energy-only questions about trial configurations
        (``save_results``, ``trial_energy``, ``restore_results``).
    positions, momenta : numpy.ndarray, shape (n_atoms, 3), or None
        The Atoms' own position and momentum arrays, written in place by the fused
        kernels (None for a view made by hand, without a scheme).
    write_momenta : bool
        Whether the scheme writes the atom momenta at the end of its step
        (False when coupling parts act after it; the dynamics then writes them).
    cell_motion : Coupling or None
        The part that moves the cell in the scheme's drift (a barostat), asked
        through :meth:`cell_move`.
    middle : tuple
        The coupling parts that act in the middle of the step (their
        ``middle(view, h)``, run by the scheme's ``middle`` operator between its
        half drifts: the O of BAOAB).
    step : int
        Steps completed before the one being taken.
    fixcom : bool
        The total momentum is held at zero (ASE's ``FixCom`` on the atoms).
    view : StepContext
        What the coupling parts are given: this context itself, or for an r-RESPA
        inner step (its own record and evaluator: the fast level's) the dynamics'
        context.
    cell_note : object or None
        What the barostat's drift query returned during this step besides its
        matrices (see :meth:`rigidmd.core.coupling.Coupling.drift_matrices`); None
        before the drift.  Kept on :attr:`view`, reset at every step.
    """

    state: RigidState
    model: BodyModel
    record: StepRecord
    evaluator: ForceEvaluator
    positions: np.ndarray | None = None
    momenta: np.ndarray | None = None
    write_momenta: bool = True
    cell_motion: object = None
    middle: tuple = ()
    step: int = 0
    fixcom: bool = False
    view: "StepContext | None" = field(default=None, repr=False)

    @property
    def packed_model(self) -> tuple:
        """The model as the fused kernel takes it (three arrays: few arguments to pass)."""
        return self.model.packed

    def __post_init__(self):
        # Counts a restore cannot change (BodyModel.update_from refuses other counts).
        self.n_bodies, self.n_free = self.model.n_bodies, self.model.n_free
        if self.view is None:
            self.view = self
        self.cell_note = None

    @property
    def cell_moves(self) -> bool:
        """A part of the dynamics moves the cell (a barostat)."""
        return self.cell_motion is not None

    @property
    def backend(self):
        """The backend the parts run on (the record's link's, a
        :class:`rigidmd.core.backend.Backend`): each operation with a compiled kernel is a
        method of it, so a part calls ``view.backend.<name>(...)`` with no branch."""
        return self.record.backend

    def cell_move(self, h):
        """The barostat's drift matrices ``A, B, S`` over ``h``, asked with the parts'
        view; its note goes to ``view.cell_note``."""
        view = self.view
        A, B, S, note = self.cell_motion.drift_matrices(view, h)
        if note is not None:
            view.cell_note = note
        return A, B, S

    def omega(self):
        """Lab angular velocities of the bodies (rad / ASE time), shape (n_bodies, 3)."""
        return obs.angular_velocities(self.state, self.model)

    def set_omega(self, omega):
        """Set the bodies' lab angular velocities (at the current orientations)."""
        L = ops.lab_from_omega(self.state.q, omega, self.model.moments)
        self.state.p = ops.momentum_from_lab(self.state.q, L)

    def accelerations(self):
        """exaDEM's stored accelerations ``(a_bodies, a_free)``, from the forces if absent."""
        if "a" not in self.record.scratch:
            apply_force_to_accel(self)
        return self.record.scratch["a"], self.record.scratch["a_free"]

    def angular_acceleration(self):
        """exaDEM's stored lab angular accelerations, from ω and τ if absent."""
        if "alpha" not in self.record.scratch:
            apply_push_to_angular_acceleration(self)
        return self.record.scratch["alpha"]


# ---------------------------------------------------------------- operators
# Each takes the context, h = dt_scale * dt, and its own keyword parameters.

def apply_translational_kick(ctx, h):
    ops.translational_kick(ctx.state, ctx.record.F, ctx.record.f, ctx.model, h)


def apply_drift(ctx, h):
    if ctx.cell_motion is None:
        ops.drift(ctx.state, h)
    else:
        ops.affine_drift(ctx.state, *ctx.cell_move(h))


def apply_rotational_kick(ctx, h):
    ops.rotational_kick(ctx.state, ctx.record.tau, h)


def apply_no_squish_rotate(ctx, h):
    ops.free_rotor(ctx.state, ctx.model.inv_moments, h)


def apply_richardson_rotate(ctx, h):
    ops.richardson_rotate(ctx.state, ctx.model.inv_moments, h)


def apply_rozmanov_kusalik_rotate(ctx, h, tol=1e-13, max_iter=100):
    ops.rozmanov_kusalik_rotate(ctx.state, ctx.record.tau, ctx.model.inv_moments, h, tol=tol,
                                max_iter=max_iter)


def apply_pcdm_predict(ctx, h):
    s, m = ctx.state, ctx.model
    q0 = s.q.copy()
    q_half, omega_body0, domega_body0 = ops.pcdm_predict(q0, ctx.omega(), ctx.record.tau, m.moments,
                                                         m.inv_moments, h)
    ctx.record.scratch["pcdm"] = (q0, q_half, omega_body0, domega_body0)
    L = ops.lab_angular_momentum(s.q, s.p)
    s.q = q_half  # the midpoint force call places the atoms here
    s.p = ops.momentum_from_lab(s.q, L)


def apply_pcdm_correct(ctx, h):
    if "pcdm" not in ctx.record.scratch:
        raise RuntimeError("pcdm_correct needs a pcdm_predict earlier in the step")
    q0, q_half, omega_body0, domega_body0 = ctx.record.scratch.pop("pcdm")
    m = ctx.model
    q1, omega1 = ops.pcdm_correct(q0, q_half, omega_body0, domega_body0, ctx.record.tau, m.moments,
                                  m.inv_moments, h)
    ctx.state.q = q1
    ctx.set_omega(omega1)


def apply_middle(ctx, h):
    view = ctx.view
    for part in ctx.middle:
        part.middle(view, h)


def apply_compute_force(ctx):
    ctx.evaluator.evaluate(ctx.state)


def apply_reset_force_moment(ctx):
    ctx.record.F[...] = 0.0
    ctx.record.tau[...] = 0.0
    ctx.record.f[...] = 0.0


def apply_force_to_accel(ctx):
    ctx.record.scratch["a"] = ctx.record.F / ctx.model.mass[:, None]
    ctx.record.scratch["a_free"] = ctx.record.f / ctx.model.free_masses[:, None]


def apply_push_f_v_r(ctx, h):
    a, a_free = ctx.accelerations()
    s = ctx.state
    if ctx.cell_motion is None:
        s.X += h * s.V + 0.5 * h * h * a
        s.x += h * s.v + 0.5 * h * h * a_free
        return
    # With a barostat: the cell's drift, at the mean velocity V + (h/2) a.
    A, B, S = ctx.cell_move(h)
    s.X = s.X @ A.T + (s.V + 0.5 * h * a) @ B.T
    s.x = s.x @ A.T + (s.v + 0.5 * h * a_free) @ B.T
    s.V = s.V @ S.T
    s.v = s.v @ S.T
    s.cell = s.cell @ A.T


def apply_push_f_v(ctx, h):
    a, a_free = ctx.accelerations()
    ctx.state.V += 0.5 * h * a
    ctx.state.v += 0.5 * h * a_free


def apply_push_to_quaternion(ctx, h):
    q, omega = ops.exadem_push_to_quaternion(ctx.state.q, ctx.omega(),
                                             ctx.angular_acceleration(), h)
    ctx.state.q = q
    ctx.set_omega(omega)


def apply_push_to_angular_acceleration(ctx):
    m = ctx.model
    ctx.record.scratch["alpha"] = ops.exadem_angular_acceleration(ctx.state.q, ctx.omega(),
                                                                  ctx.record.tau,
                                                           m.moments, m.inv_moments)


def apply_push_to_angular_velocity(ctx, h):
    ctx.set_omega(ctx.omega() + 0.5 * h * ctx.angular_acceleration())


# ---------------------------------------------------------------- fused kernel
_IDENTITY = np.array([np.eye(3)] * 3)


def fused_no_squish(ctx, dt):
    """NO_SQUISH as two compiled loops over bodies: the ``no_squish`` scheme, fused.

    The same arithmetic as the operator list ``translational_kick(1/2), drift,
    rotational_kick(1/2), no_squish_rotate, compute_force,
    translational_kick(1/2), rotational_kick(1/2)`` (checked operator by
    operator in the tests), with each body touched twice: before the force
    call (kick, drift, free rotor, placement) and after it (finiteness of
    the forces, reduction, kick, momenta).  Free atoms take plain velocity
    Verlet in NumPy.
    """
    s, record = ctx.state, ctx.record
    body, atom, index = ctx.model.packed
    n = ctx.n_bodies
    if ctx.cell_motion is not None:
        # A barostat reads the pressure after the half kick: kick first, then
        # move the cell, and let the loop's own kick add nothing.
        m, half = ctx.model, 0.5 * dt
        s.V += (half * m.inv_mass)[:, None] * record.F
        if ctx.n_free:  # NumPy's 1 µs on empty arrays otherwise
            s.v += half * record.f / m.free_masses[:, None]
        A, B, S = ctx.cell_move(dt)
        s.cell = s.cell @ A.T
        _numba.first_half(s.data, n, np.zeros_like(record.F), record.tau, body, atom, index, dt,
                          record.r, ctx.positions, np.array([A, B, S]), True)
        if ctx.n_free:
            s.x[...] = s.x @ A.T + s.v @ B.T
            s.v[...] = s.v @ S.T
            ctx.positions[m.free] = s.x
    else:
        _numba.first_half(s.data, n, record.F, record.tau, body, atom, index, dt, record.r,
                          ctx.positions, _IDENTITY, False)
        if ctx.n_free:
            m = ctx.model
            s.v += 0.5 * dt * record.f / m.free_masses[:, None]
            s.x += dt * s.v
            ctx.positions[m.free] = s.x
    _force_and_closing_kick(ctx, dt)


def _force_and_closing_kick(ctx, dt):
    """The fused steps' end: the force call, then :func:`rigidmd.core._numba.second_half`
    (body forces and torques, closing kick, momenta) and the free atoms' closing kick."""
    s, record, m = ctx.state, ctx.record, ctx.model
    body, atom, index = m.packed
    evaluator = ctx.evaluator
    forces = evaluator.calculator_forces(s, check=False)
    if ctx.n_free:
        evaluator.check_forces(forces)  # before anything is written
    # The body forces and torques are overwritten only after the forces were found finite.
    written = _numba.second_half(s.data, ctx.n_bodies, record.F, record.tau, body, atom,
                                 index, dt, forces, record.r, ctx.momenta, ctx.write_momenta)
    # The kernels wrote the bodies' arrays in place (first_half, second_half or
    # kick_half_drift, half_drift_place): their versions move once, here (the cell, when
    # a barostat moved it, was assigned, which moved its version then).
    s.touched(positions=True, momenta=True)
    if not written:
        evaluator.check_forces(forces)
        raise NonFiniteForceError(f"calculator returned forces whose sum is not finite after "
                                  f"step {evaluator.step}")
    if ctx.n_free:
        record.f = forces[m.free]
        s.v += 0.5 * dt * record.f / m.free_masses[:, None]
        if ctx.write_momenta:
            ctx.momenta[m.free] = m.free_masses[:, None] * s.v


def fused_baoab(ctx, dt):
    """BAOAB as two compiled loops around the middle: the ``baoab`` scheme, fused.

    The same arithmetic as the operator list ``translational_kick(1/2),
    rotational_kick(1/2), drift(1/2), no_squish_rotate(1/2), middle,
    drift(1/2), no_squish_rotate(1/2), compute_force, translational_kick(1/2),
    rotational_kick(1/2)`` (checked operator by operator in the tests): one loop
    before the middle (kick, half drift, half free rotor), the coupling parts'
    middle (the O step, its own kernel), one loop after it (half drift, half free
    rotor, placement), the force call and :func:`rigidmd.core._numba.second_half`.
    Free atoms take their kicks and drifts in NumPy.  Under a barostat (its
    drift through ``cell_motion``) the operators run instead.
    """
    if ctx.cell_motion is not None:
        for function, dt_scale, extra in BAOAB_OPERATORS:
            function(ctx, dt_scale * dt, **extra) if dt_scale is not None else function(ctx)
        return
    s, record, m = ctx.state, ctx.record, ctx.model
    body, atom, index = m.packed
    n, half = ctx.n_bodies, 0.5 * dt
    _numba.kick_half_drift(s.data, n, record.F, record.tau, body, dt)
    s.touched(positions=True, momenta=True)  # what the middle parts read is summed again
    if ctx.n_free:
        s.v += half * record.f / m.free_masses[:, None]
        s.x += half * s.v
    apply_middle(ctx, dt)
    _numba.half_drift_place(s.data, n, body, atom, index, dt, record.r, ctx.positions)
    if ctx.n_free:
        s.x += half * s.v
        ctx.positions[m.free] = s.x
    _force_and_closing_kick(ctx, dt)


#: The ``baoab`` scheme's operators with their dt scales, for the barostat's path (the same
#: list as :data:`rigidmd.core.schemes.BUILTIN_SCHEMES`' ``baoab``, checked in the tests).
BAOAB_OPERATORS = (
    (apply_translational_kick, 0.5, {}), (apply_rotational_kick, 0.5, {}),
    (apply_drift, 0.5, {}), (apply_no_squish_rotate, 0.5, {}), (apply_middle, 1.0, {}),
    (apply_drift, 0.5, {}), (apply_no_squish_rotate, 0.5, {}), (apply_compute_force, None, {}),
    (apply_translational_kick, 0.5, {}), (apply_rotational_kick, 0.5, {}))
