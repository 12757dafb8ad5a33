r"""r-RESPA for rigid bodies: the force split the evaluator knows, and the outer step.

A dynamics whose atoms carry a :class:`~rigidmd.core.split.MultipleTimeStep`
runs :class:`RespaStep` in place of its scheme.  One outer step of :math:`\Delta t`
with ``k`` substeps (Tuckerman, Berne & Martyna 1992) is

.. code-block:: text

    coupling parts' first halves (Δt/2)              thermostats, barostats: outer level
    slow kick (Δt/2):  V += (Δt/2) F_s/M,  p += (Δt/2) 2 q ⊗ (0, R(q)ᵀ τ_s)
    k NO_SQUISH steps of Δt/k with the fast forces   k fast calls
    one slow call at the final positions
    slow kick (Δt/2)
    coupling parts' second halves (Δt/2)

The :class:`SplitForceEvaluator` keeps one record per level (forces, torques,
point-particle forces, virial, energy: :attr:`~SplitForceEvaluator.fast_record`,
:attr:`~SplitForceEvaluator.slow_record`); the dynamics' own record holds their
sums after each outer step, so coupling parts, observers and checkpoints see the
full model.  A part acting in the middle of the step (the O of
:class:`~rigidmd.RigidLangevinBAOAB`) acts in the middle of the outer step, for
:math:`\Delta t`, inside inner step ``k//2`` (counted from 0: the middle one for odd
``k``, the one just after the outer step's midpoint for even ``k``), which is then the
``baoab`` scheme's: its two half drifts around the O step.  O always sits between half
drifts, as BAOAB needs; between two kicks (the midpoint of an even ``k``) the momenta it
reports would carry velocity Verlet's kinetic bias.  A barostat's drift (MTK's, C-rescale's move)
acts in the inner drifts: MTK's cell velocity carries the cell through each
inner drift; C-rescale moves the cell once, in the first.  A Monte Carlo cell
move, made in the first half, re-evaluates both levels.  With a slow part that
is exactly zero, ``k`` substeps are the single-step dynamics at ``Δt/k``, to
roundoff.
"""

from dataclasses import dataclass

from rigidmd.core import operators as ops
from rigidmd.core.backend import Backend
from rigidmd.core.forces import ForceEvaluator
from rigidmd.core.record import StepRecord
from rigidmd.core.schemes import Scheme, resolve_scheme
from rigidmd.core.split import MultipleTimeStep
from rigidmd.core.stepcontext import StepContext

__all__ = ["SplitRecord", "SplitForceEvaluator", "RespaStep", "respa_for", "record_for",
           "evaluator_for", "respa_step"]


def respa_for(calc, scheme: Scheme, backend: Backend) -> tuple:
    """``(split, outer step)`` for a dynamics whose atoms carry ``calc``; ``(None, None)``
    when ``calc`` is no :class:`MultipleTimeStep`.  Changes nothing; refuses in one line
    a scheme it cannot run (:func:`respa_step`).  What the levels must provide the coupling
    parts is :func:`rigidmd.core.split.check_calculator_properties`'s check."""
    if not isinstance(calc, MultipleTimeStep):
        return None, None
    return calc, respa_step(scheme, calc, backend)


def record_for(split, state, model, link) -> StepRecord:
    """The dynamics' record: a :class:`SplitRecord` under a split, else a StepRecord."""
    return StepRecord(state, model, link) if split is None else SplitRecord(state, model, link)


def evaluator_for(split, link, record, **options) -> ForceEvaluator:
    """The dynamics' evaluator: a :class:`SplitForceEvaluator` under a split."""
    if split is None:
        return ForceEvaluator(link, record, **options)
    return SplitForceEvaluator(link, record, split=split, **options)


