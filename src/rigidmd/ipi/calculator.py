r"""The i-PI server as an ASE calculator: :class:`IPICalculator` (see :mod:`rigidmd.ipi`).

Each force call is one exchange of messages with the connected engine; the
sockets (listening, accepting, waiting) are :mod:`rigidmd.ipi.connection`'s.
"""

from __future__ import annotations

import os
import time
import uuid
import warnings
from numbers import Integral, Real

import numpy as np
from ase import units
from ase.calculators.calculator import Calculator, PropertyNotImplementedError, all_changes

from rigidmd.core.checks import copy_atoms, quick_check_state
from rigidmd.ipi.connection import (
    MSGLEN,
    OWN_SOCKET,
    EngineError,
    NotAPeer,
    accept,
    check_socket_name,
    close_sockets,
    open_server,
    peer_addresses,
    process_folder,
    sweep_stale_sockets,
    unlink_if_ours,
    wait_readable,
    wait_writable,
    word,
)

__all__ = ["IPICalculator", "symmetric_virial"]


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
        Interface the TCP server binds to (``""`` or ``"0.0.0.0"``: all of them, without
        a warning).  Any process that can reach the port may connect, and over TCP one
        engine cannot be told from another; a configuration may name only loopback or a
        Unix socket without ``--trust`` (:doc:`/guide/trust`).  ``peers`` narrows it.
    peers : sequence of str, optional
        TCP only: the hosts (names or IPv4 addresses, resolved when the calculator is
        made) whose engines may connect.  A connection from any other address is closed
        with a warning naming it, and the wait goes on (within ``connect_timeout``).  The
        i-PI protocol has no secret to check, so this is the one guard against another
        host answering the forces; loopback engines must name ``localhost``.
    timeout : float, default 120.0
        Seconds an engine may take to answer one force call, taking the positions
        included (and to connect, see ``connect_timeout``) before :class:`EngineError`
        is raised.
    connect_timeout : float, optional
        Seconds to wait for the engine to connect (default ``timeout``).
    bohr, hartree : float
        The engine's Bohr (Å) and Hartree (eV): ASE's by default.
    tally_requests : bool, default False
        Say with each configuration whether the energy and the virial are
        wanted (``RMDTALLY``, see :mod:`rigidmd.ipi`); only for engines that
        understand it.

    Notes
    -----
    Properties: ``energy`` (``free_energy``), ``forces`` and, for a periodic
    cell, ``stress`` (from the virial; see :mod:`rigidmd.ipi`).  Every call
    computes all of them (the protocol has no cheaper call).  An engine that sends an
    all-zero virial has not computed one (ASE's ``SocketClient`` unless
    ``use_stress=True``): asking for the stress then raises :class:`EngineError`.  An
    engine that closes the connection, or does not answer within ``timeout``, raises
    :class:`EngineError`; the connection is dropped, and the next call waits
    for a new engine (subclasses start one).
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress"]

    def __init__(self, unixsocket=None, *, port=None, host="localhost", timeout=120.0,
                 connect_timeout=None, bohr=units.Bohr, hartree=units.Hartree,
                 tally_requests=False, peers=None, **kwargs):
        name = type(self).__name__
        unknown = sorted(set(kwargs) - _ASE_CALCULATOR_ARGUMENTS)
        if unknown:  # ASE's Calculator would keep them as parameters and use none
            raise TypeError(f"{name}: unknown argument {unknown[0]!r}")
        super().__init__(**kwargs)
        self._owner = os.getpid()  # a forked child must not stop this process's engine
        if unixsocket is not None and port is not None:
            raise ValueError("IPICalculator: give unixsocket or port, not both")
        if peers is not None and port is None:
            raise ValueError("IPICalculator: peers are for TCP (give port); a Unix socket "
                             "is checked by its file's owner")
        if port is not None and (isinstance(port, bool) or not isinstance(port, Integral)
                                 or not 1024 < port < 65536):
            raise ValueError(f"{name}: port must be a whole number in 1025-65535, got {port!r}")
        for field, value in (("timeout", timeout), ("connect_timeout", connect_timeout)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, Real)
                                      or not 0 < value < float("inf")):
                raise ValueError(f"{name}: {field} must be a positive number of seconds, "
                                 f"got {value!r}")
        if port is None and unixsocket is None:
            unixsocket = f"rigidmd-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.unixsocket = check_socket_name(unixsocket)
        self.port = None if port is None else int(port)
        self.host = host
        self.timeout = float(timeout)
        self.connect_timeout = self.timeout if connect_timeout is None else float(connect_timeout)
        self.bohr = float(bohr)
        self.hartree = float(hartree)
        self.tally_requests = bool(tally_requests)
        #: The IPv4 addresses engines may connect from (None: any).
        self.peers = peer_addresses(peers)
        #: The ``extra`` string the engine sent with its last forces (bytes).
        self.engine_extra = b""
        self._server = self._conn = None
        self._copy = None       # the atoms of the last call (copy_atoms writes into it)
        self._handshaken = False
        self._bound = None      # (device, inode) of the socket file this calculator bound
        self._peer = None       # the connected engine, in words
        self._peer_pid = None   # its process (Unix socket), when the system says
        self._peer_folder = None  # that process's working folder, when the system says
        self._verified = False  # its first answer was checked (check_first_answer)
        self._message = None    # (cell, n, tally) and the POSDATA message made for them

    @property
    def owned_here(self) -> bool:
        """Whether this process made the calculator (False in a forked child: the engine,
        its socket and its files are the parent's)."""
        return os.getpid() == self._owner

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
        """Where the engine's own messages are (appended to errors; called while the
        connected engine's process and folder, ``_peer_pid`` and ``_peer_folder``, are known)."""
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
        if self.port is None and OWN_SOCKET.fullmatch(f"ipi_{self.unixsocket}"):
            sweep_stale_sockets()  # the files of our processes killed outright
        self._server, self._bound = open_server(self.socketfile, self.host, self.port)

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
        look = self.where_to_look()  # while the engine and its peer are known
        self._shutdown(keep_files=True)
        detail = f": {why}" if why else ""
        raise EngineError(f"{who}: {message}{detail}{look}")

    def _wait_readable(self, sock, deadline, what):
        trouble = wait_readable(sock, deadline, self.engine_failure)
        if trouble == "timeout":
            self._fail(f"no {what} within {self._limit:g} s")
        if trouble == "died":
            self._fail(f"died before its {what}")

    def _connect(self, atoms):
        self.listen()
        try:
            self.launch(atoms)
            self._limit = self.connect_timeout
            deadline = time.monotonic() + self.connect_timeout
            while True:
                self._wait_readable(self._server, deadline, "connection")
                try:
                    conn, self._peer, self._peer_pid = accept(self._server, self.socketfile,
                                                              self.peers)
                    break
                except NotAPeer as refused:
                    warnings.warn(str(refused), RuntimeWarning, stacklevel=2)
            self._peer_folder = None if self._peer_pid is None else process_folder(
                self._peer_pid)
        except EngineError:
            raise  # dropped by _fail, which named what it kept
        except BaseException:
            self._shutdown(keep_files=False)
            raise
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

    def _send(self, data, deadline, what):
        """Send ``data`` by ``deadline``: an engine that stops reading (its socket's buffer
        full) is waited for as a read is (:func:`~rigidmd.ipi.connection.wait_writable`:
        the timeout and the stop checks apply), never in a blocking send."""
        view = memoryview(data)
        sent = 0
        while sent < len(view):  # a message that fits the buffer goes out in one send, unpolled
            try:
                sent += self._conn.send(view[sent:])
                continue
            except BlockingIOError:
                pass
            except OSError as err:
                self._closed(f" ({err.strerror})")
            trouble = wait_writable(self._conn, deadline, self.engine_failure)
            if trouble == "timeout":
                self._fail(f"took no {what} within {self._limit:g} s (it stopped reading)")
            if trouble == "died":
                self._fail(f"died before taking its {what}")

    def _recv(self, nbytes, deadline, what):
        buf = bytearray(nbytes)
        view = memoryview(buf)
        got = 0
        while got < nbytes:
            self._wait_readable(self._conn, deadline, what)
            try:
                n = self._conn.recv_into(view[got:])
            except BlockingIOError:
                continue  # readable, yet nothing there after all: wait again
            except OSError as err:
                self._closed(f" ({err.strerror})")
            if n == 0:
                self._closed("")
            got += n
        return buf  # a bytearray (not copied again: 124 kB a call at 1728 waters)

    def _header(self, deadline, what):
        return self._recv(MSGLEN, deadline, what).decode("ascii", "replace").strip()

    def _handshake(self, deadline):
        self._send(word("STATUS"), deadline, "status request")
        status = self._header(deadline, "status")
        if status == "NEEDINIT":
            self._send(word("INIT") + np.array([0, 1], np.int32).tobytes() + b"\0", deadline,
                       "INIT")
            self._send(word("STATUS"), deadline, "status request")
            status = self._header(deadline, "status")
        if status != "READY":
            self._fail(f"answered STATUS with {status!r}, expected READY")
        self._handshaken = True

    def _exchange(self, cell, positions, tally=b""):
        """Energy (eV), forces (eV/Å) and virial (eV, as sent) at positions in the engine's frame.

        ``tally``: what goes before ``POSDATA`` (a ``RMDTALLY`` message, or nothing).
        """
        self._limit = self.timeout
        deadline = time.monotonic() + self.timeout
        if not self._handshaken:
            self._handshake(deadline)
        bohr, n = self.bohr, len(positions)
        key = (cell.tobytes(), n, tally, bohr)  # a constant cell: the same message, refilled
        if self._message is None or self._message[0] != key:
            self._message = (key, _posdata_message(cell, n, bohr, tally))
        message = self._message[1]  # the positions written into it in Bohr, no copies:
        np.divide(positions, bohr, out=np.frombuffer(
            message, np.float64, 3 * n, len(message) - 24 * n - MSGLEN).reshape(n, 3))
        self._send(message, deadline, "positions")
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
        if not 0 <= extra <= max(_MAX_EXTRA, _MAX_EXTRA_PER_ATOM * n):
            self._fail(f"sent an extra string of {extra} bytes (expected 0 to "
                       f"{max(_MAX_EXTRA, _MAX_EXTRA_PER_ATOM * n)}): not an i-PI answer")
        self.engine_extra = bytes(self._recv(extra, deadline, "forces")) if extra else b""
        hartree = self.hartree
        return energy * hartree, forces * (hartree / bohr), virial * hartree

    # ------------------------------------------------------------ ASE
    def check_state(self, atoms, tol=1e-15):
        """What changed since the last call: ASE's test in a few array operations
        (:func:`rigidmd.core.checks.quick_check_state`; it runs at every property asked)."""
        return quick_check_state(self, atoms, tol, super().check_state)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        if atoms is not None:  # ASE's Calculator.calculate, without its directory check
            self.atoms = self._copy = copy_atoms(atoms, self._copy)
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
            tally = word("RMDTALLY") + np.array([want_energy | want_stress << 1],
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
        # An all-zero virial is one the engine did not compute (ASE's SocketClient sends
        # zeros unless run(..., use_stress=True)), never a stress of exactly zero.
        no_virial = want_stress and not virial.any()
        virial = symmetric_virial(virial) if want_stress else virial
        if rotation is not None:
            forces = forces @ rotation.T
            virial = rotation @ virial @ rotation.T
        if not self._verified:
            why = self.check_first_answer(energy if want_energy else None, forces)
            if why is not None:
                self._fail(f"is not this calculator's engine: {why}")
            self._verified = True
        if no_virial and "stress" in properties:
            raise EngineError(f"{self.describe_engine()}: sent no virial (all nine components "
                              "exactly zero), so no stress for this periodic cell; have it "
                              "send one (ASE's SocketClient: run(..., use_stress=True))")
        results = {"forces": forces}  # a new array (the exchange scaled what it read)
        if want_energy:
            results.update(energy=energy, free_energy=energy)
        if want_stress and not no_virial:  # else a later stress call asks, and says why not
            stress = -virial / abs(np.linalg.det(atoms.cell.array))
            results["stress"] = stress[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]
        if system_changes:
            self.results = results
        else:  # the same atoms asked for more: keep what was there
            self.results.update(results)

    def get_spin_polarized(self):
        """False: an i-PI engine sends no spin.  (Defined here, ASE's ``Calculator`` sets
        a deprecated stand-in on each instance, a reference cycle that kept a dropped
        calculator, and so its engine, alive until the garbage collector ran.)"""
        return False

    def close(self):
        """Close the connection, stop the engine and remove the socket file.

        In a process forked from the one that made the calculator it only forgets them:
        the engine, its socket and its files are the parent's.
        """
        if os.getpid() != self._owner:
            self._conn = self._server = self._bound = None
            self._forget_engine()
            return
        self._shutdown(keep_files=False)

    def _forget_engine(self):
        """Drop the references to an engine without stopping it (a forked child's close)."""

    def _shutdown(self, keep_files):
        close_sockets(self._conn, self._server, say_exit=not keep_files)
        self._conn = self._server = None
        self._handshaken = False
        self._peer = self._peer_pid = self._peer_folder = None
        self.stop_engine(keep_files)
        if self._bound is not None:
            unlink_if_ours(self.socketfile, self._bound)
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


# The longest ``extra`` string an engine may send (bytes), read into memory before it is
# looked at: 16 MiB, or 1 kB an atom if more.  Real ones are far shorter (LAMMPS's
# fix rigidmd/ipi: a few counters, under 100 bytes; i-PI drivers: JSON of a few
# per-atom numbers, well under 1 kB an atom); a length past it is a broken stream,
# not a string to allocate (2**28 once took 256 MB before the call timed out).
_MAX_EXTRA = 1 << 24
_MAX_EXTRA_PER_ATOM = 1024

#: The keyword arguments of ASE's ``Calculator`` an i-PI calculator passes on.
_ASE_CALCULATOR_ARGUMENTS = frozenset({"restart", "ignore_bad_restart_file", "label", "atoms",
                                       "directory"})


def _posdata_message(cell, n, bohr, tally=b""):
    """A ``POSDATA`` message (``tally`` before it, ``GETFORCE`` after it) for ``cell`` (Å,
    rows a, b, c) and ``n`` atoms, the positions left zero: the ``24 n`` bytes before the
    last 12, to be filled in Bohr.

    Returns
    -------
    bytearray
    """
    h = cell.T / bohr
    ih = np.linalg.inv(h) if np.linalg.det(cell) else np.zeros((3, 3))
    head = b"".join((tally, word("POSDATA"), np.ascontiguousarray(h, np.float64).tobytes(),
                     np.ascontiguousarray(ih, np.float64).tobytes(),
                     np.array([n], np.int32).tobytes()))
    return bytearray(head) + bytearray(24 * n) + word("GETFORCE")


def symmetric_virial(virial):
    """The symmetric virial from what an engine sent (see :mod:`rigidmd.ipi`).

    Parameters
    ----------
    virial : numpy.ndarray, shape (3, 3)

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        The upper triangle mirrored when the lower one is all zero (LAMMPS's
        ``fix ipi``), the lower one when the upper is, else ``(W + W.T) / 2``.
    """
    full = np.array(virial, dtype=float)
    lower, upper = full[_LOWER], full[_UPPER]
    if not lower.any():
        full[_LOWER] = upper
    elif not upper.any():
        full[_UPPER] = lower
    else:
        full = 0.5 * (full + full.T)
    return full


# The off-diagonal elements below and above the diagonal, in mirrored order (yx zx zy, xy xz yz).
_LOWER = (np.array([1, 2, 2]), np.array([0, 0, 1]))
_UPPER = (np.array([0, 0, 1]), np.array([1, 2, 2]))
