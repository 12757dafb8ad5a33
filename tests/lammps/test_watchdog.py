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


def gone(pid, within=10.0):
    """Whether ``pid`` has ended (or is a zombie) within ``within`` seconds."""
    deadline = time.time() + within
    while time.time() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().split(") ")[1].startswith("Z"):
                    return True
        except FileNotFoundError:
            return True
        time.sleep(0.05)
    return False


def test_a_hang_up_kills_the_group_and_ctrl_c_is_left_to_the_parent(tmp_path):
    """The watchdog handled SIGTERM only: a terminal's hang-up (SIGHUP) or Ctrl-C (SIGINT,
    sent to the whole foreground group, the watchdog too) ended it without a word to the
    engine, whose ranks then outlived everything when they were not reading their socket.
    Now SIGHUP (and SIGQUIT) kill the group first; SIGINT is ignored: the parent, which gets
    it too, decides, and the watchdog still kills the group when the parent goes."""
    import signal

    for sig in (signal.SIGHUP, signal.SIGINT):
        pid_file = tmp_path / f"pid{int(sig)}"
        command = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); " \
                  "time.sleep(60)"
        proc = subprocess.Popen([sys.executable, SCRIPT, sys.executable, "-c", command],
                                stdin=subprocess.PIPE)
        try:
            deadline = time.time() + 30
            while not pid_file.exists() or not pid_file.read_text():
                assert time.time() < deadline, "the command did not start"
                time.sleep(0.05)
            child = int(pid_file.read_text())
            time.sleep(0.2)  # the handlers are set right after the command starts
            proc.send_signal(sig)
            if sig == signal.SIGHUP:
                assert proc.wait(timeout=30) == 128 + sig and gone(child)
            else:
                assert not gone(proc.pid, within=1.0) and not gone(child, within=0.1)
                proc.stdin.close()  # the parent goes: the group goes
                proc.wait(timeout=30)
                assert gone(child)
        finally:
            if proc.poll() is None:
                proc.kill()
