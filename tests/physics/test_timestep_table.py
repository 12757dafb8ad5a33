"""The time-step table's machinery (``validation/timestep_table.py`` and its collector).

A run of a few steps of the committed 64-water TIP4P/2005 start writes every field; a run
stopped by SIGTERM writes what it has, says so, and ``--resume`` continues it to the same
series as an uninterrupted run (to LAMMPS's roundoff); the collector's dt → 0 fit
recovers a known limit from synthetic points and tells integrators that disagree.
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
from helpers import benchmark_module, finish, sigterm_once_written

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "validation" / "timestep_table.py"
# A resumed run's configurational sums against the uninterrupted run's: measured 1.2e-13
# relative in one run and 4.1e-9 in another (one rotational Laplacian: its central second
# difference over eps_rotation² = 2.5e-5 rad² amplifies the 1e-13 roundoff by which the
# fresh LAMMPS instance's trajectory parts, as for U); 1e-6 bounds that with room, while a
# restarted random stream parts them by the Hutchinson noise, 18 % measured.
TOL_CONF = 1e-6
table = benchmark_module("timestep_table")
collector = benchmark_module("timestep_table_report")


def _run(args, **kwargs):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    return subprocess.Popen([sys.executable, str(SCRIPT), "run", "--waters", "64",
                             "--model", "tip4p2005", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


@pytest.mark.lammps
def test_a_run_writes_every_field(tmp_path):
    rc, out, err = finish(_run(["--integrator", "baoab", "--dt-fs", "2", "--ps", "0.02",
                                 "--sample-fs", "4", "--frame-fs", "8", "--outdir",
                                 str(tmp_path)]))
    assert rc == 0, err
    result = json.loads((tmp_path / "tip4p2005_64_rigidmd_baoab_dt2_s1.json").read_text())
    assert result["complete"] and result["steps"] == 10 and result["stopped_by"] is None
    for field in table.RESULT_FIELDS:
        assert field in result
    # T_conf from the run's own observer, at frames 0 and 2 of 0, 8, 16 fs (every second
    # frame, the default): two samples of 64 waters scatter by ~10 K (measured: 273 ± 11 K
    # and 271 ± 10 K in a 0.4 ps run), so only its presence and its order are checked here;
    # its correctness is tests/core/test_configurational.py's.
    assert 150 < result["T_conf_tr"][0] < 450 and 150 < result["T_conf_rot"][0] < 450
    # ⟨U⟩/N without LAMMPS's intramolecular k-space constant: liquid TIP4P/2005 is near
    # -48 kJ/mol (-48.3 measured on this start at 2 fs).
    assert -55 < result["U"][0] < -40
    assert 200 < result["T_tr"][0] < 400 and 200 < result["T_rot_end"][0] < 400
    assert 2.6 < result["rdf_peak_r"][0] < 3.0  # the O–O first shell
    # The peak's errors from the blocks' peaks (three frames, three blocks): finite.
    assert result["rdf_peak_r"][1] >= 0 and np.isfinite(result["rdf_peak_g"][1])
    assert result["samples"] == 6 and result["frames"] == 3
    # Analysed again from its series with more of the start left out: t = 0.012, 0.016, 0.02.
    table.reanalyse([tmp_path / "tip4p2005_64_rigidmd_baoab_dt2_s1.json"], equil_ps=0.01)
    again = json.loads((tmp_path / "tip4p2005_64_rigidmd_baoab_dt2_s1.json").read_text())
    assert again["samples"] == 3 and again["point"]["equil_ps"] == 0.01
    assert again["steps"] == result["steps"] and again["U"] != result["U"]


@pytest.mark.lammps
@pytest.mark.parametrize("code, integrator", [("lammps", "nvt_small"), ("openmm", "middle")])
def test_the_other_codes_write_the_same_fields(tmp_path, code, integrator):
    if code == "openmm":
        pytest.importorskip("openmm", reason="needs OpenMM (pip install openmm)")
    rc, _, err = finish(_run(["--code", code, "--dt-fs", "2", "--ps", "0.02", "--sample-fs",
                               "4", "--frame-fs", "8", "--piece-ps", "0.01", "--outdir",
                               str(tmp_path)]))
    assert rc == 0, err
    result = json.loads((tmp_path / f"tip4p2005_64_{code}_{integrator}_dt2_s1.json")
                        .read_text())
    assert result["complete"] and result["steps"] == 10 and result["samples"] == 6
    for field in table.RESULT_FIELDS:
        assert field in result
    # Each code's energy on one scale: -48.35 (LAMMPS, its molecules' own Coulomb energy
    # off) and -48.34 kJ/mol (OpenMM) measured at 2 fs over 0.2 ps of this start.
    assert -55 < result["U"][0] < -40
    assert 200 < result["T_tr"][0] < 400 and 200 < result["T_rot"][0] < 400
    # T_conf from the frames' positions (frames 0 and 2, as rigidmd's above): present and
    # of the right order; test_frames_give_rigidmd_s_own_configurational_sums checks it.
    assert 150 < result["T_conf_tr"][0] < 450 and 150 < result["T_conf_rot"][0] < 450
    assert not list(tmp_path.glob("*.chk*.json"))  # the collector reads every *.json


@pytest.mark.lammps
def test_frames_give_rigidmd_s_own_configurational_sums():
    """Another code's frame, sampled from its positions alone (molecules broken across the
    box, OpenMM's M sites as they come), gives the sums rigidmd's own sampler gives at that
    state with the same probes: the two codes' T_conf are one estimator."""
    from ase import units
    from water_openmm_nve import lammps_calculator

    from rigidmd import RigidVerlet
    from rigidmd.core.configurational import ConfigurationalTemperature
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    state = table.load_start("tip4p2005", 64)
    p = {"seed": 3, "tconf_frames": 2, "tconf_probes": 2}
    atoms = table.make_atoms(state, model)
    calc = lammps_calculator(model, table.cutoff_for(state["cell"]))
    dyn = RigidVerlet(atoms, units.fs)
    dyn.nsteps = 700  # the step the frame is of: the probes are those of (2003, 700)
    own = ConfigurationalTemperature(dyn, probes=2, rng=2003, calculator=calc).sample()[:4]
    broken = state["positions"].copy()
    broken[1] += state["cell"][0]  # the first molecule's H one box away: the same state
    frames = table.frame_sampler(p, model, state)
    sums, other_step = frames(broken, 700), frames(broken, 701)
    frames.close()
    # The same forces and probes: equal to 2e-16 measured (the body fit's roundoff); 1e-9
    # leaves room for another BLAS, far below a sample's ~10 % noise.
    np.testing.assert_allclose(sums, own, rtol=1e-9)
    # Another step draws other probes: the Laplacians' estimates differ (by ~10 %).
    assert other_step[0] == pytest.approx(sums[0], rel=1e-12)  # the forces are the state's
    assert abs(other_step[3] / sums[3] - 1) > 1e-6
    assert frames.due(0) and not frames.due(1) and frames.due(4)
    assert table.frame_sampler(dict(p, tconf_frames=0), model, state) is None


