"""Sockets an i-PI calculator listens on: plain names, files left alone, who may connect.

Found by an outside pass (a user's file deleted as a "stale socket" through a name with
``..``; a program of another user answering a run's forces over loopback).
"""

import os
import socket
import stat
from pathlib import Path

import pytest

from rigidmd.config import ConfigError, check_config
from rigidmd.ipi import EngineError, IPICalculator

BAD_NAMES = ["../home/x", "a/b", "..", ".hidden", "", "x" * 81, "a b", "x\0y", "ü"]


@pytest.mark.parametrize("name", BAD_NAMES)
def test_a_socket_name_is_a_plain_name(tmp_path, name):
    """``unix:../../home/u/thesis.tex`` named /tmp/ipi_../../home/u/thesis.tex, which was
    removed as a stale socket.  Refused in the configuration and in Python."""
    raw = {"structure": {"builtin": "water_cluster", "n_molecules": 2},
           "calculator": {"name": "ipi", "address": f"unix:{name}"}, "timestep": "1 fs",
           "steps": 1, "_base": str(tmp_path)}
    with pytest.raises(ConfigError) as err:
        check_config(raw)
    message = str(err.value)
    assert message.startswith("calculator.address: ") and "\n" not in message, message
    if name:
        with pytest.raises(ValueError, match="is not a plain name"):
            IPICalculator(unixsocket=name)


@pytest.mark.parametrize("kind", ["file", "symlink", "folder"])
def test_a_path_that_is_not_a_socket_is_never_removed(tmp_path, kind):
    """Whatever was at /tmp/ipi_NAME was unlinked as a "stale socket" (a file, or a link
    to a user's file).  Only a socket file of this user, served by no one, is replaced."""
    name = f"rigidmd-notasocket-{os.getpid()}-{kind}"
    path = Path(f"/tmp/ipi_{name}")
    precious = tmp_path / "thesis.tex"
    precious.write_text("years of work")
    if kind == "file":
        path.write_text("years of work")
    elif kind == "symlink":
        path.symlink_to(precious)
    else:
        path.mkdir()
    try:
        calc = IPICalculator(unixsocket=name, timeout=5)
        with pytest.raises(EngineError, match=f"{path} exists and is not a socket"):
            calc.listen()
        calc.close()
        assert os.path.lexists(path)
        if kind == "file":
            assert path.read_text() == "years of work"
        assert precious.read_text() == "years of work"
    finally:
        if path.is_dir() and not path.is_symlink():
            path.rmdir()
        elif os.path.lexists(path):
            path.unlink()


def test_a_unix_socket_is_private():
    """The socket file was made under the user's umask (0755: any local user could
    connect and answer the forces); now 0600."""
    old = os.umask(0o022)
    try:
        calc = IPICalculator(timeout=5)
        calc.listen()
        mode = stat.S_IMODE(os.stat(calc.socketfile).st_mode)
        calc.close()
    finally:
        os.umask(old)
    assert mode == 0o600, oct(mode)
    assert os.umask(old) == old  # the process's umask is put back


def test_a_stale_socket_of_this_user_is_still_replaced():
    name = f"rigidmd-stale-{os.getpid()}"
    path = f"/tmp/ipi_{name}"
    left = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    left.bind(path)
    left.close()  # the file stays, no one listens: stale
    calc = IPICalculator(unixsocket=name, timeout=5)
    calc.listen()
    calc.close()
    assert not os.path.exists(path)


ZERO_FORCE_CLIENT = """
import sys
from ase import Atoms
from ase.calculators.lj import LennardJones
from ase.calculators.socketio import SocketClient
atoms = Atoms("Ar2", positions=[[0, 0, 0], [0, 0, 3.0]])
atoms.calc = LennardJones(epsilon=0.0)  # zero forces, as the intruder reported
if len(sys.argv) > 2:  # become that user before the socket is made (its owner)
    import os
    os.setgid(int(sys.argv[2]))
    os.setuid(int(sys.argv[2]))
try:
    SocketClient(host="localhost", port=int(sys.argv[1])).run(atoms)
except Exception:
    pass
"""


def free_port():
    with socket.socket() as probe:
        probe.bind(("localhost", 0))
        return probe.getsockname()[1]


