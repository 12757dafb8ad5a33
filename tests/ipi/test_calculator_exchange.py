"""A force call's exchange with an engine that misbehaves: stops reading, sends no virial,
or a broken length (rigidmd.ipi.IPICalculator).

Found by an outside pass: a send to an engine that had stopped reading hung past the
timeout and past a stop signal; an all-zero virial (ASE's ``SocketClient`` by default)
gave a stress of exactly zero without a word; an ``extra`` length of -1 raised
``ValueError: negative count`` and one of 2**28 allocated 256 MB.

The engines here are threads of the test process (a Unix socket each), so that nothing
is left behind: each is released and joined, and the calculator removes its socket.
"""

import os
import socket
import threading
import time

import numpy as np
import pytest
from ase import Atoms, units
from ase.build import bulk

from rigidmd.ipi import EngineError, IPICalculator, add_wait_check, remove_wait_check
from rigidmd.ipi.connection import MSGLEN, word


class FakeEngine(threading.Thread):
    """An i-PI engine in a thread: forces of harmonic wells at the origin (U = sum x^2/2,
    eV and Å), the virial ``virial`` (Hartree) and an ``extra`` string of length
    ``extra_length`` (default: its real length, the string itself sent only then).

    ``stall``: after its first READY it reads nothing until :meth:`stop` (its socket's
    buffer fills).
    """

    def __init__(self, socketfile, *, virial=None, extra=b"", extra_length=None,
                 stall=False):
        super().__init__(daemon=True)
        self.socketfile = socketfile
        self.virial = np.zeros((3, 3)) if virial is None else np.asarray(virial, float)
        self.extra = extra
        self.extra_length = len(extra) if extra_length is None else extra_length
        self.stall = stall
        self.released = threading.Event()
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(20)  # a test gone wrong ends, never hangs

    def recv(self, n):
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise EOFError
            data += chunk
        return data

    def run(self):
        try:
            self.sock.connect(self.socketfile)
            self.serve()
        except (OSError, EOFError):
            pass  # the calculator dropped the connection: the test says what it expected
        finally:
            self.sock.close()

    def serve(self):
        state, answer = "READY", None
        while True:
            header = self.recv(MSGLEN).decode().strip()
            if header == "EXIT":
                return
            if header == "STATUS":
                self.sock.sendall(word(state))
                if self.stall:
                    self.released.wait(20)
                    return
            elif header == "POSDATA":
                self.recv(144)
                n = int(np.frombuffer(self.recv(4), np.int32)[0])
                x = np.frombuffer(self.recv(24 * n), np.float64).reshape(n, 3) * units.Bohr
                answer, state = (0.5 * float((x * x).sum()), -x, n), "HAVEDATA"
            elif header == "GETFORCE":
                energy, forces, n = answer
                self.sock.sendall(b"".join((
                    word("FORCEREADY"), np.float64(energy / units.Ha).tobytes(),
                    np.int32(n).tobytes(), (forces * (units.Bohr / units.Ha)).tobytes(),
                    self.virial.tobytes(), np.int32(self.extra_length).tobytes(),
                    self.extra if self.extra_length == len(self.extra) else b"")))
                state = "READY"

    def stop(self):
        self.released.set()
        self.join(timeout=25)
        assert not self.is_alive()


def served(calc, **engine):
    """``calc`` listening, and a :class:`FakeEngine` (started) connecting to it."""
    calc.listen()
    fake = FakeEngine(calc.socketfile, **engine)
    fake.start()
    return fake


def many_atoms():
    """30000 atoms: 720 kB of positions, more than a Unix socket's buffer (about 200 kB
    on Linux), so a send to an engine that reads nothing cannot finish."""
    return Atoms("He30000", positions=np.random.default_rng(0).normal(size=(30000, 3)))


