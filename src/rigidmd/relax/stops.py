"""How :func:`rigidmd.relax.filter.relax` stops: a failed step, Ctrl-C, the last whole step.

* :class:`WholeStep` keeps the structure of the optimizer's last whole step,
  to which the atoms go back when a step fails (not the failed trial point).
* :func:`failed` is the one-line exception of a failed step: a line search
  that found no descent, an exception of the calculator, non-finite forces.
* :class:`Interrupt` makes Ctrl-C finish the step, its frame and the state
  file before ``KeyboardInterrupt``, as ``rigidmd relax`` stops.
"""

import signal
import threading

__all__ = ["RelaxationFailed", "WholeStep", "Interrupt", "Interrupted", "failed"]


class RelaxationFailed(RuntimeError):
    """The optimizer or the calculator failed in a step of
    :func:`rigidmd.relax.filter.relax` (a line search
    that found no descent, an exception of the calculator); the atoms are back at the
    structure of the last whole step, which the message names."""


def failed(err, optimizer, done):
    """The exception that says a step failed: of ``err``'s kind for non-finite forces
    (:class:`~rigidmd.core.forces.NonFiniteForceError`), else :class:`RelaxationFailed`."""
    from rigidmd.core.forces import NonFiniteForceError

    reason = " ".join(str(err).split()) or type(err).__name__
    if isinstance(err, NonFiniteForceError):
        reason = reason.split(" after step ")[0]  # the dynamics' step: not the optimizer's
    else:
        reason = f"{type(err).__name__}: {reason}"
    message = (f"relax: {optimizer} failed after step {done} ({reason}); the atoms are back "
               f"at the structure of step {done}")
    if isinstance(err, NonFiniteForceError):
        return NonFiniteForceError(message)
    return FailedValue(message) if isinstance(err, ValueError) else RelaxationFailed(message)


class FailedValue(RelaxationFailed, ValueError):
    """A ValueError in a step (a cell shrunk below a body, ...): still one for its callers."""


class Interrupted(Exception):
    """A Ctrl-C arrived during a step of :func:`relax`; raised after the step, as an observer."""


class Interrupt:
    """Ctrl-C in :func:`relax` as in ``rigidmd relax``: the step, its frame and the state
    file are finished, then ``KeyboardInterrupt``; a second Ctrl-C interrupts at once.

    Only where SIGINT has Python's own handler, in the main thread: a program that
    handles it (``rigidmd``'s commands) keeps its handling.
    """

    def __init__(self):
        self.pending, self.previous = False, None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self.previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum, frame):
        if self.pending:
            raise KeyboardInterrupt
        self.pending = True

    def __call__(self):
        if self.pending:
            raise Interrupted

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)
            self.previous = None
        return False


class WholeStep:
    """The positions and cell of the optimizer's last whole step (an observer), and its
    number (``step``: the optimizer's steps then)."""

    def __init__(self, atoms, opt):
        self.atoms, self.opt = atoms, opt
        self()

    def __call__(self):
        self.step = self.opt.nsteps
        self.positions = self.atoms.positions.copy()
        self.cell = self.atoms.cell.array.copy()

    def restore(self):
        self.atoms.set_cell(self.cell, scale_atoms=False)
        self.atoms.positions = self.positions
