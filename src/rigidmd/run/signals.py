"""Stop signals of a run: SIGTERM, SIGINT and SIGUSR1 end it between steps.

:class:`StopSignals` notes a signal and raises :class:`StopRequest` once the
step's outputs are written; :data:`EXIT_STATUS` is the status a run stopped by
each signal exits with.
"""

import os
import signal
import sys

from rigidmd.ipi import add_wait_check, remove_wait_check

__all__ = ["EXIT_STATUS", "StopRequest", "StopSignals", "run_command"]

#: Exit status of a run stopped by each signal (128 + signal number).
EXIT_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGUSR1: 138}


class StopRequest(Exception):
    """A stop signal arrived; raised after the current step's outputs were written."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class StopSignals:
    """Turn SIGTERM, SIGINT and SIGUSR1 into a :class:`StopRequest` between steps.

    :meth:`check` is attached as the last observer, so a stop comes after
    every output of the step.  A second SIGINT raises ``KeyboardInterrupt``
    at once, unless :attr:`shielded` (set while the final checkpoint is
    written): then it is only counted in :attr:`ignored`.
    """

    modifies_atoms = False

    def __init__(self):
        self.signum = None
        self.shielded = False
        self.ignored = 0
        self._previous = {}

    def _handler(self, signum, frame):
        if self.signum is None:
            self.signum = signum
        elif self.shielded:
            self.ignored += 1
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt

    def check(self):
        if self.signum is not None:
            self.shielded = True  # from here on the run only writes what it has
            raise StopRequest(self.signum)

    def __enter__(self):
        for signum in EXIT_STATUS:
            self._previous[signum] = signal.signal(signum, self._handler)
        add_wait_check(self.check)  # a stop also ends a wait for an i-PI engine (<= 0.1 s)
        return self

    def __exit__(self, *exc):
        remove_wait_check(self.check)
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False



def run_command(command_line, stream=None) -> int:
    """Run ``command_line()`` (a command's whole life, returning its exit status) with the
    stop signals' default actions until it returns, and noted after: a signal arriving
    once the command has ended and said so (its outputs whole) is said in one line, and
    the status stays the command's, never a kill without a word (exit 143).

    A command's own :class:`StopSignals` give these handlers back when they end, so that
    no moment is left with the default action.  Before the command ends the handler does
    what the default does: SIGINT raises ``KeyboardInterrupt``, the others end the
    process by the signal.
    """
    ended = []

    def handler(signum, frame):
        if ended:
            print(f"rigidmd: {signal.Signals(signum).name} arrived after the command had "
                  "ended; its outputs are whole", file=stream or sys.stderr, flush=True)
            return
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)

    for signum in (*EXIT_STATUS, signal.SIGHUP):
        signal.signal(signum, handler)
    status = command_line()
    ended.append(True)
    return status
