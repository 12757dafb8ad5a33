"""The socket side of :class:`~rigidmd.ipi.IPICalculator`: listening, accepting, waiting.

A Unix socket ``/tmp/ipi_<name>`` or a TCP port is opened
(:func:`open_server`); a stale socket file (its process gone) is replaced, a
live one refused, and only the file this process bound is removed at the end
(:func:`unlink_if_ours`); the files of this package's processes killed outright are
removed by the next one (:func:`sweep_stale_sockets`).  A Unix socket is bound with mode
0600.  An engine that
connects is named by its process (Linux's ``SO_PEERCRED`` for a Unix socket,
``/proc/net/tcp`` for loopback TCP: :func:`accept`), and another user's process is
refused.  While an
engine is awaited, or sent a message while it has stopped reading, the checks of
:func:`add_wait_check` run every :data:`WAIT_SLICE` seconds (:func:`wait_readable`,
:func:`wait_writable`).
"""

from __future__ import annotations

import errno
import os
import re
import select
import socket
import stat
import struct
import time

from rigidmd.ipi.processes import tcp_peer

__all__ = ["MSGLEN", "OWN_SOCKET", "SOCKET_NAME_RULE", "WAIT_SLICE", "EngineError",
           "NotAPeer", "accept", "peer_addresses",
           "add_wait_check", "check_socket_name", "close_sockets", "open_server", "process_folder",
           "remove_wait_check", "socket_name_ok", "sweep_stale_sockets", "unlink_if_ours",
           "wait_readable", "wait_writable", "word"]

#: Length of an i-PI header (bytes).
MSGLEN = 12
#: Seconds between looks at :func:`add_wait_check`'s checks while an engine is awaited.
WAIT_SLICE = 0.1

_wait_checks = []


def add_wait_check(check):
    """Call ``check()`` every :data:`WAIT_SLICE` seconds while an engine is awaited.

    Whatever ``check`` raises (a stop request after a signal) ends the wait:
    the engine is dropped (its exchange cannot be finished) and the exception
    propagates out of the force call, whose step a rigidmd dynamics undoes.
    A force call that is answered within one slice is never interrupted.
    """
    _wait_checks.append(check)


def remove_wait_check(check):
    """Undo :func:`add_wait_check` (no error when ``check`` is not there)."""
    if check in _wait_checks:
        _wait_checks.remove(check)


class EngineError(RuntimeError):
    """An i-PI engine died, hung or broke the protocol (the message says which and where)."""


#: What a Unix socket's name may be (said when one is refused).
SOCKET_NAME_RULE = ("letters, digits, '.', '_' and '-', not starting with '.', at most 80; the "
                    "socket is /tmp/ipi_NAME, so '/' and '..' would put it elsewhere")


def socket_name_ok(name):
    """Whether ``name`` is a plain Unix socket name: ``/tmp/ipi_NAME`` stays in ``/tmp``.

    Letters, digits, ``.``, ``_`` and ``-``, at most 80, not starting with ``.``: no
    ``/`` or ``..`` that would put the socket (and its removal) elsewhere.
    """
    return isinstance(name, str) and re.fullmatch(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,79}",
                                                  name) is not None


def check_socket_name(name):
    """``name`` (None: TCP) if it is a plain socket name, else ValueError saying the rule."""
    if name is not None and not socket_name_ok(name):
        raise ValueError(f"IPICalculator: unixsocket {name!r} is not a plain name "
                         f"({SOCKET_NAME_RULE})")
    return name


def word(text):
    """An i-PI header: ``text`` in ASCII, padded with blanks to :data:`MSGLEN` bytes."""
    return text.encode("ascii").ljust(MSGLEN)