@pytest.mark.lammps
def test_sigterm_writes_what_it_has_and_resume_continues_exactly(tmp_path):
    common = ["--integrator", "langevin", "--dt-fs", "2", "--ps", "0.6", "--sample-fs", "4",
              "--frame-fs", "8", "--save-s", "0"]
    rc, _, err = finish(_run([*common, "--outdir", str(tmp_path / "whole")]))
    assert rc == 0, err
    name = "tip4p2005_64_rigidmd_langevin_dt2_s1"
    cut = tmp_path / "cut"
    rc, out, err = sigterm_once_written(_run([*common, "--outdir", str(cut)]),
                                        cut / f"{name}.chk.npz")
    assert rc == 3, err
    assert "stopped by SIGTERM" in out and "--resume" in out
    stopped = json.loads((cut / f"{name}.json").read_text())
    assert not stopped["complete"] and stopped["stopped_by"] == "SIGTERM"
    assert 0 < stopped["steps"] < 300
    # Without --resume the run refuses to start over what is there, in one line.
    rc, _, err = finish(_run([*common, "--outdir", str(cut)]))
    assert rc != 0 and err.strip().count("\n") == 0 and "--resume" in err and name in err
    rc, _, err = finish(_run([*common, "--outdir", str(cut), "--resume"]))
    assert rc == 0, err
    resumed = json.loads((cut / f"{name}.json").read_text())
    assert resumed["complete"] and resumed["steps"] == 300
    assert resumed["resumed_from_step"] == stopped["steps"]  # from the checkpoint, not step 0
    assert resumed["T_rot_gap"] == [0.0, 0.0]  # RigidLangevin reports its end of step
    with np.load(tmp_path / "whole" / f"{name}.series.npz") as a, \
            np.load(cut / f"{name}.series.npz") as b:
        np.testing.assert_array_equal(a["t_ps"], b["t_ps"])  # no sample lost or repeated
        # The same trajectory to LAMMPS's roundoff: the resumed run's fresh LAMMPS instance
        # sums its pairs in another order (measured: 1.3e-13 relative at most over these
        # 300 steps); a restarted random stream or a lost step would differ at 1e-3.
        for key in ("U", "T_tr", "T_rot", "com"):
            np.testing.assert_allclose(a[key], b[key], rtol=1e-10, err_msg=key)
        # The configurational sums too: a sample's probes depend on its step alone, so the
        # resumed run draws those of the uninterrupted one (TOL_CONF, measured).
        assert np.isfinite(a["conf"]).all(axis=1).sum() >= 10
        np.testing.assert_allclose(a["conf"], b["conf"], rtol=TOL_CONF, err_msg="conf")


@pytest.mark.lammps
@pytest.mark.parametrize("code", ["lammps", "openmm"])
def test_the_other_codes_stop_and_resume(tmp_path, code):
    if code == "openmm":
        pytest.importorskip("openmm", reason="needs OpenMM (pip install openmm)")
    args = ["--code", code, "--dt-fs", "2", "--ps", "1.2", "--sample-fs", "4", "--frame-fs",
            "8", "--save-s", "0", "--piece-ps", "0.1", "--outdir", str(tmp_path)]
    name = f"tip4p2005_64_{code}_{'nvt_small' if code == 'lammps' else 'middle'}_dt2_s1"
    proc = _run(args)
    deadline = time.monotonic() + 200
    while not list(tmp_path.glob(f"{name}.chk.*.meta")) and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    rc, _, err = finish(proc)
    assert rc == 3, err
    stopped = json.loads((tmp_path / f"{name}.json").read_text())
    assert not stopped["complete"] and 0 < stopped["steps"] < 600
    # A kill between the checkpoint and its record left the record of the step before: the
    # resumed run skipped what lay between (0.4 ps) and relabelled the times.  LAMMPS's
    # checkpoint now carries its own record; OpenMM's step count is checked against it.
    meta = next(tmp_path.glob(f"{name}.chk.*.meta"))
    record = json.loads(meta.read_text())
    older = {"samples": 1, "frames": 1, "steps": 0}
    meta.write_text(json.dumps(older))
    if code == "openmm":
        rc, _, err = finish(_run([*args, "--resume"]))
        assert rc != 0 and f"holds step {record['steps']}, its record" in err, err
        meta.write_text(json.dumps(record))
    rc, _, err = finish(_run([*args, "--resume"]))
    assert rc == 0, err
    resumed = json.loads((tmp_path / f"{name}.json").read_text())
    assert resumed["complete"] and resumed["steps"] == 600
    assert resumed["resumed_from_step"] == stopped["steps"]
    with np.load(tmp_path / f"{name}.series.npz") as d:  # every sample once, in order
        np.testing.assert_allclose(d["t_ps"], np.arange(301) * 0.004, atol=1e-12)
        assert len(d["frame_t_ps"]) == 151


@pytest.mark.lammps
def test_a_signal_to_the_jobs_parent_stops_every_run_and_waits_for_them(tmp_path):
    proc = _run(["--integrator", "langevin", "--dt-fs", "2", "--ps", "2", "--seed", "1", "2",
                 "--sample-fs", "4", "--frame-fs", "8", "--save-s", "0", "--jobs", "2",
                 "--outdir", str(tmp_path)])
    names = [f"tip4p2005_64_rigidmd_langevin_dt2_s{seed}" for seed in (1, 2)]
    deadline = time.monotonic() + 200
    while not all((tmp_path / f"{n}.chk.npz").exists() for n in names) \
            and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    rc, out, err = finish(proc)
    assert rc == 3, err
    assert "2 of 2 runs incomplete (SIGTERM)" in out
    for n in names:  # each run finished its step and wrote what it had before the parent left
        result = json.loads((tmp_path / f"{n}.json").read_text())
        assert result["stopped_by"] == "SIGTERM" and not result["complete"]


def _synthetic(path, integrator, dt, seed, U, code="rigidmd", U_err=0.01):
    point = {"model": "tip4p2005", "waters": 216, "code": code, "integrator": integrator,
             "dt_fs": dt, "seed": seed}
    run = {"point": point, "complete": True, "ms_per_step": 3.0, "recorded_ps": 200.0,
           "U": [U, U_err], "T_tr": [298.0, 0.2], "T_rot": [298.0, 0.2],
           "T_tr_end": [298.0, 0.2], "T_rot_end": [298.0, 0.2], "rdf_peak_r": 2.76,
           "rdf_peak_g": 3.2 + 0.01 * dt ** 2, "D_pbc": [2.1, 0.05], "T_conf_tr": None,
           "T_conf_rot": None}
    file = path / f"{code}_{integrator}_{dt:g}_{seed}.json"
    file.write_text(json.dumps(run))
    return file


def test_collector_recovers_a_known_limit_and_flags_disagreement(tmp_path):
    files = []
    slopes = {"langevin": 0.06, "baoab": 0.002}
    for integrator, b in slopes.items():
        for dt in (0.5, 1.0, 2.0, 4.0):
            for seed, noise in ((1, 0.004), (2, -0.004)):  # seeds' mean on the line
                files.append(_synthetic(tmp_path, integrator, dt, seed,
                                        -47.0 + b * dt ** 2 + noise))
    points, fits = collector.report(files, tmp_path, "t")
    shared = fits[("tip4p2005", 216, "rigidmd", "U")]
    assert shared["shared"]["a"] == pytest.approx(-47.0, abs=1e-9)
    assert shared["shared"]["b"] == pytest.approx(slopes, abs=1e-9)
    assert shared["shared"]["points"] == 6  # 4 fs is outside the fit
    assert shared["agree"] is True
    assert fits[("tip4p2005", 216, "rigidmd", "rdf_peak_g")]["shared"]["a"] == \
        pytest.approx(3.2, abs=1e-9)
    langevin_1fs = next(p for p in points if p["integrator"] == "langevin"
                        and p["dt_fs"] == 1.0)
    assert langevin_1fs["runs"] == 2 and langevin_1fs["U"][0] == pytest.approx(-46.94)
    text = (tmp_path / "t.md").read_text()
    assert "| tip4p2005 | 216 | rigidmd | langevin | 4 | 2 |" in text and "+0.960" in text
    assert "—" in text  # runs without T_conf sums show a dash, never a number
    rows = [line for line in (tmp_path / "t.csv").read_text().splitlines()
            if not line.startswith("#")]
    assert len(rows) == 1 + 8 and "U_limit" in rows[0]
    # An integrator whose own limit is 0.5 kJ/mol off the others' is told.
    for dt in (0.5, 1.0, 2.0):
        for seed, noise in ((1, 0.004), (2, -0.004)):
            files.append(_synthetic(tmp_path, "bussi", dt, seed, -46.5 + noise))
    _, fits = collector.report(files, tmp_path, "t")
    assert fits[("tip4p2005", 216, "rigidmd", "U")]["agree"] is False
    assert "| NO |" in (tmp_path / "t.md").read_text()


