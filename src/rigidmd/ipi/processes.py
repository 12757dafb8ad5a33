"""Process trees read from Linux's ``/proc``: who started whom, and the CPU time they used.

:class:`~rigidmd.lammps.LAMMPSEngine` checks that the process at the socket's
other end is the engine it started or one of that engine's processes
(:func:`descends_from`); its benchmark and tests find an engine's ranks
(:func:`descendants`) and the CPU time they spend (:func:`cpu_seconds`).
Elsewhere than Linux, or for a process gone, nothing is found.
"""

import os

__all__ = ["descends_from", "descendants", "cpu_seconds"]


def _stat(pid):
    """The fields of ``/proc/PID/stat`` after the command name (the state first), or None."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()


def descends_from(pid, ancestor):
    """Whether process ``pid`` is ``ancestor`` or one of its descendants (64 generations).

    Parameters
    ----------
    pid, ancestor : int

    Returns
    -------
    bool
    """
    seen = 0
    while pid > 1 and seen < 64:
        if pid == ancestor:
            return True
        fields = _stat(pid)
        if fields is None:
            return False
        pid = int(fields[1])
        seen += 1
    return pid == ancestor


def descendants(pid):
    """Every descendant of process ``pid`` (children first, then theirs), a list of int."""
    parents = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            fields = _stat(name)
            if fields is not None:
                parents[int(name)] = int(fields[1])
    found, frontier = [], [pid]
    while frontier:
        frontier = [p for p, parent in parents.items() if parent in frontier]
        found += frontier
    return found


def cpu_seconds(pids):
    """CPU seconds (user + system) the processes ``pids`` have used so far (those gone: 0)."""
    ticks = 0
    for pid in pids:
        fields = _stat(pid)
        if fields is not None:
            ticks += int(fields[11]) + int(fields[12])
    return ticks / os.sysconf("SC_CLK_TCK")