class SplitRecord(StepRecord):
    """The dynamics' record under a split: the levels' sums, and each level's own record.

    Attributes
    ----------
    fast, slow : StepRecord
        Each level's forces, torques, point-particle forces, virial and energy
        of its last call.  The levels describe the dynamics' state: their volume and
        kinetic sums are kept with that state's versions, so a cell move (a barostat's
        drift in an inner step, a Monte Carlo move) makes them stale by itself.
    levels_known : bool
        False after restoring a checkpoint that did not store the levels (the next
        outer step evaluates both before it kicks).
    """

    def __init__(self, state, model, link=None):
        super().__init__(state, model, link)
        self.fast = StepRecord(state, model, link)
        self.slow = StepRecord(state, model, link)
        self.levels_known = True

    def backup(self, copy: bool = True) -> tuple:
        """:meth:`StepRecord.backup`, with each level's record (copies): a failed step puts
        the levels back too (a Monte Carlo move accepted before the step failed left them
        with the trial cell's forces, 5e-3 eV/Å off the restored sums)."""
        return super().backup(copy), self.fast.backup(), self.slow.backup()

    def restore(self, token: tuple) -> None:
        own, fast, slow = token
        super().restore(own)
        self.fast.restore(fast)
        self.slow.restore(slow)

    def get_state(self) -> dict:
        """The record's own state and ``levels``: each level's record (copies)."""
        return super().get_state() | {"levels": {"fast": self.fast.get_state(),
                                                 "slow": self.slow.get_state()}}

    def set_state(self, saved: dict) -> None:
        super().set_state(saved)
        levels = saved.get("levels")
        self.levels_known = levels is not None
        if levels is not None:
            self.fast.set_state(levels["fast"])
            self.slow.set_state(levels["slow"])


class SplitForceEvaluator(ForceEvaluator):
    """A :class:`~rigidmd.core.forces.ForceEvaluator` that knows the split into two levels.

    Parameters
    ----------
    link, record, stress, cell_moves
        As :class:`~rigidmd.core.forces.ForceEvaluator`; ``record`` receives the
        sums of the levels.
    split : MultipleTimeStep
        The atoms' calculator.

    Attributes
    ----------
    fast, slow : ForceEvaluator
        Each level's evaluator, calling that level's calculator alone.
    fast_record, slow_record : StepRecord
        Each level's forces, torques, virial and energy of its last call
        (``record.fast``, ``record.slow``).
    """

    def __init__(self, link, record: SplitRecord, *, split: MultipleTimeStep,
                 stress: bool = False, cell_moves: bool = False):
        super().__init__(link, record, stress=stress, cell_moves=cell_moves)
        self.split = split
        self.fast_record, self.slow_record = record.fast, record.slow
        self.fast = ForceEvaluator(link, self.fast_record, stress=stress,
                                   cell_moves=cell_moves, calc=split.fast,
                                   label=f"the fast level ({type(split.fast).__name__})")
        self.slow = ForceEvaluator(link, self.slow_record, stress=stress,
                                   cell_moves=cell_moves, calc=split.slow,
                                   label=f"the slow level ({type(split.slow).__name__})")
        self.asked = (False, False)  # energy, stress of the step's last calls

    def begin_step(self, step: int, energy: bool = False, stress: bool = False) -> None:
        super().begin_step(step, energy, stress)
        self.asked = (energy, stress)
        self.fast.begin_step(step, energy, stress)
        self.slow.begin_step(step, energy, stress)

    def evaluate(self, state) -> None:
        """Both levels at ``state`` (two calls), their sums into the dynamics' record."""
        self.fast.begin_step(self.step, *self.asked)
        self.fast.evaluate(state)
        self.evaluate_slow(state)

    def evaluate_slow(self, state) -> None:
        """The slow level at the atoms the fast level placed last; then the sums."""
        fast, slow = self.fast_record, self.slow_record
        slow.r = fast.r  # the placement the slow call's molecular virial reads
        forces = self.slow.calculator_forces(state)
        slow.F, slow.tau = ops.reduce_forces(forces, fast.r, self.model)
        slow.f = forces[self.model.free]
        self.combine()

    def combine(self) -> None:
        """The dynamics' record: the sums of the levels' forces, torques, virials, energies."""
        record, fast, slow = self.record, self.fast_record, self.slow_record
        record.F, record.tau, record.f = fast.F + slow.F, fast.tau + slow.tau, fast.f + slow.f
        record.r = fast.r.copy()
        record.virial = (None if fast.virial is None or slow.virial is None
                         else fast.virial + slow.virial)
        record.energy = (None if fast.energy is None or slow.energy is None
                         else fast.energy + slow.energy)
        self.energy_known = self.fast.energy_known and self.slow.energy_known
        record.levels_known = True
        self.split.publish(self.atoms)  # the split's cache: the sums at these positions


@dataclass(eq=False)
class _InnerContext(StepContext):
    """An inner step's context: the fast level's record and evaluator; its ``view`` (what
    the parts and the barostat's drift query get) is the dynamics' context."""

    outer_middle: bool = False  # a part acts in the middle of the outer step


class _Stretched:
    """A middle part acting over the outer step when called inside one inner step."""

    def __init__(self, part, factor: int):
        self.part, self.factor = part, factor

    def middle(self, view, h):
        self.part.middle(view, self.factor * h)


