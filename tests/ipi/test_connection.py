"""The i-PI socket: names, headers, waiting for an engine (rigidmd.ipi.connection).

Sockets an i-PI calculator listens on are tested in ``test_calculator.py``."""

import os
import socket
import stat
import subprocess
import sys
import time

import pytest

from rigidmd.ipi import connection
from rigidmd.ipi.connection import (
    MSGLEN,
    add_wait_check,
    check_socket_name,
    remove_wait_check,
    socket_name_ok,
    wait_readable,
    word,
)


@pytest.mark.parametrize("name, ok", [
    ("rigidmd", True), ("run-1.a_b", True), ("a" * 80, True), ("a" * 81, False),
    (".hidden", False), ("../etc", False), ("a/b", False), ("", False), (3, False),
])
def test_socket_names(name, ok):
    assert socket_name_ok(name) is ok
    if ok:
        assert check_socket_name(name) == name
    else:
        with pytest.raises(ValueError, match="is not a plain name"):
            check_socket_name(name)
    assert check_socket_name(None) is None


def test_headers_are_twelve_ascii_bytes():
    assert word("STATUS") == b"STATUS      " and len(word("FORCEREADY")) == MSGLEN


def test_waiting_ends_on_data_a_deadline_a_dead_engine_or_a_check():
    a, b = socket.socketpair()
    try:
        assert wait_readable(a, time.monotonic() + 0.05, lambda: None) == "timeout"
        assert wait_readable(a, time.monotonic() + 5, lambda: "gone") == "died"
        b.sendall(word("READY"))
        assert wait_readable(a, time.monotonic() + 5, lambda: None) is None
        a.recv(MSGLEN)

        class Stop(Exception):
            pass

        def check():
            raise Stop

        add_wait_check(check)
        try:
            with pytest.raises(Stop):
                wait_readable(a, time.monotonic() + 5, lambda: None)
        finally:
            remove_wait_check(check)
        remove_wait_check(check)  # not there: no error
        assert check not in connection._wait_checks
    finally:
        a.close()
        b.close()


def test_waiting_on_a_descriptor_past_1024():
    """select() refused descriptors numbered 1024 or more ("filedescriptor out of range in
    select()"): a process with many files open could not use an engine at all."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 1100:
        pytest.skip(f"this machine allows {hard} open files; the test needs 1100")
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, 1100), hard))
    a, b = socket.socketpair()
    high = os.dup2(a.fileno(), 1050)
    try:
        far = socket.socket(fileno=high)
        b.sendall(word("READY"))
        assert wait_readable(far, time.monotonic() + 5, lambda: None) is None
        far.close()
    finally:
        a.close()
        b.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def _dead_pid():
    """A process id that no process has now (a child that has exited)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not os.path.exists(f"/proc/{child.pid}")
    return child.pid


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_sweep_removes_only_the_sockets_of_our_processes_that_are_gone(tmp_path):
    """A run killed outright leaves its socket file; the next calculator removes it, and
    nothing else: not a live process's, not one still listened on, not another file."""
    dead = _dead_pid()
    left = tmp_path / f"ipi_rigidmd-{dead}-0123abcd"
    live_pid = tmp_path / f"ipi_rigidmd-{os.getpid()}-0123abcd"
    served = tmp_path / f"ipi_rigidmd-{dead}-4567abcd"
    plain = tmp_path / f"ipi_rigidmd-{dead}-89abcdef"
    other = tmp_path / f"ipi_someone-{dead}-0123abcd"
    plain.write_text("not a socket")
    listening = None
    for path in (left, live_pid, served, other):
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.bind(str(path))
        if path == served:
            sock.listen(1)
            listening = sock
        else:
            sock.close()  # closed without removing its file: as after SIGKILL
    try:
        assert connection.sweep_stale_sockets(str(tmp_path)) == [str(left)]
    finally:
        listening.close()
    assert not left.exists()
    for kept in (live_pid, served, plain, other):
        assert os.path.lexists(kept), kept


def test_binding_privately_leaves_the_umask_alone(tmp_path, monkeypatch):
    """The socket file is 0600 whatever the umask, and the process's umask, shared by its
    threads, is never changed on the way (the old bind narrowed it around ``bind``)."""
    seen = []
    real_umask = os.umask

    def spy(mask):
        seen.append(mask)
        return real_umask(mask)

    old = real_umask(0o022)
    try:
        monkeypatch.setattr(os, "umask", spy)
        server, _ = connection.open_server(str(tmp_path / "s"), "localhost", None)
        server.close()
        monkeypatch.undo()
    finally:
        real_umask(old)
    assert seen == []
    assert stat.S_IMODE(os.stat(tmp_path / "s").st_mode) == 0o600
