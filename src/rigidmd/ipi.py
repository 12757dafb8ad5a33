r"""Forces from an engine in another process: an ASE calculator speaking the i-PI protocol.

i-PI's socket protocol (Ceriotti, More and Manolopoulos, Comput. Phys. Commun.
185, 1019 (2014)) is spoken by LAMMPS (``fix ipi``), CP2K, Quantum ESPRESSO,
FHI-aims, DFTB+ and ASE's own :class:`ase.calculators.socketio.SocketClient`
(which wraps any ASE calculator).  :class:`IPICalculator` is the server side:
it listens on a Unix socket ``/tmp/ipi_<name>`` or a TCP port, an engine
connects, and every force call is one exchange of fixed-size messages (12-byte
headers, then native-endian ``float64``/``int32`` arrays)::

    server                     engine
    STATUS            ->
                      <-       READY (or NEEDINIT: the server sends INIT first)
    POSDATA h h^-1 N x ->      (the cell h = cell.T, Bohr; positions, Bohr)
    GETFORCE          ->
                      <-       FORCEREADY E N f W len extra
                               (Hartree, Hartree/Bohr, virial W in Hartree)

After the first exchange the ``STATUS`` polls are skipped: positions and the
request for forces go out in one write, the answer comes back in one read.

Units on the wire are atomic units.  Engines convert with their own Bohr and
Hartree: ASE's client with ASE's (the default here), LAMMPS's ``fix ipi``
with 8-digit ones (``bohr``, ``hartree`` take the engine's values, so that its
numbers come back to roundoff).

Asking for less (rigidmd's extension, for engines that know it)
    A server made with ``tally_requests=True`` sends, in the same write as
    each ``POSDATA``, a ``RMDTALLY`` header and one ``int32``: bit 0 asks for
    the energy, bit 1 for the virial, of that one configuration (forces are
    always computed).  An engine may then skip what is not asked, as native
    LAMMPS tallies energy and virial only on output steps; the calculator
    keeps only the properties asked for.  rigidmd's LAMMPS ``fix rigidmd/ipi``
    understands it; an engine that does not (``fix ipi``, ASE's client, i-PI
    drivers) would stop at the unknown header, so the flag is off by default.
    An engine's ``extra`` string (after the virial) is kept in
    :attr:`IPICalculator.engine_extra`.

The virial ``W = -V σ`` (eV) gives the stress.  LAMMPS's ``fix ipi`` fills
only the upper triangle (xy, xz, yz) and leaves the lower one zero (ASE's own
server would symmetrise that with the zeros and halve every shear stress):
here a zero lower (or upper) triangle is mirrored from the other, and a full
virial is symmetrised.
"""

from __future__ import annotations

import errno
import os
import select
import socket
import struct
import time
import uuid

import numpy as np
from ase import units
from ase.calculators.calculator import Calculator, PropertyNotImplementedError, all_changes

from rigidmd.core.checks import quick_check_state

__all__ = ["EngineError", "IPICalculator", "add_wait_check", "remove_wait_check",
           "symmetric_virial"]

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


def _word(text):
    return text.encode("ascii").ljust(MSGLEN)


