"""The NPT density runs (``validation/npt_density.py``): fields, stop and resume, the report.

A run of the committed 64-water TIP4P/2005 start writes the density and its error; a run
stopped by SIGTERM writes what it has, says so, and ``--resume`` continues it to the same
series as an uninterrupted run (volume moves, their acceptance and the thermostat's
random numbers included); the report compares each step with the smallest.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import benchmark_module

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "validation" / "npt_density.py"
npt = benchmark_module("npt_density")


def _run(args):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    return subprocess.Popen([sys.executable, str(SCRIPT), "run", "--waters", "64", *args],
                            env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)


def _finish(proc, timeout=300):
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, out, err


COMMON = ["--dt-fs", "2", "--ps", "0.6", "--move-fs", "8", "--equil-ps", "0.1", "--save-s",
          "0"]
NAME = "npt_tip4p2005_64_baoab_dt2_s1"


@pytest.mark.lammps
def test_sigterm_writes_what_it_has_and_resume_continues_exactly(tmp_path):
    rc, _, err = _finish(_run([*COMMON, "--outdir", str(tmp_path / "whole")]))
    assert rc == 0, err
    whole = json.loads((tmp_path / "whole" / f"{NAME}.json").read_text())
    assert whole["complete"] and whole["steps"] == 300 and whole["move_every_steps"] == 4
    # 64 waters of liquid TIP4P/2005 near 1 g/cm³ (the start is 0.997); 0.6 ps of moves
    # wander by ~1 % (σ of the volume of 64 waters at 298 K: 3 %), so only the order.
    assert 0.9 < whole["density"][0] < 1.1 and whole["density"][1] > 0
    assert 0 < whole["acceptance"] < 1  # moves were tried, some taken, some refused
    cut = tmp_path / "cut"
    proc = _run([*COMMON, "--outdir", str(cut)])
    deadline = time.monotonic() + 200
    while not (cut / f"{NAME}.chk.npz").exists() and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    rc, out, err = _finish(proc)
    assert rc == 3, err
    assert "stopped by SIGTERM" in out and "--resume" in out
    stopped = json.loads((cut / f"{NAME}.json").read_text())
    assert not stopped["complete"] and 0 < stopped["steps"] < 300
    rc, _, err = _finish(_run([*COMMON, "--outdir", str(cut)]))  # no starting over
    assert rc != 0 and err.strip().count("\n") == 0 and "--resume" in err and NAME in err
    rc, _, err = _finish(_run([*COMMON, "--outdir", str(cut), "--resume"]))
    assert rc == 0, err
    resumed = json.loads((cut / f"{NAME}.json").read_text())
    assert resumed["complete"] and resumed["resumed_from_step"] == stopped["steps"]
    with np.load(tmp_path / "whole" / f"{NAME}.series.npz") as a, \
            np.load(cut / f"{NAME}.series.npz") as b:
        np.testing.assert_array_equal(a["t_ps"], b["t_ps"])  # no sample lost or repeated
        # The same trajectory to LAMMPS's roundoff (its fresh instance sums in another
        # order: 1e-13 relative in the time-step table's test); a move decided otherwise,
        # a restarted random stream or a lost step would differ by 1e-3 or more.
        for key in ("density", "U", "T_tr", "T_rot"):
            np.testing.assert_allclose(a[key], b[key], rtol=1e-10, err_msg=key)


def _result(path, dt, density, err, integrator="baoab", seed=1):
    point = {"waters": 216, "integrator": integrator, "dt_fs": dt, "seed": seed,
             "move_fs": 50.0, "equil_ps": 30.0}
    out = {"point": point, "ps": 400.0, "complete": True, "density": [density, err],
           "U": [-47.8, 0.02], "T_tr": [298.0, 0.1], "T_rot": [298.0, 0.1],
           "acceptance": 0.5, "ms_per_step": 7.0}
    path.write_text(json.dumps(out))
    return path


def test_the_report_compares_each_step_with_the_smallest(tmp_path):
    files = [_result(tmp_path / "a.json", 0.5, 0.9950, 0.0006),
             _result(tmp_path / "b.json", 4.0, 0.9900, 0.0008),
             _result(tmp_path / "c.json", 1.0, 0.9800, 0.0010, integrator="langevin")]
    text = npt.report(files, tmp_path / "out")
    rows = json.loads((tmp_path / "out.json").read_text())
    by = {(r["integrator"], r["dt_fs"]): r for r in rows}
    assert by[("baoab", 0.5)]["diff_pct"] == 0.0 and np.isnan(by[("baoab", 0.5)]["z"])
    # (0.9900 − 0.9950) / 0.9950 = −0.5025 %; σ = hypot(0.0006, 0.0008) = 0.001: Δ/σ = −5.0
    assert by[("baoab", 4.0)]["diff_pct"] == pytest.approx(-0.50251, abs=1e-4)
    assert by[("baoab", 4.0)]["z"] == pytest.approx(-5.0)
    assert by[("langevin", 1.0)]["diff_pct"] == 0.0  # its own smallest step, not BAOAB's
    assert "| baoab | 4 | 1 | 400 | 0.9900 ± 0.0008 | 0.081 | -0.503 | -5.0 |" in text
    assert npt.report([tmp_path / "out.runs.json"]) == text  # the bundle gives the same


def test_the_npt_page_shows_what_the_committed_runs_give():
    """Every row of the report on the committed runs is on the page (a page kept by hand
    from an older collection, or runs added without their rows, fails here)."""
    text = npt.report([ROOT / "validation" / "npt_density_216.runs.json"])
    rows = [line for line in text.splitlines() if line.startswith("| ") and
            not line.startswith("| integrator")]
    page = (ROOT / "docs" / "validation" / "timestep-216-npt.md").read_text()
    assert len(rows) >= 3
    missing = [row for row in rows if row not in page]
    assert not missing, f"rows the page lacks (run the report again): {missing}"
