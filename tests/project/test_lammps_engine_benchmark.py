"""``benchmarks/lammps_engine.py`` compares like with like: rigidmd's timed steps are steps 1
to N from the start, as native LAMMPS's loop, and native's step leaves out its output.

At 1728 waters one neighbour-list build costs two to three steps, and from the benchmark's
thermal start LAMMPS re-neighbours at steps 22 and 39: a rigidmd window of steps 4 to 23
(three set-up steps, then 20 timed) held one build more than native's steps 1 to 20, and
read 1.12-1.13x native where the aligned windows read 0.98-1.03x.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import PPPM_27, benchmark_module, water_box_27

from rigidmd.lammps import LAMMPSCalculator

pytestmark = pytest.mark.lammps


class CountingCalculator(LAMMPSCalculator):
    """The in-process calculator, keeping the positions of every call."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls = []

    def calculate(self, atoms=None, properties=("energy",), system_changes=()):
        self.calls.append(atoms.positions.copy())
        super().calculate(atoms, properties, system_changes)


@pytest.mark.parametrize("kind", ["nve", "mtk"])
def test_the_timed_steps_are_steps_one_to_n_from_the_start(kind, monkeypatch):
    bench = benchmark_module("lammps_engine")
    calcs = []

    def counting(commands, **options):  # the benchmark's commands, cut off for 27 waters
        calcs.append(CountingCalculator(PPPM_27, **options))
        return calcs[-1]

    monkeypatch.setattr(bench, "LAMMPSCalculator", counting)
    start = water_box_27(temperature_K=298)
    steps = 4
    bench.calc_run(start, kind, steps)
    calls = calcs[0].calls
    # the last call is at the positions of `steps` steps from the start
    reference = start.copy()
    reference.calc = LAMMPSCalculator(PPPM_27)
    bench.dynamics(reference, kind).run(steps)
    np.testing.assert_allclose(calls[-1], reference.positions, rtol=0, atol=1e-12)
    # one calculator call per timed step after the start's (computed before the timing;
    # the start as the dynamics places it: to roundoff; a step moves atoms by ~1e-3 A)
    at_start = [k for k, x in enumerate(calls)
                if np.allclose(x, start.positions, rtol=0, atol=1e-9)]
    assert len(calls) - 1 - at_start[-1] == steps


LOG = """\
Loop time of 0.8 on 1 procs for 40 steps with 5184 atoms

Performance: 4.320 ns/day, 5.556 hours/ns, 50.000 timesteps/s, 0.259 Matom-step/s
99.5% CPU use with 1 MPI tasks x 1 OpenMP threads

MPI task timing breakdown:
Section |  min time  |  avg time  |  max time  |%varavg| %total
---------------------------------------------------------------
Pair    | 0.4        | 0.4        | 0.4        |   0.0 | 50.00
Bond    | 0          | 0          | 0          |   0.0 |  0.00
Kspace  | 0.16       | 0.16       | 0.16       |   0.0 | 20.00
Neigh   | 0.08       | 0.08       | 0.08       |   0.0 | 10.00
Comm    | 0.004      | 0.004      | 0.004      |   0.0 |  0.50
Output  | 0.04       | 0.04       | 0.04       |   0.0 |  5.00
Modify  | 0.02       | 0.02       | 0.02       |   0.0 |  2.50
Other   |            | 0.096      |            |       | 12.00
"""


def test_the_native_step_leaves_out_its_output():
    bench = benchmark_module("lammps_engine")
    wall, cpu, floor = bench.log_timing(LOG, 40)
    assert wall == pytest.approx((0.8 - 0.04) / 40, rel=1e-12)
    assert cpu == pytest.approx(0.995 * (0.8 - 0.04) / 40, rel=1e-12)
    assert floor == pytest.approx((0.4 + 0.16 + 0.08) / 40, rel=1e-12)


CHILD = """\
import os, sys, tempfile
sys.path.insert(0, {tests!r})
from helpers import benchmark_module
bench = benchmark_module("lammps_engine")
getattr(bench, "stop_on_signals", lambda: None)()
bench.lammps_executable = lambda: ({lmp!r}, dict(os.environ))
bench.export_lammps = lambda *args, **kwargs: None
tempfile.tempdir = {tmp!r}
bench.native_parallel(bench.water_box(1), 4, processes={processes})
"""


@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_a_native_run_ends_with_the_benchmark(tmp_path, how):
    """The native ``[mpirun] lmp`` of the two-core and scaling tables was started with a
    plain ``subprocess.run``: SIGTERM (or SIGKILL, a hang-up) of the benchmark left it
    running on, and its temporary folder behind.  Now it runs under LAMMPSEngine's watchdog,
    and SIGTERM ends the benchmark through its ``with`` blocks.  (A stand-in ``lmp``.)"""
    lmp = tmp_path / "lmp"
    pid_file = tmp_path / "lmp.pid"
    lmp.write_text(f"#!/bin/sh\necho $$ > {pid_file}\nexec sleep 60\n")
    lmp.chmod(0o755)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    script = tmp_path / "bench.py"
    script.write_text(CHILD.format(tests=str(Path(__file__).resolve().parents[1]),
                                   lmp=str(lmp), tmp=str(tmp), processes=1))
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2] / "src"))
    stderr = tmp_path / "bench.err"  # (a file: an orphan would hold a pipe open)
    with open(stderr, "w") as err:
        bench = subprocess.Popen([sys.executable, str(script)], env=env, stderr=err)
    deadline = time.monotonic() + 120
    while not pid_file.exists() or not pid_file.read_text().strip():
        assert bench.poll() is None, stderr.read_text()
        assert time.monotonic() < deadline, "the native run did not start"
        time.sleep(0.05)
    native = int(pid_file.read_text())
    bench.send_signal(getattr(signal, how))
    bench.wait(timeout=60)
    deadline = time.monotonic() + 10  # measured: gone within a second
    try:
        while os.path.exists(f"/proc/{native}") and \
                open(f"/proc/{native}/stat").read().split(") ")[1][0] != "Z":
            assert time.monotonic() < deadline, "the native run outlived the benchmark"
            time.sleep(0.05)
    finally:
        try:
            os.kill(native, signal.SIGKILL)  # (what this test started, if left)
        except (ProcessLookupError, PermissionError):
            pass
    if how == "SIGTERM":
        assert bench.returncode != 0
        last = stderr.read_text().strip().splitlines()[-1]
        assert last.startswith("lammps_engine.py: stopped by SIGTERM"), last
        assert list(tmp.iterdir()) == []  # the run's temporary folder removed


@pytest.mark.parametrize("args, message", [
    (["--waters", "27", "--tables", "one-core"], "argument --waters: the one-core table has "
                                                 "step counts for 216, 1728, 13824 waters, "
                                                 "not 27"),
    (["--waters", "0", "--tables", "scaling"], "--waters: 0 is not 27 r^3"),
    (["--rounds", "0"], "argument --rounds: must be at least 1, got 0"),
    (["--tables", "scaling", "--json", "nodir/x.json"], "argument --json: no folder nodir"),
])
def test_the_benchmarks_arguments_are_checked_before_any_run(tmp_path, args, message):
    """``--waters 27`` passed the 27 r^3 check and failed with a KeyError after set-up,
    ``--waters 0 --rounds 0`` printed an empty table, a --json in a missing folder failed
    after the first measured run."""
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "lammps_engine.py"
    done = subprocess.run([sys.executable, str(script), *args], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
    assert message in done.stderr.strip().splitlines()[-1]
    assert list(tmp_path.iterdir()) == []
