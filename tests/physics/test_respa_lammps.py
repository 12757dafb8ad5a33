"""r-RESPA with LAMMPS forces measured: the validation scripts' quick forms and results.

``validation/respa_kspace_share.py`` (native LAMMPS's k-space share and the r-RESPA bounds),
``respa_lammps_cost.py`` (ns/day of two-level splits, in this process or through engines),
``respa_lammps_nve.py`` (their NVE energy conservation against the outer step),
``respa_lammps_native.py`` (LAMMPS's own r-RESPA split, timed natively) and the time-step
table's split points.
"""

import importlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.lammps

ROOT = Path(__file__).resolve().parents[2]


def validation_script(name):
    sys.path.insert(0, str(ROOT / "validation"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(ROOT / "validation"))


def test_the_kspace_share_scripts_quick_form():
    """Native LAMMPS at 216 waters, 9-5 Å, a few steps: each section read from LAMMPS's
    log, f growing as the cut-off shrinks (measured 0.21, 0.55, 0.76, 0.87 in the full run;
    0.22-0.88 quick), and the bounds as the formula gives them."""
    share = validation_script("respa_kspace_share")
    result = share.main(["--quick"])
    rows = {row["cutoff"]: row for row in result["rows"]}
    assert sorted(rows) == [5.0, 6.0, 7.0, 9.0]
    f = [rows[rc]["f"] for rc in (9.0, 7.0, 6.0, 5.0)]
    assert 0.1 < f[0] < 0.4 and np.all(np.diff(f) > 0), f
    for row in rows.values():
        assert sum(row["shares"].values()) == pytest.approx(1.0)
        assert row["bound_same_rc"]["4"] == pytest.approx(1 / (1 - 0.75 * row["f"]))
    assert [s["r_split"] for s in result["split"]] == [7.0, 6.0, 5.0]


def test_the_cost_scripts_quick_form_counts_k_fast_calls_and_one_full_call():
    """Each outer step calls the fast level k times and the full model once.  The timed
    run's start (after the warm-up run) calls nothing more when the calculator still holds
    the forces: the single step's, and under the split each level's (MultipleTimeStep
    holds no results of its own, its levels do; a start asked both again before)."""
    cost = validation_script("respa_lammps_cost")
    result = cost.main(["--quick"])
    assert len(result["best"]) == 2 + 4 * 6
    for run in result["best"]:
        ps = run["steps"] * run["dt_fs"] / 1000
        calls = {name: round(rate * ps) for name, rate in run["calls_per_ps"].items()}
        k = run["k"] or 0
        assert calls == {"fast": k * run["steps"], "full": run["steps"]}, run
        assert run["ns_per_day_cpu"] > 0


def test_the_committed_results_are_there():
    for name in ("respa_kspace_share", "respa_lammps_cost", "respa_lammps_cost_skin3",
                 "respa_lammps_nve", "respa_lammps_nve_4lj", "respa_lammps_cost_engine2",
                 "respa_lammps_native", "respa_lammps_native_skin3"):
        for suffix in (".json", ".txt"):
            assert (ROOT / "validation" / f"{name}{suffix}").stat().st_size > 500


def test_the_timestep_tables_runs_take_a_split(tmp_path):
    """``timestep_table.py run --substeps 4 --r-split 5``: a point of its own (its name and
    JSON say the split), run to the end with the split's outer step."""
    subprocess.run([sys.executable, str(ROOT / "validation" / "timestep_table.py"), "run",
                    "--code", "rigidmd", "--integrator", "baoab", "--waters", "64",
                    "--dt-fs", "8", "--substeps", "4", "--r-split", "5", "--ps", "0.016",
                    "--sample-fs", "8", "--frame-fs", "16", "--blocks", "2",
                    "--outdir", str(tmp_path)], check=True, capture_output=True, timeout=600)
    run = json.loads((tmp_path / "tip4p2005_64_rigidmd_baoab_dt8_k4r5_s1.json").read_text())
    assert run["complete"] and run["steps"] == 2
    assert (run["point"]["substeps"], run["point"]["r_split"]) == (4, 5.0)


def test_the_nve_scripts_quick_form():
    """Two outer steps, k = 1 and 4, 24 fs: the split conserves better than the single step
    at each (measured quick: 0.042 and 0.007 meV/water at 2 fs, 0.197 and 0.026 at 4 fs; in
    the full run 4-5 times better at 2-6 fs), and k fast calls and one full call a step."""
    nve = validation_script("respa_lammps_nve")
    result = nve.main(["--quick"])
    points = {(p["dt_fs"], p["k"]): p for p in result["points"]}
    for dt in (2.0, 4.0):
        assert points[dt, 4]["std_meV_per_water"] < points[dt, 1]["std_meV_per_water"] / 2
        steps = points[dt, 4]["steps"]
        ps = steps * dt / 1000
        assert round(points[dt, 4]["fast_calls_per_ps"] * ps) == 4 * steps + 1
        assert round(points[dt, 4]["full_calls_per_ps"] * ps) == steps + 1


@pytest.mark.parametrize("args, message", [
    (["--sizes", "216", "5832"], "argument --sizes: 5832 waters has no step count"),
    (["--cutoffs", "9", "-2"], "argument --cutoffs: expected a positive number, got -2"),
    (["--cutoffs", "9", "12"], "argument --cutoffs: 12 Å is above 9 Å"),
    (["--cutoffs", "7"], "argument --cutoffs: 9 Å is the reference"),
    (["--cutoffs", "9", "7", "9"], "argument --cutoffs: a value given twice"),
    (["--sizes", "0"], "argument --sizes: expected a whole number >= 1"),
])
def test_the_kspace_share_scripts_cases_are_checked_before_any_is_measured(
        monkeypatch, capsys, tmp_path, args, message):
    """``--sizes 216 5832`` measured 216 and then failed (no STEPS entry: a KeyError);
    ``--cutoffs 9 -2`` measured 9 Å and then failed (LAMMPS's CalledProcessError): the
    measurements lost, in a traceback."""
    share = validation_script("respa_kspace_share")
    monkeypatch.setattr(share, "run_case", lambda *a, **k: pytest.fail("a case was measured"))
    with pytest.raises(SystemExit) as stop:
        share.main([*args, "--repeats", "1", "--out", str(tmp_path / "share")])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err.strip().splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


def test_the_kspace_share_scripts_report_refuses_another_scripts_json(tmp_path):
    """``--report`` on ``respa_lammps_cost.json`` (another script's): a KeyError's
    traceback; now one line naming the file, and no .txt written."""
    (tmp_path / "cost.json").write_text((ROOT / "validation" /
                                         "respa_lammps_cost.json").read_text())
    result = subprocess.run([sys.executable, str(ROOT / "validation" / "respa_kspace_share.py"),
                             "--report", "--out", str(tmp_path / "cost")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"--report: {tmp_path / 'cost.json'} is not a results file of respa_kspace_share.py "
        "(no lammps, rows, split)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cost.json"]
    # the committed results are one
    share = validation_script("respa_kspace_share")
    text = share.report(json.loads((ROOT / "validation" / "respa_kspace_share.json").read_text()))
    assert text.startswith("The k-space share f")


def test_the_cost_scripts_engine_form_counts_each_engines_calls():
    """``--engine 1``: every model a LAMMPSEngine (its own process), the goal's cases (the
    single step at 3 fs first), k fast calls and one full call a step, wall times."""
    cost = validation_script("respa_lammps_cost")
    result = cost.main(["--quick", "--engine", "1"])
    assert result["engine"] == 1
    assert [(r["fast"], r["dt_fs"], r["k"]) for r in result["best"]] == [
        (None if f is None else cost.fast_name(*f), dt, k) for f, dt, k in cost.ENGINE_CASES]
    for run in result["best"]:
        ps = run["steps"] * run["dt_fs"] / 1000
        calls = {name: round(rate * ps) for name, rate in run["calls_per_ps"].items()}
        assert calls == {"fast": (run["k"] or 0) * run["steps"], "full": run["steps"]}, run
        assert 0 < run["force_fraction_of_step"] < 1
    assert "vs single 3 fs (wall)" in cost.report(result)


def test_the_native_split_scripts_quick_form():
    """Every case ran as asked: LAMMPS's own log says which level computes what (the
    distance split: the inner pairs on level 1, the outer pairs and k-space on level 2;
    k-space alone: the whole pair on level 1), and the ratios are to the 3 fs step."""
    native = validation_script("respa_lammps_native")
    result = native.main(["--quick"])
    runs = {r["case"]: r for r in result["runs"]}
    assert list(runs) == list(native.CASES)
    for case, (levels, dt_fs, _k) in native.CASES.items():
        run = runs[case]
        assert run["steps"] == round(0.048 * 1000 / dt_fs)
        if levels is None:
            assert run["respa_levels"] is None
        elif levels.startswith("inner"):
            assert "pair-inner" in run["respa_levels"][0], run["respa_levels"]
            assert {"pair-outer", "kspace"} <= set(run["respa_levels"][1])
        else:
            assert "pair" in run["respa_levels"][0] and run["respa_levels"][1] == ["kspace"]
    rows = {r["case"]: r for r in result["rows"]}
    assert rows["single 3 fs"]["vs_single_3fs"] == 1.0
    assert all(r["ns_per_day"] > 0 for r in rows.values())


@pytest.mark.parametrize("args, message", [
    (["--sizes", "216", "5832"], "argument --sizes: 5832 waters is not among 216, 1728"),
    (["--ranks", "1", "1"], "argument --ranks: a value given twice"),
    (["--ranks", "0"], "argument --ranks: expected a whole number >= 1"),
    (["--ps", "-1"], "argument --ps: expected a positive number, got -1"),
])
def test_the_native_split_scripts_arguments_are_checked_first(monkeypatch, capsys, tmp_path,
                                                             args, message):
    native = validation_script("respa_lammps_native")
    monkeypatch.setattr(native, "run_case", lambda *a, **k: pytest.fail("a case was measured"))
    with pytest.raises(SystemExit) as stop:
        native.main([*args, "--out", str(tmp_path / "native")])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err.strip().splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


def test_the_native_split_script_stops_writes_and_resumes(tmp_path):
    """A Ctrl-C finishes the LAMMPS run under way (which runs in a session of its own, so
    the terminal's signal reaches the script only), writes the runs so far marked
    incomplete, says how to continue and exits 130; a new run into that --out without
    --resume, or --resume with other arguments, is refused; --resume measures only the
    rest."""
    out = tmp_path / "native"
    script = str(ROOT / "validation" / "respa_lammps_native.py")
    args = [sys.executable, script, "--sizes", "216", "--ranks", "1", "--repeats", "2",
            "--ps", "0.03", "--out", str(out)]
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    first = proc.stdout.readline()
    assert first.startswith("[1/16] repeat 0, 216 waters, 1 rank(s), single 2 fs:"), first
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert "continue with the same arguments and --resume" in err.strip().splitlines()[-1]
    stopped = json.loads(out.with_suffix(".json").read_text())
    assert not stopped["complete"] and 1 <= len(stopped["runs"]) < 16
    assert "INCOMPLETE" in out.with_suffix(".txt").read_text()
    again = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "continue it with --resume" in again.stderr
    other = subprocess.run([*args[:-2], "--skin", "3", "--out", str(out), "--resume"],
                           env=env, capture_output=True, text=True, timeout=300)
    assert other.returncode == 2 and "--resume:" in other.stderr and "was measured with" \
        in other.stderr
    t0 = time.monotonic()
    done = subprocess.run([*args, "--resume"], env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("[")]
    assert len(lines) == 16 - len(stopped["runs"]) and lines[-1].startswith("[16/16]")
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["complete"] and len(result["runs"]) == 16
    assert result["runs"][:len(stopped["runs"])] == stopped["runs"]
    assert time.monotonic() - t0 < 300
    assert sorted(p.name for p in tmp_path.iterdir()) == ["native.json", "native.txt"]