class IPICalculator(Calculator):
    r"""An ASE calculator whose forces come from an i-PI engine in another process.

    Parameters
    ----------
    unixsocket : str, optional
        Listen on the Unix socket ``/tmp/ipi_<unixsocket>`` (the engine is
        told ``unixsocket``).  Default when ``port`` is not given: a fresh name.
    port : int, optional
        Listen on this TCP port instead (an engine on another host).
    host : str, default "localhost"
        Interface the TCP server binds to (``""``: all of them).
    timeout : float, default 120.0
        Seconds an engine may take to answer one force call (and to connect,
        see ``connect_timeout``) before :class:`EngineError` is raised.
    connect_timeout : float, optional
        Seconds to wait for the engine to connect (default ``timeout``).
    bohr, hartree : float
        The engine's Bohr (Å) and Hartree (eV): ASE's by default.
    tally_requests : bool, default False
        Say with each configuration whether the energy and the virial are
        wanted (``RMDTALLY``, see the module notes); only for engines that
        understand it.

    Notes
    -----
    Properties: ``energy`` (``free_energy``), ``forces`` and, for a periodic
    cell, ``stress`` (from the virial; see the module notes).  Every call
    computes all of them (the protocol has no cheaper call).  An engine that
    closes the connection, or does not answer within ``timeout``, raises
    :class:`EngineError`; the connection is dropped, and the next call waits
    for a new engine (subclasses start one).
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress"]

    def __init__(self, unixsocket=None, *, port=None, host="localhost", timeout=120.0,
                 connect_timeout=None, bohr=units.Bohr, hartree=units.Hartree,
                 tally_requests=False, **kwargs):
        super().__init__(**kwargs)
        if unixsocket is not None and port is not None:
            raise ValueError("IPICalculator: give unixsocket or port, not both")
        if port is not None and not (1024 < int(port) < 65536):
            raise ValueError(f"IPICalculator: port {port} is not in 1025-65535")
        if not timeout > 0:
            raise ValueError(f"IPICalculator: timeout must be positive, got {timeout!r}")
        if port is None and unixsocket is None:
            unixsocket = f"rigidmd-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.unixsocket = unixsocket
        self.port = None if port is None else int(port)
        self.host = host
        self.timeout = float(timeout)
        self.connect_timeout = self.timeout if connect_timeout is None else float(
            connect_timeout)
        self.bohr = float(bohr)
        self.hartree = float(hartree)
        self.tally_requests = bool(tally_requests)
        #: The ``extra`` string the engine sent with its last forces (bytes).
        self.engine_extra = b""
        self._server = None
        self._conn = None
        self._handshaken = False
        self._bound = None      # (device, inode) of the socket file this calculator bound
        self._peer = None       # the connected engine, in words
        self._peer_pid = None   # its process (Unix socket), when the system says
        self._verified = False  # its first answer was checked (check_first_answer)

    # ------------------------------------------------------------ hooks
    @property
    def socketfile(self):
        """The Unix socket's path (None for TCP)."""
        return None if self.unixsocket is None else f"/tmp/ipi_{self.unixsocket}"

    def launch(self, atoms):
        """Start the engine (here: none; it is started elsewhere and connects)."""

    def engine_failure(self):
        """Why the engine is gone (a sentence), or None while it runs."""
        return None

    def where_to_look(self):
        """Where the engine's own messages are (appended to errors)."""
        return ""

    def frame(self, cell):
        """Rotation ``Q`` taking the cell into the engine's frame (None: no rotation)."""
        return None

    def engine_cell(self, cell):
        """The cell sent for ``cell`` (in the engine's frame): the same lattice, any basis."""
        return cell

    def origin(self, cell):
        """Where the engine puts the cell's origin (Å, in its frame): added to positions."""
        return None

    def engine_positions(self, cell, positions):
        """The positions sent for ``positions`` (Å, engine frame, before :meth:`origin`)."""
        return positions

    def check_peer(self, pid):
        """Why the process ``pid`` that connected is not this calculator's engine, or None."""
        return None

    def check_first_answer(self, energy, forces):
        """Why an engine's first answer shows it is not this system's, or None.

        ``energy`` (eV; None when the engine was not asked for it), ``forces`` (eV/Å,
        shape (n, 3), in the atoms' frame).
        """
        return None

    def stop_engine(self, keep_files=False):
        """Stop the engine (here: none; only the connection is closed).

        ``keep_files``: the engine failed; keep what names the failure (its log).
        """

    @property
    def connected(self):
        """Whether an engine is connected."""
        return self._conn is not None

    # ------------------------------------------------------------ the socket
    def listen(self):
        """Open the socket now (it is opened at the first call otherwise), so that an
        engine started elsewhere can connect; idempotent."""
        if self._server is None:
            self._listen()

    def _listen(self):
        if self.port is None:
            if len(self.socketfile) > 100:
                raise ValueError(f"IPICalculator: unixsocket name too long: {self.socketfile}")
            server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                self._bound = _bind_unix(server, self.socketfile)
            except BaseException:
                server.close()
                raise
        else:
            server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                server.bind((self.host, self.port))
            except OSError as err:
                server.close()
                if err.errno == errno.EADDRINUSE:
                    raise EngineError(f"IPICalculator: port {self.port} on {self.host!r} is in "
                                      "use by another process; give another port") from None
                raise EngineError(f"IPICalculator: cannot listen on {self.host}:{self.port} "
                                  f"({err.strerror or err})") from None
        server.listen(1)
        self._server = server

    @property
    def address(self):
        """Where this calculator listens, in words (the socket file, or host:port)."""
        return self.socketfile if self.port is None else f"{self.host}:{self.port}"

    def describe_engine(self):
        """The connected engine, in words (its process for a Unix socket, else its address)."""
        return self._peer or f"i-PI engine awaited on {self.address}"

    def _fail(self, message):
        """Drop the engine and raise one error naming it and where to look."""
        why = self.engine_failure()
        who = self.describe_engine()
        self._shutdown(keep_files=True)
        detail = f": {why}" if why else ""
        raise EngineError(f"{who}: {message}{detail}{self.where_to_look()}")

    def _wait_readable(self, sock, deadline, what):
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self._fail(f"no {what} within {self._limit:g} s")
            ready, _, _ = select.select([sock], [], [], min(left, WAIT_SLICE))
            if ready:
                return
            for check in list(_wait_checks):
                check()  # a stop request ends the wait (see add_wait_check)
            if self.engine_failure() is not None:
                self._fail(f"died before its {what}")

    def _connect(self, atoms):
        self.listen()
        try:
            self.launch(atoms)
            self._limit = self.connect_timeout
            self._wait_readable(self._server, time.monotonic() + self.connect_timeout,
                                "connection")
            conn, peer = self._server.accept()
        except EngineError:
            raise  # dropped by _fail, which named what it kept
        except BaseException:
            self._shutdown(keep_files=False)
            raise
        if conn.family != socket.AF_UNIX:
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._peer = f"i-PI engine at {peer[0]}:{peer[1]}"
            self._peer_pid = None
        else:
            self._peer_pid = _peer_pid(conn)
            self._peer = (f"i-PI engine on {self.socketfile}" if self._peer_pid is None else
                          f"i-PI engine process {self._peer_pid} ({_command_name(self._peer_pid)})"
                          f" on {self.socketfile}")
        conn.setblocking(True)
        self._conn = conn
        self._handshaken = False
        self._verified = False
        if self._peer_pid is not None:
            why = self.check_peer(self._peer_pid)
            if why is not None:
                self._fail(f"connected, but is not this calculator's engine ({why})")

    def _closed(self, detail):
        """The engine closed the connection: wait a little for it to end, then say why."""
        deadline = time.monotonic() + 2.0
        while self.engine_failure() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        self._fail(f"closed the connection{detail}")

    def _send(self, *parts):
        try:
            self._conn.sendall(b"".join(parts))
        except OSError as err:
            self._closed(f" ({err.strerror})")

    def _recv(self, nbytes, deadline, what):
        buf = bytearray(nbytes)
        view = memoryview(buf)
        got = 0
        while got < nbytes:
            self._wait_readable(self._conn, deadline, what)
            try:
                n = self._conn.recv_into(view[got:])
            except OSError as err:
                self._closed(f" ({err.strerror})")
            if n == 0:
                self._closed("")
            got += n
        return bytes(buf)

    def _header(self, deadline, what):
        return self._recv(MSGLEN, deadline, what).decode("ascii", "replace").strip()

    def _handshake(self, deadline):
        self._send(_word("STATUS"))
        status = self._header(deadline, "status")
        if status == "NEEDINIT":
            self._send(_word("INIT"), np.array([0, 1], np.int32).tobytes(), b"\0")
            self._send(_word("STATUS"))
            status = self._header(deadline, "status")
        if status != "READY":
            self._fail(f"answered STATUS with {status!r}, expected READY")
        self._handshaken = True

    def _exchange(self, cell, positions, tally=b""):
        """Energy (eV), forces (eV/Å) and virial (eV) for positions in the engine's frame.

        ``tally``: what goes before ``POSDATA`` (a ``RMDTALLY`` message, or nothing).
        """
        self._limit = self.timeout
        deadline = time.monotonic() + self.timeout
        if not self._handshaken:
            self._handshake(deadline)
        bohr, n = self.bohr, len(positions)
        h = cell.T / bohr
        ih = np.linalg.inv(h) if np.linalg.det(cell) else np.zeros((3, 3))
        self._send(tally, _word("POSDATA"), np.ascontiguousarray(h, np.float64).tobytes(),
                   np.ascontiguousarray(ih, np.float64).tobytes(),
                   np.array([n], np.int32).tobytes(),
                   np.ascontiguousarray(positions / bohr, np.float64).tobytes(),
                   _word("GETFORCE"))
        while True:
            header = self._header(deadline, "forces")
            if header != "HAVEDATA":  # an engine may still answer a poll
                break
        if header != "FORCEREADY":
            self._fail(f"answered GETFORCE with {header!r}, expected FORCEREADY")
        head = self._recv(12, deadline, "forces")
        energy = float(np.frombuffer(head, np.float64, 1)[0])
        natoms = int(np.frombuffer(head, np.int32, 1, 8)[0])
        if natoms != n:
            self._fail(f"sent forces on {natoms} atoms, expected {n}")
        body = self._recv(8 * (3 * n + 9) + 4, deadline, "forces")
        forces = np.frombuffer(body, np.float64, 3 * n).reshape(n, 3)
        virial = np.frombuffer(body, np.float64, 9, 24 * n).reshape(3, 3)
        extra = int(np.frombuffer(body, np.int32, 1, 24 * n + 72)[0])
        self.engine_extra = self._recv(extra, deadline, "forces") if extra else b""
        hartree = self.hartree
        return energy * hartree, forces * (hartree / bohr), symmetric_virial(virial) * hartree

    # ------------------------------------------------------------ ASE
    def check_state(self, atoms, tol=1e-15):
        """What changed since the last call: ASE's test in a few array operations
        (:func:`rigidmd.core.checks.quick_check_state`; it runs at every property asked)."""
        return quick_check_state(self, atoms, tol, super().check_state)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        atoms = self.atoms
        periodic = bool(atoms.pbc.any())
        if "stress" in properties and not periodic:
            raise PropertyNotImplementedError("IPICalculator: no stress without a periodic cell")
        cell = atoms.cell.array.copy()
        rotation = self.frame(cell) if periodic else None
        positions = atoms.positions
        if rotation is not None:
            cell, positions = cell @ rotation, positions @ rotation
        if periodic:
            cell = self.engine_cell(cell)
            positions = self.engine_positions(cell, positions)
        origin = self.origin(cell) if periodic else None
        if origin is not None:
            positions = positions + origin
        if self._conn is None:
            self._connect(atoms)
        want_energy = not self.tally_requests or bool({"energy", "free_energy"} & set(properties))
        want_stress = periodic and (not self.tally_requests or "stress" in properties)
        tally = b""
        if self.tally_requests:
            tally = _word("RMDTALLY") + np.array([want_energy | want_stress << 1],
                                                 np.int32).tobytes()
        try:
            energy, forces, virial = self._exchange(cell, positions, tally)
        except EngineError:
            raise  # dropped by _fail
        except BaseException:
            # A stop request or Ctrl-C while the engine computes: the exchange cannot be
            # finished, so the engine cannot be asked again.  The next call starts anew.
            self._shutdown(keep_files=False)
            raise
        if rotation is not None:
            forces = forces @ rotation.T
            virial = rotation @ virial @ rotation.T
        if not self._verified:
            why = self.check_first_answer(energy if want_energy else None, forces)
            if why is not None:
                self._fail(f"is not this calculator's engine: {why}")
            self._verified = True
        results = {"forces": forces.copy()}
        if want_energy:
            results.update(energy=energy, free_energy=energy)
        if want_stress:
            stress = -virial / abs(np.linalg.det(atoms.cell.array))
            results["stress"] = stress[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]
        if system_changes:
            self.results = results
        else:  # the same atoms asked for more: keep what was there
            self.results.update(results)

    def close(self):
        """Close the connection, stop the engine and remove the socket file."""
        self._shutdown(keep_files=False)

    def _shutdown(self, keep_files):
        if self._conn is not None and not keep_files:
            try:  # a polite engine ends on EXIT (LAMMPS aborts; its watchdog cleans up)
                self._conn.setblocking(False)
                self._conn.send(_word("EXIT"))
            except OSError:
                pass
        for sock in (self._conn, self._server):
            if sock is not None:
                try:
                    sock.close()
                except OSError:
                    pass
        self._conn = self._server = None
        self._handshaken = False
        self._peer = self._peer_pid = None
        self.stop_engine(keep_files)
        if self._bound is not None:
            _unlink_if_ours(self.socketfile, self._bound)
            self._bound = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - nothing to report to at interpreter exit
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
        server.bind(path)
    except OSError as err:
        if err.errno != errno.EADDRINUSE:
            raise EngineError(f"IPICalculator: cannot create the socket {path} "
                              f"({err.strerror or err})") from None
        if _served(path):
            raise EngineError(f"IPICalculator: the socket {path} is in use by another live "
                              "process (another run's engine server?); give another "
                              "unixsocket name") from None
        os.unlink(path)  # left by a process that is gone
        server.bind(path)
    info = os.stat(path)
    return info.st_dev, info.st_ino