def wait_readable(sock, deadline, engine_failure):
    """Wait until ``sock`` can be read, running :func:`add_wait_check`'s checks meanwhile.

    Parameters
    ----------
    sock : socket.socket
    deadline : float
        ``time.monotonic()`` at which to give up.
    engine_failure : callable
        Returns why the engine is gone (a sentence), or None while it runs.

    Returns
    -------
    str or None
        None when readable, ``"timeout"`` past the deadline, ``"died"`` when
        ``engine_failure`` says so.
    """
    return _wait(sock, select.POLLIN | select.POLLPRI, deadline, engine_failure)


def wait_writable(sock, deadline, engine_failure):
    """Wait until ``sock`` takes more bytes, running :func:`add_wait_check`'s checks meanwhile.

    As :func:`wait_readable`, for an engine that has stopped reading while the socket's
    buffer is full (a closed or reset connection counts as writable: the next send says so).

    Returns
    -------
    str or None
        None when writable, ``"timeout"`` past the deadline, ``"died"`` when
        ``engine_failure`` says so.
    """
    return _wait(sock, select.POLLOUT, deadline, engine_failure)


def _wait(sock, events, deadline, engine_failure):
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return "timeout"
        # poll, not select: select refuses a descriptor numbered 1024 or more ("filedescriptor
        # out of range"), which a process with many files open gets for every new socket.
        poller = select.poll()
        poller.register(sock, events)
        if poller.poll(max(1, int(1000 * min(left, WAIT_SLICE)))):
            return None
        for check in list(_wait_checks):
            check()  # a stop request ends the wait (see add_wait_check)
        if engine_failure() is not None:
            return "died"


def open_server(socketfile, host, port):
    """A listening socket: the Unix socket ``socketfile`` when ``port`` is None, else TCP.

    Returns
    -------
    server : socket.socket
    bound : tuple or None
        ``(st_dev, st_ino)`` of the socket file bound (None for TCP).

    Raises
    ------
    ValueError
        The socket file's path is too long.
    EngineError
        The socket file is served by a live process, or the port is in use.
    """
    bound = None
    if port is None:
        if len(socketfile) > 100:
            raise ValueError(f"IPICalculator: unixsocket name too long: {socketfile}")
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            bound = _bind_unix(server, socketfile)
        except BaseException:
            server.close()
            raise
    else:
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            server.bind((host, port))
        except OSError as err:
            server.close()
            if err.errno == errno.EADDRINUSE:
                raise EngineError(f"IPICalculator: port {port} on {host!r} is in "
                                  "use by another process; give another port") from None
            raise EngineError(f"IPICalculator: cannot listen on {host}:{port} "
                              f"({err.strerror or err})") from None
    server.listen(1)
    return server, bound


class NotAPeer(EngineError):
    """A TCP connection from an address not among the calculator's peers: it is closed and
    the wait for the engine goes on."""


def peer_addresses(peers):
    """The IPv4 addresses of ``peers`` (host names or addresses), a frozenset; None for None.

    Raises
    ------
    ValueError
        A peer that is not a non-empty string, or a name that does not resolve (named).
    """
    if peers is None:
        return None
    if isinstance(peers, str):
        peers = [peers]
    addresses = set()
    for peer in peers:
        if not isinstance(peer, str) or not peer.strip():
            raise ValueError(f"IPICalculator: peers: {peer!r} is not a host name or an "
                             "IPv4 address")
        try:
            addresses.update(socket.gethostbyname_ex(peer.strip())[2])
        except OSError as err:
            raise ValueError(f"IPICalculator: peers: {peer!r} does not resolve to an IPv4 "
                             f"address ({err.strerror or err})") from None
    if not addresses:
        raise ValueError("IPICalculator: peers: empty; give the hosts whose engines may "
                         "connect, or leave peers out")
    return frozenset(addresses)