def test_the_collector_leaves_out_stopped_runs(tmp_path):
    files = [_synthetic(tmp_path, "langevin", dt, 1, -47.0 + 0.05 * dt ** 2)
             for dt in (0.5, 1.0, 2.0)]
    stopped = json.loads(files[0].read_text())
    stopped.update(complete=False, U=[-40.0, 0.5], point=dict(stopped["point"], seed=2))
    files.append(tmp_path / "stopped.json")
    files[-1].write_text(json.dumps(stopped))
    points, fits = collector.report(files, tmp_path, "t")
    assert fits[("tip4p2005", 216, "rigidmd", "U")]["shared"]["a"] == pytest.approx(-47.0)
    assert next(p for p in points if p["dt_fs"] == 0.5)["runs"] == 1
    points, _ = collector.report(files, tmp_path, "t", include_incomplete=True)
    assert next(p for p in points if p["dt_fs"] == 0.5)["runs"] == 2


def test_other_codes_get_their_own_limit(tmp_path):
    files = [_synthetic(tmp_path, "middle", dt, seed, -46.0 + 0.01 * dt ** 2, code="openmm")
             for dt in (0.5, 1.0, 2.0) for seed in (1, 2)]
    files += [_synthetic(tmp_path, "langevin", dt, 1, -47.0 + 0.05 * dt ** 2)
              for dt in (0.5, 1.0, 2.0)]
    _, fits = collector.report(files, tmp_path, "t")
    assert fits[("tip4p2005", 216, "openmm", "U")]["shared"]["a"] == pytest.approx(-46.0)
    assert fits[("tip4p2005", 216, "rigidmd", "U")]["shared"]["a"] == pytest.approx(-47.0)


def test_no_agreement_is_claimed_where_no_limit_could_be_fitted(tmp_path):
    files = [_synthetic(tmp_path, integrator, 1.0, 1, -47.0)
             for integrator in ("langevin", "baoab")]  # one step each: no limit
    _, fits = collector.report(files, tmp_path, "t")
    assert fits[("tip4p2005", 216, "rigidmd", "U")]["agree"] is None
    assert "| yes |" not in (tmp_path / "t.md").read_text()


@pytest.mark.parametrize("dev, err, verdict", [
    (0.02, 0.01, "meets"), (0.04, 0.01, "unresolved"), (0.08, 0.01, "fails"),
    (-0.08, 0.01, "fails"), (0.0, 0.03, "unresolved"), (0.01, float("nan"), "unresolved"),
    (0.2, float("nan"), "unresolved"),
])
def test_a_goal_is_met_only_when_its_errors_show_it(dev, err, verdict):
    assert collector.verdict(dev, err, 0.05) == verdict


def test_the_largest_accurate_step_stops_at_the_first_that_fails(tmp_path):
    """One run a step: 3 fs fails ⟨U⟩ (+0.2 ± 0.01 kJ/mol), 4 fs has too large an error to
    fail anything (± 1): the largest step no goal fails is 2 fs, not 4 (before, the larger
    step was taken, so a code whose 4 fs was excluded could be timed at 5 fs)."""
    files = [_synthetic(tmp_path, "baoab", dt, 1, -47.0) for dt in (0.5, 1.0, 2.0)]
    files.append(_synthetic(tmp_path, "baoab", 3.0, 1, -46.8))
    files.append(_synthetic(tmp_path, "baoab", 4.0, 1, -47.0, U_err=1.0))
    points, fit_table = collector.report(files, tmp_path, "s")
    rows, best = collector.assess(points, fit_table)
    verdicts = {r["dt_fs"]: {c["verdict"] for c in r["checks"].values()} for r in rows}
    assert "fails" in verdicts[3.0] and "fails" not in verdicts[4.0]
    baoab = best[("tip4p2005", 216, "rigidmd", "baoab")]
    assert baoab["not_excluded_fs"] == 2.0 and baoab["first_failing_fs"] == 3.0


def test_the_runs_that_would_decide_a_goal():
    """T_conf,rot +2.8 ± 0.8 K from 6 runs against 2 K: the error must fall to 0.4 and
    below (a failure is strict: |dev| − 2e > tol), e = 0.8·√(6/m) → 25 runs, checked by
    judging the deviation at that error.  A point whose limit alone is too uncertain, or
    whose deviation sits on the tolerance, gets None."""
    m = collector.runs_to_decide(2.8, 0.8, 0.8, 6, 2.0)
    assert m == 25
    assert collector.verdict(2.8, 0.8 * np.sqrt(6 / m), 2.0) == "fails"
    assert collector.verdict(2.8, 0.8 * np.sqrt(6 / (m - 1)), 2.0) == "unresolved"
    # ⟨U⟩ 0.0 ± 0.03 against 0.05 with the limit's ± 0.01 in it: 2·hypot(e_p, 0.01) ≤ 0.05
    # → e_p ≤ 0.0229 from 0.0283 with 3 runs: 4.6, so 5 runs.
    e_p = np.sqrt(0.03**2 - 0.01**2)
    m = collector.runs_to_decide(0.0, 0.03, e_p, 3, 0.05)
    assert m == 5
    assert collector.verdict(0.0, np.hypot(e_p * np.sqrt(3 / m), 0.01), 0.05) == "meets"
    assert collector.verdict(0.0, np.hypot(e_p * np.sqrt(3 / (m - 1)), 0.01), 0.05) == \
        "unresolved"
    # BAOAB's 4 fs ⟨U⟩, +0.008 ± 0.048 with the shared limit's ± 0.028: 2·0.028 > 0.042,
    # so no number of runs at 4 fs decides it; the limit needs them.
    assert collector.runs_to_decide(0.008, 0.048, np.sqrt(0.048**2 - 0.028**2), 6,
                                    0.05) is None
    assert collector.runs_to_decide(0.05, 0.01, 0.01, 3, 0.05) is None  # on the tolerance
    assert collector.runs_to_decide(0.0, float("nan"), float("nan"), 1, 0.05) is None
    assert collector.runs_to_decide(0.049, 0.0001, 0.0001, 3, 0.05) == 4  # at least one more


def test_a_pooled_error_is_never_below_what_the_runs_own_errors_give():
    """Three runs that agree by chance (scatter 0.01, each ± 0.07) keep the error their own
    errors give the mean (0.07·√3/3 = 0.040), not the scatter's 0.006; runs that scatter
    more than their errors say keep the scatter's; one run keeps its own error."""
    def runs(values, err):
        return [{"U": [v, err]} for v in values]

    mean, err = collector.pool(runs([-47.68, -47.69, -47.67], 0.07), "U")
    assert mean == pytest.approx(-47.68) and err == pytest.approx(0.07 / np.sqrt(3))
    mean, err = collector.pool(runs([-47.5, -47.7, -47.9], 0.01), "U")
    assert err == pytest.approx(0.2 / np.sqrt(3))  # s = 0.2
    assert collector.pool(runs([-47.6], 0.03), "U") == [-47.6, 0.03]
    # A run without an error of its own (one run's RDF peak): the scatter alone.
    assert collector.pool([{"g": 3.2}, {"g": 3.4}], "g")[1] == pytest.approx(0.1)


