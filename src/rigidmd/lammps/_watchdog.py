"""Run a command in its own process group and kill that group when our parent goes.

``python _watchdog.py COMMAND...`` (run by path: it imports nothing from
rigidmd).  The parent holds the write end of this process's stdin and never
writes to it; when the parent closes it or dies in any way (SIGKILL too), the
read below returns, and the whole process group of the command (``mpirun``,
its proxies and every ``lmp`` rank) is sent SIGTERM, then SIGKILL.  When the
command ends by itself, what is left of its group is killed too, and its exit
status is passed on.  SIGTERM, SIGHUP and SIGQUIT kill the group first; SIGINT (a Ctrl-C
sent to the terminal's foreground group) is left to the parent.
"""

import os
import signal
import subprocess
import sys
import threading
import time


def _kill_group(pgid):
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        time.sleep(0.5)


def main():
    proc = subprocess.Popen(sys.argv[1:], stdin=subprocess.DEVNULL, start_new_session=True)
    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):  # a hang-up, Ctrl-\
        signal.signal(sig, lambda signum, _: (_kill_group(proc.pid), os._exit(128 + signum)))
    # Ctrl-C reaches the terminal's whole foreground group, this process too: the parent
    # decides (it closes the engine, or dies and so closes this process's stdin).
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch():
        while os.read(0, 4096):
            pass
        _kill_group(proc.pid)

    threading.Thread(target=watch, daemon=True).start()
    code = proc.wait()
    _kill_group(proc.pid)
    sys.exit(code if code >= 0 else 128 - code)


if __name__ == "__main__":
    main()