def accept(server, socketfile, peers=None):
    """Accept the engine waiting on ``server`` (readable); a non-blocking connection.

    Non-blocking, so that a send to an engine that has stopped reading waits with a
    deadline (:func:`wait_writable`) instead of in the kernel, where neither the
    timeout nor a stop request can end it.

    Parameters
    ----------
    server : socket.socket
    socketfile : str or None
        The Unix socket's path (None for TCP), to name it.
    peers : frozenset of str, optional
        For TCP, the IPv4 addresses an engine may connect from (:func:`peer_addresses`).

    Returns
    -------
    conn : socket.socket
    peer : str
        The engine in words (its process, program and working folder when the system
        says, else its address).
    peer_pid : int or None
        Its process (Linux: ``SO_PEERCRED`` for a Unix socket, ``/proc/net/tcp`` for
        loopback TCP).

    Raises
    ------
    NotAPeer
        A TCP connection from an address not in ``peers`` (it is disconnected).
    EngineError
        The process that connected is another user's (it is disconnected): on loopback
        any local user can connect first and answer the forces.
    """
    conn, address = server.accept()
    if conn.family != socket.AF_UNIX:
        if peers is not None and address[0] not in peers:
            close_sockets(conn, None, say_exit=False)
            raise NotAPeer(f"IPICalculator: refused a connection from {address[0]}:"
                           f"{address[1]}, not among the peers ({', '.join(sorted(peers))}); "
                           "still waiting for the engine")
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        on = f"at {address[0]}:{address[1]}"
        uid, pid = tcp_peer(conn)
    else:
        on = f"on {socketfile}"
        uid, pid = _peer_credentials(conn)
    if pid is None:
        peer = f"i-PI engine {on}"
    else:
        folder = process_folder(pid)
        where = "" if folder is None else f", in {folder}"
        peer = f"i-PI engine process {pid} ({_command_name(pid)}{where}) {on}"
    if uid is not None and uid != os.getuid():
        close_sockets(conn, None, say_exit=False)
        shown = f"process {pid}" if pid is not None else "a process"
        raise EngineError(f"IPICalculator: {shown} of another user (uid {uid}) connected "
                          f"{on} first; its forces are not used (refused, the run stops)")
    conn.setblocking(False)
    return conn, peer, pid


def close_sockets(conn, server, say_exit):
    """Close the connection and the server (either may be None); ``say_exit``: send EXIT first.

    A polite engine ends on ``EXIT`` (LAMMPS aborts; its watchdog cleans up).
    """
    if conn is not None and say_exit:
        try:
            conn.setblocking(False)
            conn.send(word("EXIT"))
        except OSError:
            pass
    for sock in (conn, server):
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass


def unlink_if_ours(path, bound):
    """Remove the socket file ``path`` if it is still the one bound (``(st_dev, st_ino)``)."""
    try:
        info = os.stat(path)
        if (info.st_dev, info.st_ino) == bound:
            os.unlink(path)
    except OSError:
        pass


def _listening_unix_paths():
    """Paths of the listening Unix sockets on this machine (Linux), or None if unknown."""
    try:
        with open("/proc/net/unix") as f:
            lines = f.read().splitlines()[1:]
    except OSError:
        return None
    paths = set()
    for line in lines:
        fields = line.split(None, 7)
        if len(fields) == 8 and int(fields[3], 16) & 0x10000:  # __SO_ACCEPTCON: listening
            paths.add(fields[7])
    return paths


def _served(path):
    """Whether a live process listens on the Unix socket ``path``.

    Linux lists listening sockets in ``/proc/net/unix``: looked up there, so
    that the server is not disturbed.  Elsewhere a connection is tried (and
    closed at once).
    """
    listening = _listening_unix_paths()
    if listening is not None:
        if path in listening:
            return True
        time.sleep(0.2)  # a process that has bound the socket but not yet listened on it
        return path in (_listening_unix_paths() or ())
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    probe.settimeout(1.0)
    try:
        probe.connect(path)
    except OSError:
        return False
    finally:
        probe.close()
    return True