def respa_step(scheme: Scheme, split: MultipleTimeStep, backend: Backend) -> "RespaStep":
    """The outer step a dynamics runs for ``split``; refuses an inner scheme it cannot run.

    Raises
    ------
    ValueError
        ``scheme`` is neither NO_SQUISH nor its ``baoab`` form (one line).
    """
    for name in ("no_squish", "baoab"):
        if scheme == resolve_scheme(name):
            return RespaStep(scheme, split, backend)
    raise ValueError(f"MultipleTimeStep: the inner steps are NO_SQUISH (integrator no_squish, "
                     f"or baoab), not {scheme.name!r}")


class RespaStep:
    """One r-RESPA outer step: what :class:`~rigidmd.core.stepper.Stepper` runs for a split.

    Parameters
    ----------
    scheme : Scheme
        ``no_squish`` or ``baoab``: the inner step (``baoab`` only where a part acts
        in the middle, see the module's text).
    split : MultipleTimeStep
        Its ``substeps`` are read at every outer step.
    backend : rigidmd.core.backend.Backend
        The dynamics' backend: the inner steps run its step functions (the fused
        kernels on the compiled backend, the operators on the reference).
    """

    kernel = None  # the stepper runs run() and writes the momenta itself

    def __init__(self, scheme: Scheme, split: MultipleTimeStep, backend: Backend):
        self.scheme, self.split, self.backend = scheme, split, backend
        self.name = scheme.name
        self.plain = resolve_scheme("no_squish")
        self.baoab = resolve_scheme("baoab")
        #: The inner step of each scheme (own, plain, middle), on the backend.
        self._step_of = {id(s): backend.step_function(s)
                         for s in (self.scheme, self.plain, self.baoab)}
        self._contexts = None

    def _inner(self, ctx):
        """The inner contexts (plain, middle), built once."""
        if self._contexts is None:
            ev = ctx.evaluator
            common = dict(positions=ctx.positions, momenta=ctx.momenta, write_momenta=False,
                          cell_motion=ctx.cell_motion, view=ctx.view,
                          outer_middle=bool(ctx.middle))
            plain = _InnerContext(ctx.state, ctx.model, ev.fast_record, ev.fast, **common)
            middle = _InnerContext(ctx.state, ctx.model, ev.fast_record, ev.fast,
                                   middle=tuple(_Stretched(part, self.split.substeps)
                                                for part in ctx.middle), **common)
            self._contexts = [plain, middle, self.split.substeps]
        plain, middle, k = self._contexts
        if k != self.split.substeps:  # substeps changed: the middle parts' stretch too
            middle.middle = tuple(_Stretched(part.part, self.split.substeps)
                                  for part in middle.middle)
            self._contexts[2] = self.split.substeps
        return plain, middle

    def _inner_step(self, ctx, dt, with_middle: bool) -> None:
        # NO_SQUISH inner steps around a middle part's step; else the dynamics' own scheme.
        scheme = self.baoab if with_middle else self.plain if ctx.outer_middle else self.scheme
        self._step_of[id(scheme)](ctx, dt)

    def run(self, ctx, dt) -> None:
        """Advance ``ctx`` (the dynamics' context) by one outer step of ``dt``."""
        ev, state, model, record = ctx.evaluator, ctx.state, ctx.model, ctx.record
        if ev.atoms.calc is not self.split:
            raise ValueError("MultipleTimeStep: the atoms' calculator was replaced after the "
                             "dynamics was made; make a new dynamics for the new calculator")
        if not record.levels_known:  # a checkpoint without the levels: both, once
            ev.evaluate(state)
        k = self.split.substeps
        plain, middle = self._inner(ctx)
        slow = ev.slow_record
        # (a failure is undone by the stepper: its record backup holds the levels' records)
        half = 0.5 * dt
        ops.translational_kick(state, slow.F, slow.f, model, half)
        ops.rotational_kick(state, slow.tau, half)
        h, centre = dt / k, k // 2
        acts = bool(ctx.middle)
        energy, stress = ev.asked
        for j in range(k):
            ev.fast.begin_step(ev.step, *((energy, stress) if j == k - 1 else (False, False)))
            inside = acts and j == centre  # O between the half drifts of inner step k//2
            self._inner_step(middle if inside else plain, h, inside)
            if ctx.fixcom and j < k - 1:  # (the stepper removes it after the last)
                ops.remove_centre_velocity(state, model)  # FixCom: as each single step
        ev.evaluate_slow(state)
        ops.translational_kick(state, slow.F, slow.f, model, half)
        ops.rotational_kick(state, slow.tau, half)

    def todict(self):
        return self.scheme.todict()