def test_goals_and_the_largest_steps_from_the_limit(tmp_path):
    """Synthetic rigidmd points on U = -47 + b·dt² (b = 0.004 kJ/mol/fs²: 0.064 at 4 fs, over
    the 0.05 goal); RDF peak 3.2 + 0.01·dt² (0.5 % at 4 fs); T 298 K: the largest step no
    goal fails is 2 fs, and no step shows every goal (T_conf is not measured).  LAMMPS at
    2 and 4 fs only takes rigidmd's limits of the static quantities when told (the same
    forces), never D_PBC's (another thermostat), and says so."""
    files = []
    for dt in (0.5, 1.0, 2.0, 4.0):  # each run's own error 0.002: the mean's is too
        for seed, noise in ((1, 0.002), (2, -0.002)):
            files.append(_synthetic(tmp_path, "baoab", dt, seed, -47.0 + 0.004 * dt ** 2
                                    + noise, U_err=0.002))
    for dt in (2.0, 4.0):
        files.append(_synthetic(tmp_path, "nvt_small", dt, 1, -47.0 + 0.03 * dt ** 2,
                                code="lammps"))
    for seed, noise in ((1, 0.002), (2, -0.002)):  # 6 fs: judged at twice the tolerances
        files.append(_synthetic(tmp_path, "baoab", 6.0, seed, -47.0 + 0.07 + noise,
                                U_err=0.002))
    split = _synthetic(tmp_path, "baoab", 8.0, 1, -47.0 + 0.07)  # an r-RESPA split at 8 fs
    run = json.loads(split.read_text())
    run["point"].update(substeps=4, r_split=5.0)
    split.write_text(json.dumps(run))
    files.append(split)
    points, fit_table = collector.report(files, tmp_path, "g")
    assert not np.isfinite(fit_table[("tip4p2005", 216, "lammps", "U")]["shared"]["a"])
    rows, best = collector.assess(points, fit_table)
    at = {(r["code"], r["dt_fs"]): r["checks"] for r in rows}
    assert at[("rigidmd", 4.0)]["U"]["dev"] == pytest.approx(0.064, abs=1e-6)
    assert at[("rigidmd", 4.0)]["U"]["verdict"] == "fails"
    assert at[("rigidmd", 4.0)]["rdf_peak_g"]["dev"] == pytest.approx(0.16 / 3.2, rel=1e-6)
    assert at[("rigidmd", 1.0)]["U"]["verdict"] == "meets"
    assert at[("rigidmd", 6.0)]["U"]["tolerance"] == 0.1  # 0.07 over: within twice 0.05
    assert at[("rigidmd", 6.0)]["U"]["verdict"] == "meets"
    # A split competes with the accurate single step: its own tolerances at any outer step.
    assert at[("rigidmd", 8.0)]["U"]["tolerance"] == 0.05
    # One run at +0.07 against 0.05, unresolved: a second would decide it (were it to stay).
    assert at[("rigidmd", 8.0)]["U"]["verdict"] == "unresolved"
    assert at[("rigidmd", 8.0)]["U"]["runs_to_decide"] == 2
    assert "| rigidmd | baoab k=4 r=5 | 8 | 1 | 2 |" in (tmp_path / "g.md").read_text()
    split = best[("tip4p2005", 216, "rigidmd", "baoab k=4 r=5")]  # its levels as fields
    assert (split["scheme"], split["substeps"], split["r_split"]) == ("baoab", 4, 5.0)
    assert "U" not in at[("lammps", 4.0)]  # no limit of its own: not judged
    # 6 fs is a stability step; at 2 fs the RDF peak (3.2 + 0.01 dt², no error of its own) is
    # 1.25 % off its exact limit, which the fit's zero scatter makes a clear ✗.
    assert at[("rigidmd", 2.0)]["rdf_peak_g"]["verdict"] == "fails"
    baoab = best[("tip4p2005", 216, "rigidmd", "baoab")]
    assert baoab["not_excluded_fs"] == 1.0 and baoab["shown_fs"] is None
    assert baoab["missing"] == ["T_conf_rot", "T_conf_tr"]
    points, fit_table = collector.report(files, tmp_path, "g", borrow={"lammps": "rigidmd"})
    borrowed = fit_table[("tip4p2005", 216, "lammps", "U")]
    assert borrowed["borrowed_from"] == "rigidmd"
    assert borrowed["shared"]["a"] == pytest.approx(-47.0, abs=1e-3)
    assert "borrowed_from" not in fit_table[("tip4p2005", 216, "lammps", "D_pbc")]
    text = (tmp_path / "g.md").read_text()
    assert "lammps's limits of ⟨U⟩ and the RDF peak are rigidmd's (the same forces" in text
    lammps_4 = next(r for r in json.loads((tmp_path / "g.json").read_text())["assessed"]
                    if r["code"] == "lammps" and r["dt_fs"] == 4.0)
    assert lammps_4["checks"]["U"]["dev"] == pytest.approx(0.48, abs=2e-3)
    assert lammps_4["checks"]["U"]["verdict"] == "fails"


def test_the_collector_refuses_to_borrow_openmm_s_limit(tmp_path, capsys):
    with pytest.raises(SystemExit):
        collector.main([str(tmp_path / "x.json"), "--borrow-limit", "openmm=rigidmd"])
    assert "OpenMM's long-range and dispersion treatments differ" in capsys.readouterr().err


def test_fit_limit_needs_enough_points():
    fit = collector.fit_limit([1.0], [-47.0], [0.01], ["langevin"])
    assert np.isnan(fit["a"])


def test_configurational_temperatures_from_the_hooks_sums(tmp_path):
    from ase import units

    series = table.Series(tmp_path / "s.npz")
    rng = np.random.default_rng(1)
    for i in range(20):
        den_tr, den_rot = rng.uniform(1, 2, 2)
        series.add(i * 0.1, -3000.0, (298.0, 298.0), (298.0, 298.0))
        series.frame(i * 0.1, np.zeros((2, 3)), np.zeros((2, 3)), np.eye(3) * 10,
                     (300 * units.kB * den_tr, den_tr, 310 * units.kB * den_rot, den_rot))
    p = {"equil_ps": 0.0, "blocks": 4, "msd_fit_ps": [3, 10], "box_A": 10.0}
    out = table.analyse(series, p, 2)
    assert out["T_conf_tr"][0] == pytest.approx(300.0) and out["T_conf_rot"][0] == \
        pytest.approx(310.0)
    # A frame not sampled (``--tconf-frames`` above 1) counts for nothing.
    series.frame(2.0, np.zeros((2, 3)), np.zeros((2, 3)), np.eye(3) * 10, None)
    assert table.analyse(series, p, 2)["T_conf_tr"][0] == pytest.approx(300.0)
    # Without any sums (no sampler: LAMMPS, OpenMM, --tconf-frames 0), null, never a number.
    bare = table.Series(tmp_path / "b.npz")
    for i in range(5):
        bare.add(i * 0.1, -3000.0, (298.0, 298.0), (298.0, 298.0))
        bare.frame(i * 0.1, np.zeros((2, 3)), np.zeros((2, 3)), np.eye(3) * 10, None)
    assert table.analyse(bare, p, 2)["T_conf_tr"] is None


@pytest.mark.lammps
def test_sampling_tconf_leaves_the_trajectory_alone(tmp_path):
    """The sampler evaluates its displaced configurations on a LAMMPS instance of its own,
    so the run with it is the run without it, bit for bit."""
    runs = {}
    for frames in (0, 1):
        out = tmp_path / f"f{frames}"
        rc, _, err = finish(_run(["--integrator", "baoab", "--dt-fs", "2", "--ps", "0.04",
                                   "--sample-fs", "4", "--frame-fs", "8", "--tconf-frames",
                                   str(frames), "--outdir", str(out)]))
        assert rc == 0, err
        runs[frames] = (json.loads((out / "tip4p2005_64_rigidmd_baoab_dt2_s1.json")
                                   .read_text()),
                        dict(np.load(out / "tip4p2005_64_rigidmd_baoab_dt2_s1.series.npz")))
    (plain, plain_series), (sampled, sampled_series) = runs[0], runs[1]
    assert plain["T_conf_tr"] is None and sampled["T_conf_tr"] is not None
    for key in ("U", "T_tr", "T_rot", "O", "com"):
        assert np.array_equal(plain_series[key], sampled_series[key]), key
    assert np.isfinite(sampled_series["conf"]).all() and np.isnan(plain_series["conf"]).all()


def test_start_keeps_the_shared_216_water_states():
    before = table.start_file("tip4p2005", 216).read_bytes()
    with pytest.raises(SystemExit, match="--waters 216: the start is water_openmm_long"):
        table.make_start("tip4p2005", 216)
    assert table.start_file("tip4p2005", 216).read_bytes() == before
    with pytest.raises(SystemExit, match="--waters 100: a start is made for a cube number"):
        table.make_start("tip4p2005", 100)