def test_a_send_to_an_engine_that_stopped_reading_ends_at_the_timeout():
    """The engine answers READY, then reads nothing: the positions were sent with a
    blocking ``sendall`` that waited in the kernel past ``timeout=3`` (28.5 s, until
    SIGINT).  Now the call ends at the timeout, naming what the engine did not take:
    measured 1.0 s for ``timeout=1``; bound 4 s (the engine here stays 20 s, and the
    old code waited for it to go)."""
    calc = IPICalculator(timeout=1)
    fails_within(calc, served(calc, stall=True), many_atoms(), 4,
                 r"^i-PI engine process \d+ .*: took no positions within 1 s \(it stopped "
                 r"reading\)$")
    assert not os.path.exists(calc.socketfile)


def fails_within(calc, fake, atoms, seconds, message):
    """A force call through ``calc`` to ``fake`` raises EngineError ``message`` within
    ``seconds`` and drops the engine; the fake engine is stopped either way."""
    atoms.calc = calc
    try:
        start = time.monotonic()
        with pytest.raises(EngineError, match=message):
            atoms.get_forces()
        assert time.monotonic() - start < seconds
        assert not calc.connected
    finally:
        calc.close()
        fake.stop()


class Stop(Exception):
    pass


def test_a_stop_check_ends_a_send_to_an_engine_that_stopped_reading():
    """The checks of ``add_wait_check`` (a run's stop signals) ran only while an answer
    was awaited: a stop during the send did nothing until the engine went.  Now they run
    while the send waits too: measured 0.51 s for a check that stops from 0.5 s on
    (within one wait slice, 0.1 s); bound 3 s, the timeout 30 s (the old code: 22 s,
    when the engine here went)."""
    calc = IPICalculator(timeout=30)
    fake = served(calc, stall=True)
    atoms = many_atoms()
    atoms.calc = calc
    start = time.monotonic()

    def check():
        if time.monotonic() - start > 0.5:
            raise Stop

    add_wait_check(check)
    try:
        with pytest.raises(Stop):
            atoms.get_forces()
        assert time.monotonic() - start < 3
        assert not calc.connected  # the exchange cannot be finished: the engine is dropped
    finally:
        remove_wait_check(check)
        calc.close()
        fake.stop()


def test_a_first_sigterm_of_a_run_ends_a_send_to_an_engine_that_stopped_reading():
    """Under ``rigidmd run`` a first SIGTERM or SIGINT only notes the signal; it was
    looked at in the waits for an answer alone, so during the send it did nothing.
    Measured 0.55 s for a SIGTERM at 0.5 s; bound 3 s, the timeout 30 s."""
    from helpers import stopped_by_sigterm

    calc = IPICalculator(timeout=30)
    fake = served(calc, stall=True)
    atoms = many_atoms()
    atoms.calc = calc
    try:
        assert stopped_by_sigterm(atoms.get_forces, 0.5) < 3
    finally:
        calc.close()
        fake.stop()


def copper():
    """A strained triclinic copper cell of 8 atoms (periodic)."""
    atoms = bulk("Cu", "fcc", a=3.6) * (2, 2, 1)
    atoms.cell = atoms.cell.array @ np.array([[1, 0.05, 0.02], [0, 1, 0.03], [0, 0, 1.02]])
    atoms.rattle(0.1, seed=1)
    return atoms


def test_an_all_zero_virial_is_no_stress():
    """ASE's ``SocketClient.run(atoms)`` sends a virial of nine zeros unless
    ``use_stress=True``: the stress came out exactly zero (in the report, for EMT
    copper of -0.065 -0.77 ... eV/Å^3 in process).  Now asking for it says so, naming
    the engine; energy and forces are still served, and no zero stress is kept for a
    later call."""
    calc = IPICalculator(timeout=20)
    fake = served(calc)  # a zero virial
    atoms = copper()
    atoms.calc = calc
    try:
        forces = atoms.get_forces()
        np.testing.assert_allclose(forces, -atoms.positions, rtol=1e-12, atol=1e-12)
        assert "stress" not in calc.results
        for _ in range(2):  # the same atoms asked again: asked of the engine again
            with pytest.raises(EngineError, match=r"^i-PI engine process \d+ .*: sent no "
                               r"virial \(all nine components exactly zero\), so no stress "
                               r".*use_stress=True\)\)$"):
                atoms.get_stress()
        assert calc.connected  # the engine answered the protocol: it is kept
        np.testing.assert_array_equal(atoms.get_forces(), forces)
    finally:
        calc.close()
        fake.stop()


