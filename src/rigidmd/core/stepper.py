r"""The step: coupling halves around the integrator's scheme, with rollback, and the time.

One step of :math:`\Delta t` is the symmetric splitting

.. code-block:: text

    part_1.first_half(Δt/2) ... part_n.first_half(Δt/2)
    the scheme's deterministic step (kicks, drift, rotation, force calls)
    part_n.second_half(Δt/2) ... part_1.second_half(Δt/2)

after which the atom momenta are written once.  A part that acts inside the
deterministic step (``acts_in_middle``, the O of BAOAB) is called by the
scheme's ``middle`` operator, through the step context.  If anything fails (the
calculator, an iteration, a coupling part, a cell too small for a body), the
state, the per-step record, the parts' variables and the atoms are put back
as they were at the start of the step.  The stepper never reads the Atoms:
the force evaluator and the body link do.
"""

from collections.abc import Sequence

import numpy as np

from rigidmd.core.coupling import Coupling
from rigidmd.core.link import BodyLink
from rigidmd.core.operators import remove_centre_velocity
from rigidmd.core.schemes import Scheme
from rigidmd.core.stepcontext import StepContext

__all__ = ["Stepper", "remove_centre_velocity"]


class Stepper:
    """Advances a :class:`StepContext` by whole steps, undoing a step that fails.

    Parameters
    ----------
    scheme : Scheme
    context : StepContext
        The one view of the step: the scheme's operators and the parts read it (its
        ``step`` is set and its ``cell_note`` cleared before each step).
    couplings : sequence of Coupling
        Applied in this order before the scheme and in reverse after it.
    link : BodyLink
        Writes the momenta once per step, and the atoms back after a rollback.
    kernel : callable or None
        The scheme's fused kernel on the dynamics' backend
        (:meth:`rigidmd.core.backend.Backend.scheme_kernel`), or None: the scheme's operators.
    fixcom : bool
        Hold the total momentum at zero (ASE's ``FixCom``).

    Attributes
    ----------
    time : float
        Simulated time (ASE units), summed step by step.
    """

    def __init__(self, scheme: Scheme, context: StepContext, couplings: Sequence[Coupling],
                 link: BodyLink, kernel=None, fixcom: bool = False):
        self.scheme, self.context, self.couplings = scheme, context, tuple(couplings)
        self.view, self.link, self.fixcom = context, link, fixcom
        #: The compiled kernel this stepper runs, or None (the scheme's operators).
        self.kernel = kernel
        self.cell_moves = context.cell_moves
        self.state, self.record = context.state, context.record
        self._backup = self.state.copy()
        self.time = 0.0

    def step(self, dt: float, step: int, energy: bool = False, stress: bool = False) -> None:
        """Advance one step of ``dt`` (ASE time units); ``step`` steps were completed before.

        ``energy`` and ``stress``: the step's force call computes them too
        (see :meth:`rigidmd.core.forces.ForceEvaluator.begin_step`).
        """
        ctx, state, record, view = self.context, self.state, self.record, self.view
        ctx.evaluator.begin_step(step, energy, stress)
        backup = self._backup
        np.copyto(backup.data, state.data)  # state.copy_into(backup), without a call
        couplings = self.couplings
        # The fused kernel writes the record's forces in place after the force call;
        # a coupling's second half may still fail after it (a warning turned error).
        saved = record.backup(copy=self.kernel is None or bool(couplings))
        coupled = [part.get_state() for part in couplings] if couplings else ()
        try:
            view.cell_note = None
            view.step = step
            half = 0.5 * dt
            if couplings:
                for part in couplings:
                    part.first_half(view, half)
            if self.kernel is not None:
                self.kernel(ctx, dt)
            else:
                self.scheme.run(ctx, dt)
            if self.fixcom:
                remove_centre_velocity(state, ctx.model)
            if couplings:
                for part in reversed(couplings):
                    part.second_half(view, half)
            if not ctx.write_momenta or self.kernel is None:
                self.link.write_momenta(state, record.r)
            self.time += dt
        except BaseException:
            backup.copy_into(state)
            record.restore(saved)
            view.cell_note = None
            for part, variables in zip(couplings, coupled, strict=True):
                part.set_state(variables)
            if self.cell_moves:
                self.link.atoms.set_cell(state.cell)
            record.r = self.link.place(state, record.r)
            self.link.write_momenta(state, record.r)
            raise

    def get_state(self) -> dict:
        """The time and the parts' variables (copies)."""
        return {"time": self.time, "couplings": [part.get_state() for part in self.couplings]}

    def set_state(self, saved: dict) -> None:
        """Restore what :meth:`get_state` returned."""
        self.time = float(saved["time"])
        for part, variables in zip(self.couplings, saved["couplings"], strict=True):
            part.set_state(variables)