def test_tip4p2005_xml_is_tip4p2005():
    """OpenMM's TIP4P/2005 from ``validation/tip4p2005.xml`` against OpenMM's TIP4P-Ew system
    given rigidmd's TIP4P/2005 charges, Lennard-Jones and M weights (``water_openmm_long``):
    the same energy (measured 7e-10 kJ/mol per molecule apart; the file's weights have 12
    digits)."""
    mm = pytest.importorskip("openmm", reason="needs OpenMM (pip install openmm)")
    from openmm import unit

    from rigidmd.water import water_model

    long = benchmark_module("water_openmm_long")
    model = water_model("tip4p2005")
    state = table.load_start("tip4p2005", 64)
    cutoff = table.cutoff_for(state["cell"])
    energies = []
    for system in (table.openmm_water_system(state, model, cutoff),
                   _reparametrised(long, state, model, cutoff)):
        context = mm.Context(system, mm.VerletIntegrator(1e-3),
                             mm.Platform.getPlatformByName("Reference"))
        context.setPositions(state["positions"] / 10)
        context.computeVirtualSites()
        energies.append(context.getState(getEnergy=True).getPotentialEnergy()
                        .value_in_unit(unit.kilojoule_per_mole) / 64)
    assert energies[0] == pytest.approx(energies[1], abs=1e-8)
    assert -49 < energies[0] < -47


def _reparametrised(long, state, model, cutoff):
    old = long.CUTOFF
    long.CUTOFF = cutoff
    try:
        return long.openmm_system(state, model)
    finally:
        long.CUTOFF = old


def test_block_mean_and_rdf_peak():
    x = np.repeat([1.0, 2.0, 3.0, 4.0], 5)
    mean, err = table.block_mean(x, 4)
    assert mean == 2.5 and err == pytest.approx(np.std([1, 2, 3, 4], ddof=1) / 2)
    # Two molecules 2.8 Å apart in a 20 Å box: the RDF's only peak is at 2.8 Å.
    O = np.array([[[1.0, 1.0, 1.0], [3.8, 1.0, 1.0]]])
    r, g = table.rdf_first_peak(O, np.eye(3) * 20.0, bin_A=0.02)
    assert abs(r - 2.8) < 0.02 and g > 0


@pytest.mark.lammps
def test_time_to_solution_measures_each_largest_step(tmp_path):
    """``time_to_solution.py``: the table's largest steps (and a given point) measured side
    by side from the 64-water start; ns/day is 86.4·dt/ms and the ratio is to LAMMPS's own
    integrator at its step."""
    tts = benchmark_module("time_to_solution")
    table_json = tmp_path / "table.json"
    table_json.write_text(json.dumps({"largest_steps": [
        {"model": "tip4p2005", "waters": 64, "code": "rigidmd", "integrator": "baoab",
         "not_excluded_fs": 4.0, "shown_fs": 2.0, "missing": []},
        {"model": "tip4p2005", "waters": 64, "code": "lammps", "integrator": "nvt_small",
         "not_excluded_fs": 2.0, "shown_fs": None, "missing": []},
        {"model": "tip4p2005", "waters": 64, "code": "rigidmd", "integrator": "baoab k=2 r=4",
         "scheme": "baoab", "substeps": 2, "r_split": 4.0, "not_excluded_fs": 6.0,
         "shown_fs": None, "missing": []}]}))
    rows = tts.main([str(table_json), "--extra", "rigidmd:langevin:2", "--steps", "300",
                     "--rounds", "1", "--outdir", str(tmp_path), "--workdir",
                     str(tmp_path / "work"), "--skin", "3"])
    assert [(r["code"], r["integrator"], r["dt_fs"], r["basis"]) for r in rows] == [
        ("rigidmd", "baoab", 4.0, "not excluded"), ("rigidmd", "baoab", 2.0, "shown"),
        ("lammps", "nvt_small", 2.0, "not excluded"),
        ("rigidmd", "baoab k=2 r=4", 6.0, "not excluded"), ("rigidmd", "langevin", 2.0, "given")]
    lammps = rows[2]
    assert [r["reference"] for r in rows] == [False, False, True, False, False]
    assert (rows[3]["scheme"], rows[3]["substeps"], rows[3]["r_split"]) == ("baoab", 2, 4.0)
    assert (rows[0]["substeps"], rows[0]["r_split"]) == (1, None)  # the figure reads these
    # The split's outer step costs more than a single step: two levels, the fast one twice.
    assert rows[3]["cpu_ms_per_step"] > rows[0]["cpu_ms_per_step"]
    for r in rows:
        assert r["cpu_ms_per_step"] > 0
        assert r["ns_per_day"] == pytest.approx(86.4 * r["dt_fs"] / r["cpu_ms_per_step"])
        assert r["vs_lammps"] == pytest.approx(r["ns_per_day"] / lammps["ns_per_day"])
    written = (tmp_path / "time_to_solution.txt").read_text()
    assert "| rigidmd | baoab | 4 | not excluded |" in written
    assert "neighbour skin 3 Å" in written
    with pytest.raises(SystemExit):
        tts.main([str(table_json), "--extra", "openmm:baoab:4"])
    with pytest.raises(SystemExit):  # a split is rigidmd's, with k >= 2
        tts.main([str(table_json), "--extra", "rigidmd:baoab:6:1:5"])
    # A split given: its levels reach the measurement as a table's split row's do.
    points, levels = tts.chosen_points({"largest_steps": []}, ["rigidmd:baoab:6:2:5"])
    assert points == [("rigidmd", "baoab k=2 r=5", 6.0, "given")]
    assert levels == {"baoab k=2 r=5": ("baoab", 2, 5.0)}


def test_a_bundle_of_runs_gives_the_same_table(tmp_path):
    """``--bundle`` writes every run read into one file, which the collector reads again to
    the same table (how the docs' tables are kept with their runs)."""
    files = [_synthetic(tmp_path, "baoab", dt, seed, -47.0 + 0.01 * seed)
             for dt in (1.0, 2.0) for seed in (1, 2)]
    collector.main([*map(str, files), "--outdir", str(tmp_path), "--name", "a", "--bundle"])
    bundle = json.loads((tmp_path / "a.runs.json").read_text())
    assert len(bundle) == 4
    collector.main([str(tmp_path / "a.runs.json"), "--outdir", str(tmp_path), "--name", "b"])
    assert (tmp_path / "a.md").read_text() == (tmp_path / "b.md").read_text()


def test_seeds_of_a_deterministic_integrator_start_apart():
    """LAMMPS's Nosé–Hoover chains (and rigidmd's) draw no random numbers, so their seeds
    were one run repeated (measured: three identical LAMMPS runs).  A seed other than 1
    now draws the start's momenta again (the centre of mass at rest); a stochastic
    integrator's seeds share the start."""
    point = {"model": "tip4p2005", "waters": 64, "code": "lammps", "integrator": "nvt_small"}
    first, second, third = (table.start_for(dict(point, seed=s))["momenta"] for s in (1, 2, 3))
    shared = table.load_start("tip4p2005", 64)["momenta"]
    np.testing.assert_array_equal(first, shared)
    assert np.abs(second - first).max() > 0.1 and np.abs(third - second).max() > 0.1
    assert np.abs(second.sum(axis=0)).max() < 1e-10
    baoab = dict(point, code="rigidmd", integrator="baoab", seed=2)
    np.testing.assert_array_equal(table.start_for(baoab)["momenta"], shared)
    nose_hoover = dict(point, code="rigidmd", integrator="nosehoover", seed=2)
    np.testing.assert_array_equal(table.start_for(nose_hoover)["momenta"], second)


@pytest.mark.parametrize("name, options, pages", [
    ("timestep_table_216", ["--borrow-limit", "lammps=rigidmd"],
     ("timestep-216.md", "timestep-216-goals.md", "timestep-216-tables.md",
      "timestep-216-codes.md", "timestep-216-runs.md", "timestep-216-plan.md")),
    ("timestep_table_216_spce", [], ("timestep-216-spce.md", "timestep-216-plan.md")),
])
def test_the_216_water_pages_show_what_the_committed_runs_give(tmp_path, name, options,
                                                               pages):
    """The pages' tables are the collector's on the committed runs (``--bundle``), every row
    of them: a page kept by hand from an older collection, or runs added without their
    rows, fails here."""
    bundle = ROOT / "validation" / f"{name}.runs.json"
    collector.main([str(bundle), "--outdir", str(tmp_path), "--name", "t", *options])
    rows = [line for line in (tmp_path / "t.md").read_text().splitlines()
            if line.startswith("| ") and not line.startswith("| model") and
            not line.startswith("| code")]
    pages = "".join((ROOT / "docs" / "validation" / page).read_text() for page in pages)
    assert len(rows) > 5
    missing = [row for row in rows if row not in pages]
    assert not missing, f"rows the pages lack (run the collector again): {missing}"


