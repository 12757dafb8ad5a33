"""The i-PI socket: names, headers, waiting for an engine (rigidmd.ipi.connection).

Sockets an i-PI calculator listens on are tested in ``test_calculator.py``."""

import socket
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
