"""The NPT density runs (``validation/npt_density.py``): fields, stop and resume, the report.

A run of the committed 64-water TIP4P/2005 start writes the density and its error; a run
stopped by SIGTERM writes what it has, says so, and ``--resume`` continues it to the same
series as an uninterrupted run (volume moves, their acceptance and the thermostat's
random numbers included); the report compares each step with the smallest.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import benchmark_module, finish, sigterm_once_written

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "validation" / "npt_density.py"
npt = benchmark_module("npt_density")


def _run(args):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    return subprocess.Popen([sys.executable, str(SCRIPT), "run", "--waters", "64", *args],
                            env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)


COMMON = ["--dt-fs", "2", "--ps", "0.6", "--move-fs", "8", "--equil-ps", "0.1", "--save-s",
          "0"]
NAME = "npt_tip4p2005_64_baoab_dt2_s1"


@pytest.mark.lammps
def test_sigterm_writes_what_it_has_and_resume_continues_exactly(tmp_path):
    rc, _, err = finish(_run([*COMMON, "--outdir", str(tmp_path / "whole")]))
    assert rc == 0, err
    whole = json.loads((tmp_path / "whole" / f"{NAME}.json").read_text())
    assert whole["complete"] and whole["steps"] == 300 and whole["move_every_steps"] == 4
    # 64 waters of liquid TIP4P/2005 near 1 g/cm³ (the start is 0.997); 0.6 ps of moves
    # wander by ~1 % (σ of the volume of 64 waters at 298 K: 3 %), so only the order.
    assert 0.9 < whole["density"][0] < 1.1 and whole["density"][1] > 0
    assert 0 < whole["acceptance"] < 1  # moves were tried, some taken, some refused
    cut = tmp_path / "cut"
    rc, out, err = sigterm_once_written(_run([*COMMON, "--outdir", str(cut)]),
                                        cut / f"{NAME}.chk.npz")
    assert rc == 3, err
    assert "stopped by SIGTERM" in out and "--resume" in out
    stopped = json.loads((cut / f"{NAME}.json").read_text())
    assert not stopped["complete"] and 0 < stopped["steps"] < 300
    rc, _, err = finish(_run([*COMMON, "--outdir", str(cut)]))  # no starting over
    assert rc != 0 and err.strip().count("\n") == 0 and "--resume" in err and NAME in err
    rc, _, err = finish(_run([*COMMON, "--outdir", str(cut), "--resume"]))
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
    out = {"point": point, "molecules": 216, "ps": 400.0, "complete": True,
           "density": [density, err], "U": [-47.8, 0.02], "T_tr": [298.0, 0.1],
           "T_rot": [298.0, 0.1], "move_every_steps": round(50 / dt), "acceptance": 0.5,
           "ms_per_step": 7.0}
    path.write_text(json.dumps(out))
    return path


def test_the_report_combines_each_step_s_runs_and_judges_the_goal(tmp_path):
    files = [_result(tmp_path / "a.json", 0.5, 0.9950, 0.0008, seed=1),
             _result(tmp_path / "b.json", 0.5, 0.9970, 0.0008, seed=2),
             _result(tmp_path / "c.json", 4.0, 0.9900, 0.0008),
             _result(tmp_path / "d.json", 2.0, 0.9962, 0.0006),
             _result(tmp_path / "e.json", 1.0, 0.9800, 0.0010, integrator="langevin")]
    text = npt.report(files, tmp_path / "out")
    rows = json.loads((tmp_path / "out.json").read_text())
    by = {(r["integrator"], r["dt_fs"]): r for r in rows}
    # Equal errors: the mean, 0.9960, and the error 0.0008/√2 = 0.000566 (0.057 %).
    assert by[("baoab", 0.5)]["runs"] == 2 and by[("baoab", 0.5)]["ps"] == 800
    assert by[("baoab", 0.5)]["density"] == pytest.approx([0.9960, 0.0008 / np.sqrt(2)])
    assert by[("baoab", 0.5)]["goal"] == "—" and np.isnan(by[("baoab", 0.5)]["z"])
    # 4 fs: (0.9900 − 0.9960) / hypot(0.0008, 0.000566) = −6.1σ: excluded.
    assert by[("baoab", 4.0)]["z"] == pytest.approx(-0.006 / np.hypot(0.0008, 0.0008 / 2**0.5))
    assert by[("baoab", 4.0)]["diff_pct"] == pytest.approx(-0.60241, abs=1e-4)
    assert by[("baoab", 4.0)]["goal"] == "✗"
    # 2 fs: +0.2/0.83 σ, σ 0.060 % and 0.057 % ≤ 0.1 %: shown to meet the goal.
    assert by[("baoab", 2.0)]["goal"] == "✓"
    assert by[("langevin", 1.0)]["goal"] == "—"  # its own smallest step, not BAOAB's
    assert "| baoab | 4 | 1 | 400 | 0.9900 ± 0.0008 | 0.081 | -0.602 | -6.1 | ✗ |" in text
    assert "| baoab | 0.5 | 2 | 400 | 0.9970 ± 0.0008 | 0.080 | -47.800 ± 0.020 |" in text
    assert npt.report([tmp_path / "out.runs.json"]) == text  # the bundle gives the same
    # Errors above the goal's σ leave the verdict open, however close the means.
    loose = [_result(tmp_path / "f.json", 0.5, 0.9960, 0.0020),
             _result(tmp_path / "g.json", 4.0, 0.9961, 0.0020)]
    npt.report(loose, tmp_path / "loose")
    assert json.loads((tmp_path / "loose.json").read_text())[1]["goal"].startswith("?")
    # A run stopped before its equilibration ended has no density: listed, left out of the
    # combination (it made every combined value nan, and nan passed as "✓").
    young = _result(tmp_path / "h.json", 0.5, float("nan"), float("nan"), seed=3)
    text = npt.report([*files, young], tmp_path / "young")
    assert "| baoab | 0.5 | 3 | 400 | none yet: not past the first 30 ps |" in text
    by = {(r["integrator"], r["dt_fs"]): r for r in
          json.loads((tmp_path / "young.json").read_text())}
    assert by[("baoab", 0.5)]["runs"] == 2 and by[("baoab", 4.0)]["goal"] == "✗"
    alone = npt.report([young, _result(tmp_path / "i.json", 4.0, 0.99, 0.0005)],
                       tmp_path / "alone")
    assert "✓" not in alone  # no reference step: nothing is shown to meet the goal


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


@pytest.mark.parametrize("args, message", [
    (["--dt-fs", "0", "--ps", "1"], "--dt-fs: expected a positive number"),  # ZeroDivision
    (["--dt-fs", "2", "--ps", "0"], "--ps: expected a positive number"),  # a NaN "complete"
    (["--dt-fs", "2", "--ps", "1", "--equil-ps", "5"], "--equil-ps 5: leaves nothing"),
    (["--dt-fs", "2", "--ps", "1", "--blocks", "0"], "--blocks: expected a whole number"),
    (["--dt-fs", "2", "2", "--ps", "1", "--equil-ps", "0"], "--dt-fs: a value given twice"),
])
def test_npt_run_arguments_are_checked_first(tmp_path, args, message):
    """Each was a traceback, a failure after the whole run, or a run of NaN marked
    complete (an outside pass, 2026-11-29)."""
    proc = _run([*args, "--outdir", str(tmp_path / "out")])
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0 and message in err, err
    assert not (tmp_path / "out").exists()


def test_the_report_refuses_a_run_twice_or_runs_made_unalike(tmp_path):
    """The same JSON twice was two runs (σ down by √2); 64 and 216 waters, or other
    equilibrations, were combined under a header naming the first run's (an outside pass,
    2026-11-29)."""
    bundle = ROOT / "validation" / "npt_density_216.runs.json"
    runs = json.loads(bundle.read_text())
    with pytest.raises(SystemExit, match=r"is also in .*give each run once"):
        npt.report([bundle, bundle])
    smaller = dict(runs[0], name="other", molecules=64)  # (another size: another run)
    (tmp_path / "other.json").write_text(json.dumps(smaller))
    with pytest.raises(SystemExit, match=r"the runs differ in molecules \(216, 64\)"):
        npt.report([bundle, tmp_path / "other.json"])
    npt.report([bundle])  # the committed runs, alike


def test_a_point_running_or_killed_with_other_arguments_is_refused(tmp_path):
    """As the table's runs (timestep_table.py's claim and record): a second run of a point
    into one --outdir ran beside the first, and --resume of a run killed outright (a
    checkpoint, no JSON) with other arguments continued it without a word."""
    import fcntl

    out = tmp_path / "out"
    out.mkdir()
    claim = out / f"{NAME}.claim"
    claim.write_text("12345 elsewhere\n")
    with open(claim) as held:  # the point, running
        fcntl.flock(held, fcntl.LOCK_EX)
        rc, _, err = finish(_run([*COMMON, "--outdir", str(out)]))
    assert rc != 0 and f"{NAME}: being run already (process 12345 elsewhere" in err, err
    assert sorted(p.name for p in out.iterdir()) == [claim.name]
    claim.unlink()
    # what a run killed before its JSON leaves: its checkpoint and the record of its arguments
    (out / f"{NAME}.chk.npz").write_bytes(b"a checkpoint")
    point = {"waters": 64, "ps": 0.6, "equil_ps": 0.1, "move_fs": 8.0, "blocks": 10,
             "integrator": "baoab", "dt_fs": 2.0, "seed": 1}
    (out / f"{NAME}.arguments").write_text(json.dumps(point))
    rc, _, err = finish(_run([*COMMON[:4], "--move-fs", "50", "--equil-ps", "0.1",
                              "--outdir", str(out), "--resume"]))
    assert rc != 0 and f"{NAME}: --resume with --move-fs 50.0, but the run was made with " \
                       "8.0" in err, err
    assert "Traceback" not in err