def _bind_unix(server, path):
    """Bind ``server`` to ``path``; a stale socket file is replaced, a live one refused.

    Returns the socket file's ``(st_dev, st_ino)``, so that only this file is
    removed at the end (never another process's).
    """
    try:
        _bind_private(server, path)
    except OSError as err:
        if err.errno != errno.EADDRINUSE:
            raise EngineError(f"IPICalculator: cannot create the socket {path} "
                              f"({err.strerror or err})") from None
        try:
            info = os.lstat(path)
        except OSError:
            info = None
        if info is not None and not stat.S_ISSOCK(info.st_mode):
            raise EngineError(f"IPICalculator: {path} exists and is not a socket (left "
                              "alone); give another unixsocket name") from None
        if info is not None and info.st_uid != os.getuid():
            raise EngineError(f"IPICalculator: the socket {path} belongs to another user "
                              f"(uid {info.st_uid}; left alone); give another unixsocket "
                              "name") from None
        if _served(path):
            raise EngineError(f"IPICalculator: the socket {path} is in use by another live "
                              "process (another run's engine server?); give another "
                              "unixsocket name") from None
        try:
            os.unlink(path)  # our own socket, left by a process that is gone
            _bind_private(server, path)
        except OSError as err:
            raise EngineError(f"IPICalculator: cannot replace the stale socket {path} "
                              f"({err.strerror or err})") from None
    info = os.stat(path)
    return info.st_dev, info.st_ino


def _bind_private(server, path):
    """Bind the Unix socket ``server`` to ``path`` as mode 0600: only this user connects.

    Linux checks write permission on the socket file at ``connect``, and the file takes
    its mode from the socket's inode less the umask at ``bind``: the inode is made 0600
    first (``fchmod`` of the unbound socket), so the process's umask, shared by its
    threads, is never changed.  Where ``fchmod`` of a socket is refused, the file is made
    0600 right after ``bind`` (:func:`accept` refuses another user's process either way).
    """
    try:
        os.fchmod(server.fileno(), 0o600)
        narrowed = True
    except OSError:
        narrowed = False
    server.bind(path)
    if not narrowed:
        os.chmod(path, 0o600)


#: The socket files :class:`~rigidmd.ipi.IPICalculator` names itself:
#: ``/tmp/ipi_rigidmd-<pid>-<8 hex digits>``.
OWN_SOCKET = re.compile(r"ipi_rigidmd-(\d+)-[0-9a-f]{8}")


def sweep_stale_sockets(folder="/tmp"):
    """Remove the socket files this package named whose process is gone.

    A process killed outright (``SIGKILL``, the machine's out-of-memory killer) cannot
    remove its socket file.  Removed here: files named as :data:`OWN_SOCKET`, sockets,
    owned by this user, whose process (the pid in the name) no longer exists and which
    no process listens on.  Anything else is left alone.

    Returns
    -------
    list of str
        The paths removed.
    """
    removed = []
    if not os.path.isdir("/proc/self"):
        return removed  # this system cannot tell whether a process lives
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        match = OWN_SOCKET.fullmatch(name)
        if match is None or os.path.exists(f"/proc/{match.group(1)}"):
            continue  # not ours, or its process lives
        path = os.path.join(folder, name)
        try:
            info = os.lstat(path)
        except OSError:
            continue
        if not stat.S_ISSOCK(info.st_mode) or info.st_uid != os.getuid() or _served(path):
            continue
        try:
            os.unlink(path)
            removed.append(path)
        except OSError:
            pass
    return removed


def _peer_credentials(conn):
    """The owner and process at the other end of a Unix socket (Linux's SO_PEERCRED):
    ``(uid, pid)``, each None when unknown."""
    option = getattr(socket, "SO_PEERCRED", None)
    if option is None:
        return None, None
    try:
        pid, uid, _ = struct.unpack("3i", conn.getsockopt(socket.SOL_SOCKET, option,
                                                          struct.calcsize("3i")))
    except OSError:
        return None, None
    return (uid if pid > 0 else None), (pid if pid > 0 else None)


def process_folder(pid):
    """The working folder of process ``pid`` (Linux, a process of this user), or None."""
    try:
        return os.readlink(f"/proc/{pid}/cwd")
    except OSError:
        return None


def _command_name(pid):
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return "unknown program"