@pytest.mark.lammps
def test_the_skin_reaches_every_level_and_leaves_the_forces():
    """``skin`` (time_to_solution's ``--skin``) is every LAMMPS level's neighbour skin, and
    changes the cost, not the forces: the 64-water start's forces at 2 and 3 Å agree to
    roundoff (measured 1.2e-15 eV/Å, neighbour order; bound 1e-10 eV/Å)."""
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    state = table.load_start("tip4p2005", 64)
    point = {"substeps": 2, "r_split": 4.0, "skin": 3.0}
    split = table.rigidmd_calculator(point, model, state["cell"])
    assert split.fast.skin == split.full.skin == 3.0
    forces = []
    for skin in (2.0, 3.0):
        atoms = table.make_atoms(state, model, skin)
        assert atoms.calc.skin == skin
        forces.append(atoms.get_forces())
    np.testing.assert_allclose(forces[0], forces[1], rtol=0, atol=1e-10)


def test_diffusion_has_a_limit_per_kind_of_thermostat(tmp_path):
    """D_PBC under a Langevin friction and under a global thermostat are different
    quantities (216 waters, dt → 0: 1.88 ± 0.03 × 1e-5 cm²/s under Bussi and Nosé–Hoover,
    1.78 ± 0.02 under the 1/ps friction), so each kind has its own limit; ⟨U⟩, a static
    quantity, stays shared."""
    files = []
    for integrator, d in (("baoab", 1.8), ("bussi", 2.2), ("nosehoover", 2.2)):
        for dt in (1.0, 2.0):
            file = _synthetic(tmp_path, integrator, dt, 1, -47.0)
            run = json.loads(file.read_text())
            run["D_pbc"] = [d, 0.02]
            file.write_text(json.dumps(run))
            files.append(file)
    points, fits = collector.report(files, tmp_path, "d")
    assert fits[("tip4p2005", 216, "rigidmd:friction", "D_pbc")]["shared"]["a"] == \
        pytest.approx(1.8)
    assert fits[("tip4p2005", 216, "rigidmd:global", "D_pbc")]["shared"]["a"] == \
        pytest.approx(2.2)
    assert fits[("tip4p2005", 216, "rigidmd:global", "D_pbc")]["agree"] is True
    assert fits[("tip4p2005", 216, "rigidmd", "U")]["shared"]["points"] == 6
    rows, _ = collector.assess(points, fits)
    assert all(abs(r["checks"]["D_pbc"]["dev"]) < 1e-9 for r in rows)


def test_a_limit_from_points_without_errors_has_no_invented_error():
    """Single runs of a quantity with no error of its own (the RDF peak of one run): the
    limit's error is the scatter's about the fit, or nan with no degree of freedom left;
    before, equal weights of 1 gave an error of about 1.4 whatever the values."""
    exact = collector.fit_limit([1.0, 2.0], [3.17, 3.14], [np.nan, np.nan], ["baoab"] * 2)
    assert exact["a"] == pytest.approx(3.18) and np.isnan(exact["a_err"])
    scattered = collector.fit_limit([0.5, 1.0, 2.0], [3.181, 3.169, 3.141],
                                    [np.nan] * 3, ["baoab"] * 3)
    assert 0 < scattered["a_err"] < 0.02


def test_a_stop_in_another_program_hands_its_signal_handlers_back():
    """``measure_ms`` runs points inside its caller (time_to_solution.py, the tests): its
    ``Stop`` left SIGINT and SIGTERM to itself, and a later Ctrl-C test in the same test
    process found no Python handler (three relax tests failed that way under xdist)."""
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    with table.Stop() as stop:
        assert signal.getsignal(signal.SIGINT) == stop._handle
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)
        assert stop and stop.signal == "SIGTERM"
    assert {sig: signal.getsignal(sig) for sig in before} == before


# ------------------------------------------------------------ outside pass, 2026-11-29

def test_the_collector_refuses_a_run_twice_and_runs_made_unalike(tmp_path):
    """The same file twice (or a bundle with its own inputs) was pooled as more runs (U's
    error 0.069 for 0.108), and runs of 0.4 and 2 ps, or of other equilibration, were pooled
    as one point, all without a word."""
    files = [_synthetic(tmp_path, "baoab", dt, seed, -47.0 + 0.01 * seed)
             for dt in (1.0, 2.0) for seed in (1, 2)]
    with pytest.raises(SystemExit, match=r"is also in .*give each run once"):
        collector.report([*files, files[0]], tmp_path, "t")
    longer = json.loads(files[1].read_text())
    longer["point"].update(seed=3, ps=2.0)
    other = tmp_path / "longer.json"
    other.write_text(json.dumps(longer))
    with pytest.raises(SystemExit, match=r"its runs differ in ps \(2.0, null\)"):
        collector.report([*files, other], tmp_path, "t")
    (tmp_path / "broken.json").write_text('{"a": ')
    with pytest.raises(SystemExit, match=r"broken.json: not a readable run or bundle"):
        collector.report([*files, tmp_path / "broken.json"], tmp_path, "t")


@pytest.mark.parametrize("args, message", [
    (["--jobs", "0"], "--jobs: expected a whole number >= 1"),  # waited for ever
    (["--ps", "0"], "--ps: expected a positive number"),  # wrote a complete run of NaN
    (["--dt-fs", "0"], "--dt-fs: expected a positive number"),
    (["--sample-fs", "0"], "--sample-fs: expected a positive number"),  # ZeroDivisionError
    (["--blocks", "1"], "--blocks: expected a whole number >= 2"),  # failed after the run
    (["--equil-ps", "5"], "--equil-ps 5: leaves nothing of --ps 0.1"),
    (["--seed", "1", "1"], "--seed: a value given twice"),
    # the same point twice: both processes ran it into the same files (an outside pass)
    (["--integrator", "baoab", "baoab"], "--integrator: a value given twice"),
    (["--code", "openmm", "--substeps", "2"], "--substeps: a force split is rigidmd's"),
    (["--code", "lammps", "--integrator", "baoab"], "--integrator: rigidmd's"),
    # each point failed in its own process, the hint repeated per point
    (["--waters", "100"], "--waters 100: no start state timestep_table.start_tip4p2005_100"),
])
def test_run_arguments_that_would_not_run_are_refused_first(tmp_path, args, message):
    given = dict(zip(["--dt-fs", "--ps"], ["2", "0.1"], strict=True))
    for option in args[::2]:
        given.pop(option, None)
    rc, _, err = finish(_run([*[x for kv in given.items() for x in kv], *args,
                              "--outdir", str(tmp_path / "out")]))
    assert rc != 0 and message in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_run_left_by_a_kill_or_resumed_otherwise_is_refused(tmp_path):
    """A killed run (checkpoint, no JSON) was started over by the same command without
    --resume; --resume with other arguments mixed the series and labelled them with the new
    ones; --resume of a run whose checkpoint was gone started from step 0 in silence."""
    point = {"code": "rigidmd", "integrator": "langevin", "model": "tip4p2005",
             "waters": 64, "dt_fs": 2.0, "seed": 1, "ps": 0.4, "sample_fs": 20.0}
    json_path, chk = tmp_path / "run.json", tmp_path / "run.chk.npz"
    chk.write_bytes(b"x")
    with pytest.raises(SystemExit, match=r"run.chk.npz: exists; give --resume"):
        table.complete_already(json_path, "run", False, point, chk)
    json_path.write_text(json.dumps({"point": dict(point, save_s=300.0), "complete": False,
                                     "steps": 50, "ps": 0.1}))
    with pytest.raises(SystemExit, match=r"--resume with --sample-fs 100.0, but the run was "
                                         r"made with 20.0"):
        table.complete_already(json_path, "run", True, dict(point, sample_fs=100.0), chk)
    assert table.complete_already(json_path, "run", True, dict(point, save_s=10.0), chk) \
        is False  # how often it saves may change
    chk.unlink()
    with pytest.raises(SystemExit, match=r"stopped at 0.1 ps but .*run.chk.npz is gone"):
        table.complete_already(json_path, "run", True, point, chk)