def test_a_real_virial_is_the_stress_and_a_cluster_needs_none():
    """An engine that sends a virial gets its stress (W = -V sigma); a cluster, where no
    stress is asked, is served with a zero virial as before."""
    virial = np.array([[0.3, 0.01, 0.02], [0.01, -0.2, 0.03], [0.02, 0.03, 0.1]])  # Hartree
    calc = IPICalculator(timeout=20)
    fake = served(calc, virial=virial)
    atoms = copper()
    atoms.calc = calc
    try:
        expected = -virial * units.Ha / atoms.get_volume()
        np.testing.assert_allclose(atoms.get_stress(voigt=False), expected, rtol=1e-14,
                                   atol=0)
    finally:
        calc.close()
        fake.stop()
    calc = IPICalculator(timeout=20)
    fake = served(calc)
    cluster = Atoms("Ar2", positions=[[0, 0, 0], [0, 0, 3.0]])
    cluster.calc = calc
    try:
        np.testing.assert_allclose(cluster.get_forces(), -cluster.positions, rtol=1e-12,
                                   atol=1e-12)
    finally:
        calc.close()
        fake.stop()


ASE_CLIENT = """
import sys
from ase.calculators.emt import EMT
from ase.calculators.socketio import SocketClient
from ase.io import read
atoms = read(sys.argv[1])
atoms.calc = EMT()
SocketClient(unixsocket=sys.argv[2]).run(atoms, use_stress=sys.argv[3] == "1")
"""


@pytest.mark.parametrize("use_stress", [False, True])
def test_ases_socket_client_gives_the_stress_only_with_use_stress(tmp_path, use_stress):
    """ASE's own client, as the guide shows it (a subprocess): ``use_stress=False``, its
    default, is refused for the stress; ``use_stress=True`` gives EMT's in-process stress
    (measured 3e-16 eV/Å^3 apart, of -0.088 ... ; bound 1e-12)."""
    import subprocess
    import sys

    from ase.calculators.emt import EMT

    atoms = copper()
    reference = atoms.copy()
    reference.calc = EMT()
    atoms.write(tmp_path / "start.traj")
    calc = IPICalculator(timeout=60)
    calc.listen()
    client = subprocess.Popen([sys.executable, "-c", ASE_CLIENT, str(tmp_path / "start.traj"),
                               calc.unixsocket, "1" if use_stress else "0"])
    atoms.calc = calc
    try:
        if use_stress:
            np.testing.assert_allclose(atoms.get_stress(), reference.get_stress(), rtol=0,
                                       atol=1e-12)
        else:
            with pytest.raises(EngineError, match=r"sent no virial .*use_stress=True"):
                atoms.get_stress()
    finally:
        calc.close()
        try:
            client.wait(timeout=20)
        finally:
            if client.poll() is None:
                client.kill()
                client.wait()


@pytest.mark.parametrize("length", [-1, 1 << 28])
def test_a_broken_extra_length_is_named(length):
    """An ``extra`` length of -1 raised ``ValueError: negative count`` (no engine named);
    one of 2**28 made the calculator allocate 256 MB, then time out.  Both are a broken
    answer, named at once (measured 0.005 s; bound 1 s, the timeout 10 s)."""
    calc = IPICalculator(timeout=10)
    fails_within(calc, served(calc, extra_length=length),
                 Atoms("Ar2", positions=[[0, 0, 0], [0, 0, 3.0]]), 1,
                 rf"^i-PI engine process \d+ .*: sent an extra string of {length} bytes "
                 rf"\(expected 0 to 16777216\)")


def test_an_extra_string_is_kept():
    calc = IPICalculator(timeout=20)
    fake = served(calc, extra=b'{"neighbor_builds": 3}')
    atoms = Atoms("Ar2", positions=[[0, 0, 0], [0, 0, 3.0]])
    atoms.calc = calc
    try:
        atoms.get_forces()
        assert calc.engine_extra == b'{"neighbor_builds": 3}'
    finally:
        calc.close()
        fake.stop()