def _unlink_if_ours(path, bound):
    try:
        info = os.stat(path)
        if (info.st_dev, info.st_ino) == bound:
            os.unlink(path)
    except OSError:
        pass


def _peer_pid(conn):
    """The process at the other end of a Unix socket (Linux's SO_PEERCRED), or None."""
    option = getattr(socket, "SO_PEERCRED", None)
    if option is None:
        return None
    try:
        pid, _, _ = struct.unpack("3i", conn.getsockopt(socket.SOL_SOCKET, option,
                                                        struct.calcsize("3i")))
    except OSError:
        return None
    return pid if pid > 0 else None


def _command_name(pid):
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return "unknown program"


def symmetric_virial(virial):
    """The symmetric virial from what an engine sent (see the module notes).

    Parameters
    ----------
    virial : numpy.ndarray, shape (3, 3)

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        The upper triangle mirrored when the lower one is all zero (LAMMPS's
        ``fix ipi``), the lower one when the upper is, else ``(W + W.T) / 2``.
    """
    lower = virial[np.tril_indices(3, -1)]
    upper = virial[np.triu_indices(3, 1)]
    if not np.any(lower):
        return np.triu(virial) + np.triu(virial, 1).T
    if not np.any(upper):
        return np.tril(virial) + np.tril(virial, -1).T
    return 0.5 * (virial + virial.T)