@pytest.mark.lammps
def test_a_parent_killed_outright_takes_its_runs_with_it(tmp_path):
    """After SIGKILL of the parent (or a hang-up) its ``_point`` processes ran on, orphans;
    each now gets SIGTERM when its parent dies, and writes what it has."""
    proc = _run(["--integrator", "langevin", "--dt-fs", "2", "--ps", "2", "--seed", "1", "2",
                 "--jobs", "1", "--save-s", "0", "--outdir", str(tmp_path)])
    name = "tip4p2005_64_rigidmd_langevin_dt2_s1"
    deadline = time.monotonic() + 200
    while not (tmp_path / f"{name}.chk.npz").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    children = [int(pid) for pid in subprocess.run(
        ["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout.split()]
    assert children, "no run process"
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 60
    while any(os.path.exists(f"/proc/{pid}") and
              open(f"/proc/{pid}/stat").read().split(") ")[1][0] != "Z" for pid in children):
        assert time.monotonic() < deadline, "a run outlived its parent"
        time.sleep(0.1)
    result = json.loads((tmp_path / f"{name}.json").read_text())
    assert result["stopped_by"] == "SIGTERM" and not result["complete"]


def test_benchmark_and_page_arguments_are_checked_first(tmp_path):
    """``cost --steps 10`` printed a plausible ms/step from (t10 - t20) / (10 - 20), 20 a
    ZeroDivisionError; ``timestep_table_pages.py --help`` rewrote the pages."""
    with pytest.raises(SystemExit, match=r"--steps 10: must be above 20"):
        table.measure_ms("rigidmd", "langevin", 2.0, 10, "tip4p2005", 64, tmp_path)
    pages = sorted((ROOT / "docs" / "validation").glob("timestep-216*.md"))
    before = {p: p.stat().st_mtime_ns for p in pages}
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, str(ROOT / "validation" /
                                                 "timestep_table_pages.py"), "--help"],
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "usage:" in result.stdout
    assert {p: p.stat().st_mtime_ns for p in pages} == before


@pytest.mark.parametrize("script, args, message", [
    ("timestep_table", ["analyse", "{missing}"], "argument files: no such file"),
    ("timestep_table", ["analyse", "{empty}"], "not a run's JSON (no point, name or molecules)"),
    ("time_to_solution", ["{missing}"], "argument table: no such file"),
    ("time_to_solution", ["{empty}"], "not the JSON of timestep_table_report.py"),
    ("respa_kspace_share", ["--report", "--out", "{missing_stem}"],
     "missing.json: not a readable JSON file"),
    ("water_openmm_long", ["report", "{missing}"], "argument files: no such file"),
])
def test_a_missing_or_foreign_input_file_is_one_line(tmp_path, script, args, message):
    """Each printed a FileNotFoundError's or a KeyError's traceback."""
    (tmp_path / "empty.json").write_text("{}")
    names = {"missing": tmp_path / "missing.json", "empty": tmp_path / "empty.json",
             "missing_stem": tmp_path / "missing"}
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, str(ROOT / "validation" / f"{script}.py"),
                             *[a.format(**names) for a in args]],
                            env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode != 0 and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.json"]


def test_a_quantity_only_some_runs_sampled_is_counted_as_such(tmp_path):
    """T_conf pooled from the one run of three that sampled it was shown beside the point's
    three runs, and the plan counted three runs' worth of its error."""
    files = [_synthetic(tmp_path, "baoab", dt, seed, -47.0) for dt in (0.5, 1.0, 2.0)
             for seed in (1, 2)]
    for seed in (1, 2, 3):
        files.append(_synthetic(tmp_path, "baoab", 4.0, seed, -47.0))
    run = json.loads(files[-1].read_text())
    run.update(T_conf_tr=[301.0, 1.0], T_conf_rot=[298.0, 1.0])  # the third run's only
    files[-1].write_text(json.dumps(run))
    points, fit_table = collector.report(files, tmp_path, "c")
    four = next(p for p in points if p["dt_fs"] == 4.0)
    assert four["runs"] == 3 and four["runs_of"]["T_conf_tr"] == 1
    assert "301.0 ± 1.0 / 298.0 ± 1.0 (1 of 3 runs)" in (tmp_path / "c.md").read_text()
    rows, _ = collector.assess(points, fit_table)
    check = next(r for r in rows if r["dt_fs"] == 4.0)["checks"]["T_conf_tr"]
    # +3.0 ± 1.0 against 2 K, unresolved; one run's error 1.0 fails it once 3 - 2/√m > 2,
    # at m = 5 runs that sample it: those and the two that did not, 7 in all (5 if all
    # three had counted).
    assert check["verdict"] == "unresolved" and check["runs_to_decide"] == 7


def test_progress_counts_from_the_run_s_start(capsys):
    """A LAMMPS run's first report (after its first piece) said 0.00 ns/day: the rate
    counted from that report itself."""
    progress = table.Progress("run", 1.0, every_s=0.0, shared=True)
    progress.begin(0.25)  # a resumed run
    time.sleep(0.05)
    progress(0.5, force=True)
    line = capsys.readouterr().out
    rate = float(line.split("(")[1].split()[0])
    assert "run: 0.50 / 1 ps" in line and 0 < rate < 0.25 / 0.05 * 86.4  # ns/day


def test_a_native_lammps_run_ends_with_the_script_that_started_it(tmp_path):
    """respa_kspace_share.py's ``lmp`` ran on after the script was stopped (its default
    SIGTERM, or SIGKILL): its children now get SIGTERM when it dies (the same
    ``ends_with_parent`` the table's points use)."""
    script = tmp_path / "parent.py"
    script.write_text(
        "import subprocess, sys, time\n"
        f"sys.path.insert(0, {str(ROOT / 'validation')!r})\n"
        "from children import ends_with_parent\n"
        "child = subprocess.Popen(['sleep', '60'], preexec_fn=ends_with_parent)\n"
        "print(child.pid, flush=True)\n"
        "time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 10  # measured: gone within 0.01 s
    while os.path.exists(f"/proc/{child}") and \
            open(f"/proc/{child}/stat").read().split(") ")[1][0] != "Z":
        assert time.monotonic() < deadline, "the child outlived its parent"
        time.sleep(0.01)


# ------------------------------------------------------------ outside pass, 2026-12 (runs)
TINY = ["--integrator", "baoab", "--dt-fs", "2", "--sample-fs", "4", "--frame-fs", "8",
        "--tconf-frames", "0"]
BAOAB = "tip4p2005_64_rigidmd_baoab_dt2_s1"


@pytest.mark.lammps
def test_a_second_run_of_a_point_into_one_outdir_is_refused(tmp_path):
    """Two runs of one point into one --outdir both ran, and the later one's files replaced
    the earlier one's without a word: the point is claimed (its ``.claim`` locked) while it
    runs; a claim left unlocked, by a process that ended, is taken over."""
    import fcntl

    claim = tmp_path / f"{BAOAB}.claim"
    claim.write_text("12345 elsewhere\n")
    with open(claim) as held:  # another run of the point, running
        fcntl.flock(held, fcntl.LOCK_EX)
        rc, _, err = finish(_run([*TINY, "--ps", "0.02", "--outdir", str(tmp_path)]))
    assert rc != 0 and f"{BAOAB}: being run already (process 12345 elsewhere" in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == [claim.name]  # nothing written
    rc, out, err = finish(_run([*TINY, "--ps", "0.02", "--outdir", str(tmp_path)]))
    assert rc == 0, err
    assert "the claim of process 12345 elsewhere, which ended without removing it, taken " \
           "over" in out
    assert not claim.exists()
    # (the record of its arguments is no *.json: the collector reads every *.json)
    assert [p.name for p in tmp_path.glob("*.json")] == [f"{BAOAB}.json"]


@pytest.mark.lammps
def test_a_resume_after_a_kill_with_other_arguments_is_refused(tmp_path):
    """A run killed outright (SIGKILL: a checkpoint and a series, no JSON) was continued by
    --resume with other arguments (--sample-fs 100 after 20) without a word, its series mixed:
    its arguments are recorded before its first sample and checked."""
    proc = _run([*TINY, "--ps", "4", "--save-s", "0", "--outdir", str(tmp_path)])
    chk = tmp_path / f"{BAOAB}.chk.npz"
    deadline = time.monotonic() + 200
    while not chk.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.kill()
    finish(proc)
    assert chk.exists() and not (tmp_path / f"{BAOAB}.json").exists()
    before = {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()}
    rc, _, err = finish(_run([*TINY[:4], "--sample-fs", "100", "--frame-fs", "200",
                              "--tconf-frames", "0", "--ps", "4", "--outdir", str(tmp_path),
                              "--resume"]))
    assert rc != 0 and f"{BAOAB}: --resume with --sample-fs 100.0, but the run was made " \
                       "with 4.0" in err, err
    assert "Traceback" not in err
    after = {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()}
    assert {k: v for k, v in after.items() if not k.endswith(".claim")} == \
        {k: v for k, v in before.items() if not k.endswith(".claim")}


def _analysed_run(tmp_path, ps=0.4):
    """A run's JSON and series as a run of ``ps`` (4 waters, a sample every 20 fs, a frame
    every 40 fs), analysed."""
    rng = np.random.default_rng(1)
    point = {"code": "rigidmd", "integrator": "baoab", "model": "tip4p2005", "waters": 4,
             "dt_fs": 2.0, "seed": 1, "ps": ps, "equil_ps": 0.0, "blocks": 2,
             "msd_fit_ps": [1.0, 5.0], "box_A": 20.0}
    series = table.Series(tmp_path / "run.series.npz")
    for i in range(int(round(ps / 0.02)) + 1):
        series.add(0.02 * i, -190.0 + rng.normal(), (298.0, 298.0), (298.0, 298.0))
        if i % 2 == 0:
            O = np.array([[0.0, 0, 0], [2.8, 0, 0], [0, 2.8, 0], [0, 0, 2.8]])
            O = O + rng.normal(scale=0.1, size=O.shape)
            series.frame(0.02 * i, O, O, np.diag([20.0] * 3))
    series.save()
    out = {"point": point, "name": "run", "molecules": 4, "complete": True, "ps": ps,
           **table.analyse(series, point, 4)}
    path = tmp_path / "run.json"
    path.write_text(json.dumps(out))
    return path


@pytest.mark.parametrize("equil_ps, message", [
    ("50", "--equil-ps 50: leaves nothing of run.json's 0.4 ps"),
    ("0.4", "--equil-ps 0.4: leaves nothing of run.json's 0.4 ps"),
    ("nan", "argument --equil-ps: expected a number >= 0"),
    ("-3", "argument --equil-ps: expected a number >= 0"),
])
def test_analyse_refuses_an_equilibration_that_leaves_nothing(tmp_path, capsys, equil_ps,
                                                              message):
    """``analyse --equil-ps 50`` of a 0.4 ps run (or nan) rewrote its JSON with every result
    NaN, still ``"complete": true``."""
    path = _analysed_run(tmp_path)
    before = path.read_text()
    with pytest.raises(SystemExit) as refused:
        table.main(["analyse", str(path), "--equil-ps", equil_ps])
    assert message in f"{refused.value.code}{capsys.readouterr().err}"
    assert path.read_text() == before
    table.main(["analyse", str(path), "--equil-ps", "0.1"])  # what leaves part of it
    run = json.loads(path.read_text())
    assert run["point"]["equil_ps"] == 0.1 and np.isfinite(run["U"][0])


def test_the_collector_refuses_runs_fitted_or_pieced_otherwise(tmp_path):
    """Runs of D_PBC fitted over other lags (--msd-fit-ps), or LAMMPS's runs in other pieces
    (--piece-ps), were pooled into one point, its D_PBC the mean of two measurements."""
    files = [_synthetic(tmp_path, "baoab", dt, seed, -47.0) for dt in (1.0, 2.0)
             for seed in (1, 2)]
    for file, fit in zip(files, ([3.0, 10.0], [0.1, 0.25], [3.0, 10.0], [3.0, 10.0]),
                         strict=True):
        run = json.loads(file.read_text())
        run["point"].update(msd_fit_ps=fit, piece_ps=10.0 * run["point"]["seed"])
        file.write_text(json.dumps(run))
    with pytest.raises(SystemExit, match=r"tip4p2005 216 rigidmd baoab 1.0 fs: its runs differ "
                                         r"in msd_fit_ps \(\[0.1, 0.25\], \[3.0, 10.0\]\)"):
        collector.report(files, tmp_path, "t")
    collector.report(files[2:], tmp_path, "t")  # rigidmd's runs carry --piece-ps unused
    pieces = [_synthetic(tmp_path, "nvt_small", dt, seed, -47.0, code="lammps")
              for dt in (1.0, 2.0) for seed in (1, 2)]
    for file in pieces:
        run = json.loads(file.read_text())
        run["point"].update(piece_ps=10.0 * run["point"]["seed"])
        file.write_text(json.dumps(run))
    with pytest.raises(SystemExit, match=r"lammps nvt_small 1.0 fs: its runs differ in "
                                         r"piece_ps \(10.0, 20.0\)"):
        collector.report(pieces, tmp_path, "t")


@pytest.mark.parametrize("args, message", [
    # refused only after a compile run that wrote into --outdir
    (["cost", "--waters", "64", "--steps", "10"], "argument --steps: expected a whole number "
                                                  ">= 21, got 10"),
    # suggested 'start --waters 0'
    (["cost", "--waters", "0"], "argument --waters: expected a whole number >= 1, got 0"),
    (["cost", "--waters", "100"], "--waters 100: no start state timestep_table.start_tip4p2005"
                                  "_100.npz; starts are made for cube numbers of waters"),
    # tracebacks
    (["start", "--waters", "0"], "argument --waters: expected a whole number >= 8, got 0"),
    (["start", "--waters", "-8"], "argument --waters: expected a whole number >= 8, got -8"),
    (["start", "--waters", "8", "--seed", "-1"], "argument --seed: expected a whole number "
                                                 ">= 0, got -1"),
])
def test_cost_and_start_arguments_are_checked_first(tmp_path, args, message):
    """Each argument in one line naming it, before a run writes anything."""
    out = tmp_path / "cost"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, str(SCRIPT), *args,
                             *(["--outdir", str(out)] if args[0] == "cost" else [])],
                            env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0 and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and not out.exists()


def test_the_collector_refuses_a_foreign_run_and_takes_a_missing_field_as_missing(tmp_path):
    """An NPT run of npt_density.py (a point without model or code) ended in a KeyError
    traceback, and so did a table run without ms_per_step."""
    npt_runs = json.loads((ROOT / "validation" / "npt_density_216.runs.json").read_text())
    (tmp_path / "npt.json").write_text(json.dumps(next(r for r in npt_runs if r["complete"])))
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    result = subprocess.run([sys.executable, str(ROOT / "validation" /
                                                 "timestep_table_report.py"),
                             str(tmp_path / "npt.json"), "--outdir", str(tmp_path / "out")],
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "Traceback" not in result.stderr, result.stderr
    assert f"{tmp_path / 'npt.json'}: holds something that is not a table run (its point " \
           "has no model" in result.stderr
    assert not (tmp_path / "out").exists()
    files = [_synthetic(tmp_path, "baoab", dt, seed, -47.0) for dt in (1.0, 2.0)
             for seed in (1, 2)]
    for file in files[:3]:  # the point of 2 fs: one run of two has it
        run = json.loads(file.read_text())
        del run["ms_per_step"]
        file.write_text(json.dumps(run))
    points, _ = collector.report(files, tmp_path, "t")
    assert [p["ms_per_step"] for p in points] == [None, 3.0]
