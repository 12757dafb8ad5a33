"""rigidmd.ipi.processes: the process tree and CPU time read from /proc."""

import os
import subprocess
import sys
import time

from rigidmd.ipi.processes import cpu_seconds, descendants, descends_from


def test_a_child_and_its_child_descend_from_this_process_and_use_cpu():
    """A child that starts a grandchild: both are this process's descendants, neither is its
    ancestor; the grandchild's spin shows as CPU time; a process gone (reaped) counts nothing."""
    code = ("import subprocess, sys; p = subprocess.Popen([sys.executable, '-c', "
            "'import time\\nt = time.process_time()\\nwhile time.process_time() - t < 5: pass']);"
            " print(p.pid, flush=True); p.wait()")
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        grandchild = int(child.stdout.readline())
        assert {child.pid, grandchild} <= set(descendants(os.getpid()))
        assert descendants(grandchild) == []
        assert descends_from(grandchild, os.getpid()) and descends_from(child.pid, child.pid)
        assert not descends_from(os.getpid(), child.pid)
        before = cpu_seconds([grandchild])
        time.sleep(0.3)
        assert cpu_seconds([grandchild]) > before
    finally:
        for pid in descendants(child.pid):
            os.kill(pid, 9)
        child.kill()
        child.wait()
    assert cpu_seconds([child.pid]) == 0.0 and not descends_from(child.pid, os.getpid())
