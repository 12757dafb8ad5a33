"""Production runs from the command line: stop by signal or kill, resume, locks, failures.

Every continued run is compared with the same run left alone: trajectory
frames bit for bit, log lines character for character, XTC frames equal.
The system is 8 TIP3P waters (ASE's TIP3P, deterministic), 2 fs steps.
"""

import errno
import json
import os
import signal
import subprocess
import sys
import time
from functools import cache

import numpy as np
import pytest
from ase.io import read, write

from rigidmd import cli
from rigidmd.checkpoint import read_checkpoint
from rigidmd.systems import water_cluster

THERMOSTATS = {
    "nve": "",
    "nose_hoover": "thermostat: {kind: nose_hoover, temperature: 250 K, tdamp: 50 fs}",
    "langevin": "thermostat: {kind: langevin, temperature: 250 K, friction: 0.02 1/fs, seed: 2}",
    "bussi": "thermostat: {kind: bussi, temperature: 250 K, taut: 50 fs, seed: 3}",
}
STEPS = 1500


def config_text(thermostat, xtc=True):
    outputs = "{directory: out, trajectory: md.traj, log: md.log, interval: 10, "
    outputs += "checkpoint_interval: 50" + (", mdanalysis: md.xtc}" if xtc else "}")
    return (f"structure: cluster.xyz\nread_options: {{format: extxyz}}\nbodies: mol-id\n"
            f"calculator: {{name: tip3p, options: {{rc: 40.0}}}}\n"
            f"velocities: {{temperature: 250 K, seed: 1}}\n{THERMOSTATS[thermostat]}\n"
            f"timestep: 2 fs\nsteps: {STEPS}\noutputs: {outputs}\n")


def project(path, thermostat, xtc=True):
    path.mkdir(parents=True, exist_ok=True)
    write(path / "cluster.xyz", water_cluster(8, seed=4), format="extxyz")
    (path / "run.yaml").write_text(config_text(thermostat, xtc))
    return path


def start(path, *args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "rigidmd.cli", "run", "run.yaml", *args],
                            cwd=path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def finish(proc):
    stdout, stderr = proc.communicate(timeout=600)
    return proc.returncode, stdout, stderr


def wait_for_lines(log, n, proc, timeout=120):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if log.exists() and len(log.read_text().splitlines()) > n:
            return
        if proc.poll() is not None:
            raise AssertionError("the run ended before it could be stopped")
        time.sleep(0.05)
    raise AssertionError("the run produced no log lines")


def outputs(path, xtc=True):
    """Positions of every .traj frame, the log text, and the XTC frames (if any)."""
    out = path / "out"
    frames = np.array([a.positions for a in read(out / "md.traj", ":")])
    result = {"traj": frames, "log": (out / "md.log").read_text()}
    if xtc:
        import MDAnalysis as mda

        universe = mda.Universe(str(out / "md.psf"), str(out / "md.xtc"))
        result["xtc"] = np.array([ts.positions.copy() for ts in universe.trajectory])
        result["xtc_steps"] = [ts.data["step"] for ts in universe.trajectory]
    return result


@cache
def uninterrupted(root, thermostat, xtc=True):
    path = project(root / f"plain-{thermostat}-{xtc}", thermostat, xtc)
    status, _, stderr = finish(start(path))
    assert status == 0, stderr
    return outputs(path, xtc)


def assert_same(resumed, reference):
    np.testing.assert_array_equal(resumed["traj"], reference["traj"])
    assert resumed["log"] == reference["log"]
    if "xtc" in reference:
        assert resumed["xtc_steps"] == reference["xtc_steps"]
        np.testing.assert_array_equal(resumed["xtc"], reference["xtc"])


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("production")


@pytest.mark.mdanalysis
@pytest.mark.parametrize("thermostat, signum", [
    ("nve", signal.SIGTERM), ("nose_hoover", signal.SIGTERM), ("langevin", signal.SIGTERM),
    ("bussi", signal.SIGTERM), ("langevin", signal.SIGINT), ("nose_hoover", signal.SIGUSR1),
])
def test_stop_by_signal_and_resume_equals_an_uninterrupted_run(root, thermostat, signum):
    reference = uninterrupted(root, thermostat)
    path = project(root / f"{thermostat}-{signum}", thermostat)
    proc = start(path)
    wait_for_lines(path / "out" / "md.log", 12, proc)
    proc.send_signal(signum)
    status, stdout, _ = finish(proc)
    assert status == 128 + signum
    assert f"stopped by {signal.Signals(signum).name}" in stdout
    assert "continue with: rigidmd run run.yaml --resume" in stdout
    stopped = read_checkpoint(path / "out" / "checkpoint.npz").nsteps
    assert 0 < stopped < STEPS
    # Every output is whole and readable at the stop.
    partial = outputs(path)
    assert len(partial["traj"]) == stopped // 10 + 1 == len(partial["xtc"])
    status, stdout, stderr = finish(start(path, "--resume"))
    assert status == 0, stderr
    assert f"resuming from step {stopped}" in stdout
    assert_same(outputs(path), reference)