def intruder(port, user=None):
    """A process answering zero forces on localhost:``port`` (as ``user``, a uid)."""
    import subprocess
    import sys

    return subprocess.Popen(
        [sys.executable, "-c", ZERO_FORCE_CLIENT, str(port), *([] if user is None else
                                                              [str(user)])],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def argon():
    from ase import Atoms

    return Atoms("Ar2", positions=[[0, 0, 0], [0, 0, 3.0]])


def test_another_users_process_on_loopback_is_refused():
    """A program of another local user connected first to a run's localhost:PORT and
    supplied zero forces for 21 calls, exit 0.  Its owner is read from /proc/net/tcp and
    the connection refused: the run stops, naming it."""
    if os.getuid() != 0:
        pytest.skip("needs root to start a process as another user")
    if not os.path.exists("/proc/net/tcp"):
        pytest.skip("needs Linux's /proc/net/tcp")
    port = free_port()
    calc = IPICalculator(port=port, timeout=20)
    calc.listen()
    proc = intruder(port, user=65534)
    try:
        atoms = argon()
        atoms.calc = calc
        with pytest.raises(EngineError, match="of another user \\(uid 65534\\) connected"):
            atoms.get_forces()
    finally:
        calc.close()
        proc.kill()
        proc.wait(timeout=10)


def test_a_loopback_engine_is_named_by_its_process():
    """Over TCP the engine was only an address; now its process, as for a Unix socket,
    so that LAMMPSEngine's check that it started the engine (check_peer) applies."""
    if not os.path.exists("/proc/net/tcp"):
        pytest.skip("needs Linux's /proc/net/tcp")
    port = free_port()
    seen = []

    class Expecting(IPICalculator):
        def check_peer(self, pid):
            seen.append(pid)
            return None if pid == proc.pid else f"process {pid} is not {proc.pid}"

    calc = Expecting(port=port, timeout=20)
    calc.listen()
    proc = intruder(port)
    try:
        atoms = argon()
        atoms.calc = calc
        atoms.get_forces()
        assert seen == [proc.pid]
        assert f"process {proc.pid} (python" in calc.describe_engine()
    finally:
        calc.close()
        proc.kill()
        proc.wait(timeout=10)


def test_an_engine_from_a_host_not_among_the_peers_is_refused_and_the_wait_goes_on():
    """Over TCP any host that reaches the port could connect first and answer the forces
    (the i-PI protocol has no secret).  With ``peers``, a connection from another address
    is closed with a warning naming it; the run keeps waiting for its engine, and stops
    at ``connect_timeout`` naming the wait when none comes."""
    port = free_port()
    calc = IPICalculator(port=port, timeout=20, connect_timeout=4, peers=["192.0.2.7"])
    assert calc.peers == frozenset({"192.0.2.7"})
    calc.listen()
    proc = intruder(port)  # connects from 127.0.0.1
    try:
        atoms = argon()
        atoms.calc = calc
        with pytest.warns(RuntimeWarning, match=r"refused a connection from 127\.0\.0\.1:\d+, "
                          r"not among the peers \(192\.0\.2\.7\); still waiting"), \
                pytest.raises(EngineError, match="no connection within 4 s"):
            atoms.get_forces()
        assert proc.wait(timeout=10) == 0  # it was disconnected, its forces never asked
    finally:
        calc.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


def test_an_engine_from_a_peer_is_served():
    port = free_port()
    calc = IPICalculator(port=port, timeout=20, peers=["localhost"])
    assert "127.0.0.1" in calc.peers  # names are resolved when the calculator is made
    calc.listen()
    proc = intruder(port)
    try:
        atoms = argon()
        atoms.calc = calc
        assert abs(atoms.get_forces()).max() == 0  # its zero forces, as asked
    finally:
        calc.close()
        proc.kill()
        proc.wait(timeout=10)


@pytest.mark.parametrize("kwargs, message", [
    ({"unixsocket": "rigidmd-peers-test", "peers": ["localhost"]}, "peers are for TCP"),
    ({"port": 31999, "peers": ["localhost", ""]}, "peers: '' is not a host name"),
    ({"port": 31999, "peers": [7]}, "peers: 7 is not a host name"),
    ({"port": 31999, "peers": []}, "peers: empty"),
])
def test_peers_are_checked_when_the_calculator_is_made(kwargs, message):
    with pytest.raises(ValueError, match=message):
        IPICalculator(timeout=20, **kwargs)


def test_peers_may_be_named_in_a_configuration_without_trust(tmp_path):
    """Peers only narrow who may answer: allowed without ``--trust``, and a run may add or
    change them when it is continued (not part of what the trajectory is)."""
    from rigidmd.run.fingerprint import fingerprint

    def raw(**options):
        return {"structure": {"builtin": "water_cluster", "n_molecules": 2},
                "calculator": {"name": "ipi", "address": "localhost:31998",
                               "options": options}, "timestep": "1 fs", "steps": 1,
                "_base": str(tmp_path)}

    with_peers = check_config(raw(peers=["localhost"]))
    assert with_peers.calculator.options["peers"] == ["localhost"]
    assert fingerprint(with_peers) == fingerprint(check_config(raw()))
    # The same for each level of a split (a level is fingerprinted as one calculator is).
    engine = {"name": "ipi", "address": "localhost:31997"}

    def split(**options):
        return dict(raw(), calculator={"fast": {"name": "tip3p"}, "substeps": 2, "slow": dict(
            engine, options=options)})

    assert fingerprint(check_config(split(peers=["localhost"]))) == \
        fingerprint(check_config(split()))
    assert fingerprint(check_config(split(peers=["localhost"]))) != \
        fingerprint(check_config(dict(split(), calculator=dict(split()["calculator"],
                                                                substeps=3))))
    with pytest.raises(ConfigError, match="calculator.options.peers"):
        check_config(raw(peers="localhost"))  # a list, as the reference says
