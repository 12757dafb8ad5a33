"""Processes the validation scripts start end with them."""

import signal
import sys

__all__ = ["ends_with_parent"]


def ends_with_parent():
    """A ``preexec_fn``: the child gets SIGTERM when its parent dies (Linux's
    PR_SET_PDEATHSIG), so that a script killed outright (SIGKILL, a hang-up, its default
    SIGTERM) leaves nothing computing on: a table point writes what it has and stops, a
    native ``lmp`` ends."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG = 1
