"""Process trees read from Linux's ``/proc``: who started whom, and the CPU time they used.

:class:`~rigidmd.lammps.LAMMPSEngine` checks that the process at the socket's
other end is the engine it started or one of that engine's processes
(:func:`descends_from`); its benchmark and tests find an engine's ranks
(:func:`descendants`) and the CPU time they spend (:func:`cpu_seconds`).
The process at the other end of a loopback TCP connection is found the same
way (:func:`tcp_peer`: ``/proc/net/tcp`` gives the socket's owner and inode,
``/proc/PID/fd`` the process holding it).  Elsewhere than Linux, or for a process
gone, nothing is found.
"""

import os
import socket
import struct

__all__ = ["descends_from", "descendants", "cpu_seconds", "tcp_peer"]


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


def _tcp_key(address):
    """``/proc/net/tcp``'s spelling of an IPv4 ``(host, port)``: ``0100007F:7A69``."""
    host, port = address[:2]
    return f"{struct.unpack('<I', socket.inet_aton(host))[0]:08X}:{port:04X}"


def tcp_peer(conn):
    """The owner and process of the local socket at the other end of ``conn`` (TCP, IPv4).

    Parameters
    ----------
    conn : socket.socket
        An accepted connection.

    Returns
    -------
    uid, pid : int or None
        ``(None, None)`` when unknown: not Linux, a peer on another machine, or gone.
        ``pid`` is None when the process is not this user's (its ``fd`` cannot be read).
    """
    try:
        local, remote = _tcp_key(conn.getpeername()), _tcp_key(conn.getsockname())
        with open("/proc/net/tcp") as f:
            lines = f.read().splitlines()[1:]
    except (OSError, ValueError):
        return None, None
    for line in lines:
        fields = line.split()
        if len(fields) > 9 and fields[1] == local and fields[2] == remote:
            uid, inode = int(fields[7]), fields[9]
            return uid, _holder(f"socket:[{inode}]")
    return None, None


def _holder(link):
    """The process with an open file descriptor ``link`` (``socket:[INODE]``), or None."""
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            fds = os.listdir(f"/proc/{name}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                if os.readlink(f"/proc/{name}/fd/{fd}") == link:
                    return int(name)
            except OSError:
                continue
    return None