@pytest.mark.mdanalysis
def test_kill_9_then_resume_repairs_every_output(root):
    """After SIGKILL (and a last frame cut in half), --resume cuts back and continues."""
    reference = uninterrupted(root, "langevin")
    path = project(root / "killed", "langevin")
    proc = start(path)
    wait_for_lines(path / "out" / "md.log", 40, proc)
    proc.send_signal(signal.SIGKILL)
    finish(proc)
    out = path / "out"
    checkpoint = read_checkpoint(out / "checkpoint.npz")
    # A power cut in the middle of writing: half a frame and half a line at the ends.
    for name, garbage in (("md.xtc", b"\x00\x00\x07\xcb\x00"), ("md.log", b"1.2340   -3."),
                          ("md.traj", b"\x01" * 37)):
        with open(out / name, "ab") as fh:
            fh.write(garbage)
    status, stdout, stderr = finish(start(path, "--resume"))
    assert status == 0, stderr
    assert f"resuming from step {checkpoint.nsteps}" in stdout and "cut back" in stdout
    assert_same(outputs(path), reference)


def test_a_second_run_into_a_directory_in_use_is_refused(tmp_path):
    path = project(tmp_path, "nve", xtc=False)
    first = start(path)
    wait_for_lines(path / "out" / "md.log", 2, first)
    second = finish(start(path, "--overwrite"))
    first.send_signal(signal.SIGTERM)
    finish(first)
    assert second[0] == 2
    assert f"is in use by process {first.pid}" in second[2]
    assert second[2].count("\n") == 1


def test_a_lock_left_by_a_dead_process_is_taken_over(tmp_path):
    path = project(tmp_path, "nve", xtc=False)
    (path / "out").mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    import socket

    (path / "out" / ".rigidmd.lock").write_text(json.dumps(
        {"pid": int(dead), "host": socket.gethostname()}))
    (path / "run.yaml").write_text(config_text("nve", xtc=False).replace(
        f"steps: {STEPS}", "steps: 20"))
    status, stdout, stderr = finish(start(path))
    assert status == 0, stderr
    assert f"taking over the lock left by process {dead}" in stdout
    assert not (path / "out" / ".rigidmd.lock").exists()


def test_outputs_are_never_mixed(tmp_path):
    path = project(tmp_path, "nve", xtc=False)
    (path / "run.yaml").write_text(config_text("nve", xtc=False).replace(
        f"steps: {STEPS}", "steps: 20"))
    assert finish(start(path))[0] == 0
    before = (path / "out" / "md.log").read_text()
    status, _, stderr = finish(start(path))
    assert status == 2
    assert "already holds md.traj, md.log" in stderr and "--resume" in stderr
    assert (path / "out" / "md.log").read_text() == before
    status, stdout, stderr = finish(start(path, "--overwrite"))
    assert status == 0, stderr
    assert "removing md.traj" in stdout
    assert (path / "out" / "md.log").read_text() == before  # the same run again
    assert len(read(path / "out" / "md.traj", ":")) == 3
    # Nothing to do when the run is complete; more steps continue it.
    status, stdout, _ = finish(start(path, "--resume"))
    assert status == 0 and "the run is complete (20 of 20 steps)" in stdout
    status, stdout, stderr = finish(start(path, "--resume", "--steps", "40"))
    assert status == 0, stderr
    assert len(read(path / "out" / "md.traj", ":")) == 5
    # A changed configuration cannot be resumed.
    (path / "run.yaml").write_text(config_text("nve", xtc=False).replace(
        "timestep: 2 fs", "timestep: 1 fs"))
    status, _, stderr = finish(start(path, "--resume"))
    assert status == 2
    assert stderr.startswith("rigidmd: error: --resume: timestep differs from the checkpoint's "
                             "run (only steps may change"), stderr


def test_demo_replaces_its_own_outputs(tmp_path):
    for _ in range(2):
        status = cli.main(["demo", "--steps", "20", "--outdir", str(tmp_path / "demo")])
        assert status == 0
    log = (tmp_path / "demo" / "demo.log").read_text().splitlines()
    # One header and the lines of one run (steps 0 and 20), not two runs appended.
    assert len(log) == 3 and log[0].startswith("Time[ps]")
    assert sum(line.startswith("Time") for line in log) == 1


def test_full_disk_stops_with_one_line_and_keeps_the_checkpoint(tmp_path, monkeypatch, capsys):
    """ENOSPC while writing the log: status 1, one line naming the file, checkpoint intact."""
    from rigidmd.logger import RigidLogger

    path = project(tmp_path, "langevin", xtc=False)
    original = RigidLogger.__call__
    calls = []

    def failing(self):
        calls.append(1)
        if len(calls) == 12:
            raise OSError(errno.ENOSPC, "No space left on device", str(path / "out" / "md.log"))
        original(self)

    monkeypatch.setattr(RigidLogger, "__call__", failing)
    monkeypatch.chdir(path)
    status = cli.main(["run", "run.yaml"])
    err = capsys.readouterr().err
    assert status == 1
    messages = [line for line in err.splitlines() if not line.startswith("[")]  # not progress
    assert len(messages) == 1 and "Traceback" not in err
    assert "md.log: the disk is full" in messages[0] and "last checkpoint is intact" in err
    checkpoint = read_checkpoint(path / "out" / "checkpoint.npz")
    assert checkpoint.nsteps == 100  # the last one before the failure at step 110
