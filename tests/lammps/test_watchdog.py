"""A command in its own process group, killed with it when our parent goes
(rigidmd.lammps._watchdog, run by path)."""

import os
import subprocess
import sys
import time

import rigidmd.lammps._watchdog as watchdog

SCRIPT = watchdog.__file__


def test_the_commands_exit_status_is_passed_on():
    proc = subprocess.Popen([sys.executable, SCRIPT, sys.executable, "-c",
                             "raise SystemExit(3)"], stdin=subprocess.PIPE)
    try:
        assert proc.wait(timeout=60) == 3  # stdin still open: the parent is there
    finally:
        proc.stdin.close()


def test_closing_stdin_kills_the_whole_group(tmp_path):
    """The command starts a grandchild that writes its pid; closing the watchdog's stdin (the
    parent gone) kills both within the watchdog's SIGTERM-then-SIGKILL second."""
    child = ("import subprocess, sys, time; "
             f"p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']); "
             f"open({str(tmp_path / 'pid')!r}, 'w').write(str(p.pid)); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, SCRIPT, sys.executable, "-c", child],
                            stdin=subprocess.PIPE)
    deadline = time.time() + 30
    while not (tmp_path / "pid").exists() or not (tmp_path / "pid").read_text():
        assert time.time() < deadline, "the command did not start"
        time.sleep(0.05)
    grandchild = int((tmp_path / "pid").read_text())
    proc.stdin.close()
    proc.wait(timeout=30)
    deadline = time.time() + 10
    while time.time() < deadline:
        try:
            os.kill(grandchild, 0)
        except ProcessLookupError:
            break
        # A zombie until its parent (killed too) is reaped by init: check its state.
        with open(f"/proc/{grandchild}/stat") as fh:
            if fh.read().split(") ")[1].startswith("Z"):
                break
        time.sleep(0.1)
    else:
        raise AssertionError(f"process {grandchild} of the group is still running")
