"""Production runs from the command line: stop by signal or kill, resume, locks, failures.

Every continued run is compared with the same run left alone: trajectory
frames bit for bit, log lines character for character, XTC frames equal.
The system is 8 TIP3P waters (ASE's TIP3P, deterministic), 2 fs steps.
"""

import errno
import json
import signal
import subprocess
import sys
from functools import cache

import numpy as np
import pytest
from ase.io import read, write
from helpers import (  # the rigidmd-run projects these tests share with run/test_runner_faults.py
    STEPS,
    config_text,
    file_bytes,
    finish,
    messages,
    project,
    run_here,
    short_project,
    start,
    wait_for_lines,
)

from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.run import cli


def outputs(path, xtc=True):
    """Positions of every .traj frame, the log text, and the XTC frames (if any)."""
    out = path / "out"
    frames = np.array([a.positions for a in read(out / "md.traj", ":")])
    result = {"traj": frames, "log": (out / "md.log").read_text(),
              "traj_bytes": (out / "md.traj").read_bytes()}
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
    assert resumed["traj_bytes"] == reference["traj_bytes"]  # the file, not only its frames
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
    from rigidmd.core.logger import RigidLogger

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


# ---------------------------------------------------------------------------------------
# Short runs in this process (40 steps of the 8 waters, NVE unless said): faults found
# from outside (issue 22).
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def short_reference(tmp_path_factory):
    """The bytes of md.traj and md.log of the short run, left alone."""
    path = short_project(tmp_path_factory.mktemp("short"))
    status, _, stderr = finish(start(path))
    assert status == 0, stderr
    return file_bytes(path)


def test_resumed_files_equal_an_uninterrupted_runs_byte_for_byte(tmp_path, monkeypatch, capsys,
                                                               short_reference):
    """Not only the frames: the .traj file (no masses or charges array the run did not have)."""
    path = short_project(tmp_path)
    assert run_here(path, monkeypatch, capsys, "--steps", 20)[0] == 0
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert "resuming from step 20" in stdout
    assert file_bytes(path) == short_reference


def test_restart_from_this_directorys_trajectory_with_overwrite(tmp_path, monkeypatch, capsys):
    """--restart out/md.traj --overwrite reads the frame before removing the outputs."""
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    last = read(path / "out" / "md.traj", -1)
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--restart", "out/md.traj",
                                      "--overwrite")
    assert status == 0, stderr
    assert "removing md.traj" in stdout
    first = read(path / "out" / "md.traj", 0)
    # The start is projected onto rigid motion again: equal to roundoff.
    np.testing.assert_allclose(first.positions, last.positions, rtol=0, atol=1e-12)
    np.testing.assert_allclose(first.get_momenta(), last.get_momenta(), rtol=0, atol=1e-12)
    assert len(read(path / "out" / "md.traj", ":")) == 3


def test_overwrite_keeps_the_outputs_when_the_new_run_cannot_start(tmp_path, monkeypatch,
                                                                  capsys):
    """A dynamics that refuses to start removes nothing (it is checked on a copy first)."""
    from rigidmd.core import dynamics

    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    before = file_bytes(path)

    def refuse(atoms):
        raise ValueError("body 3 spans more than half the cell")

    monkeypatch.setattr(dynamics, "check_constraints", refuse)
    status, _, stderr = run_here(path, monkeypatch, capsys, "--overwrite")
    assert status == 2 and "body 3 spans" in stderr
    assert file_bytes(path) == before


def test_a_run_killed_before_its_first_checkpoint_resumes_without_repeats(
        tmp_path, monkeypatch, capsys, short_reference):
    """Only the step-0 checkpoint exists: frame 0 and the step-0 log line are written once."""
    from rigidmd.core.logger import RigidLogger

    path = short_project(tmp_path, checkpoint_interval=40)
    original, calls = RigidLogger.__call__, []

    def killed(self):
        calls.append(1)
        if len(calls) == 3:  # after the frame of step 20: the process dies here
            raise SystemExit(137)
        original(self)

    monkeypatch.setattr(RigidLogger, "__call__", killed)
    with pytest.raises(SystemExit):
        run_here(path, monkeypatch, capsys)
    monkeypatch.setattr(RigidLogger, "__call__", original)
    assert read_checkpoint(path / "out" / "checkpoint.npz").nsteps == 0
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert "is at step 0: starting the run again" in stdout
    assert file_bytes(path) == short_reference


def test_a_second_ctrl_c_between_a_frame_and_its_log_line(tmp_path, monkeypatch, capsys,
                                                        short_reference):
    """Stopping at once keeps the last whole checkpoint; --resume loses no log line."""
    from rigidmd.core.logger import RigidLogger

    path = short_project(tmp_path, checkpoint_interval=20)
    original, calls = RigidLogger.__call__, []

    def interrupted(self):
        calls.append(1)
        if len(calls) == 4:  # step 30: its frame is written, its log line is not
            raise KeyboardInterrupt
        original(self)

    monkeypatch.setattr(RigidLogger, "__call__", interrupted)
    status, stdout, _ = run_here(path, monkeypatch, capsys)
    monkeypatch.setattr(RigidLogger, "__call__", original)
    assert status == 130
    assert "the checkpoint of step 20 is kept" in stdout and "undone" not in stdout
    assert read_checkpoint(path / "out" / "checkpoint.npz").nsteps == 20
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert "resuming from step 20" in stdout and "cut back" in stdout
    assert file_bytes(path) == short_reference


@pytest.mark.parametrize("mode", ["--resume", "--overwrite"])
def test_resume_and_overwrite_remove_temporaries_of_a_killed_checkpoint_write(
        tmp_path, monkeypatch, capsys, mode):
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    stale = path / "out" / ".checkpoint.npz.4242-0a1b2c3d.tmp"
    stale.write_bytes(b"PK half a checkpoint")
    status, stdout, stderr = run_here(path, monkeypatch, capsys, mode, "--steps", 40)
    assert status == 0, stderr
    assert f"removed {stale.name}" in stdout
    assert sorted(p.name for p in (path / "out").iterdir()) == [
        "checkpoint.npz", "md.log", "md.traj"]


def test_demo_leaves_another_runs_checkpoint_alone(tmp_path, monkeypatch, capsys):
    """The demo into a run's directory: that run can still be resumed."""
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    checkpoint = (path / "out" / "checkpoint.npz").read_bytes()
    for _ in range(2):  # the second demo replaces the first's outputs
        assert cli.main(["demo", "--steps", "20", "--outdir", str(path / "out")]) == 0
    assert (path / "out" / "checkpoint.npz").read_bytes() == checkpoint
    capsys.readouterr()
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", 40)
    assert status == 0, stderr
    assert "resuming from step 20" in stdout


def test_demo_refuses_to_replace_another_runs_files(tmp_path, monkeypatch, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "demo.log").write_text("a log of mine\n")
    assert cli.main(["demo", "--steps", "20", "--outdir", str(tmp_path / "out")]) == 2
    assert "holds demo.log, which are not an earlier demo's" in capsys.readouterr().err
    assert (tmp_path / "out" / "demo.log").read_text() == "a log of mine\n"


def test_a_copied_run_directory_resumes(tmp_path, monkeypatch, capsys, short_reference):
    """The record compares the structure file's content, not where it lay."""
    import shutil

    path = short_project(tmp_path / "first")
    assert run_here(path, monkeypatch, capsys, "--steps", 20)[0] == 0
    copy = tmp_path / "elsewhere" / "copy"
    shutil.copytree(path, copy)
    status, stdout, stderr = run_here(copy, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert file_bytes(copy) == short_reference
    atoms = read(path / "cluster.xyz")
    atoms.positions[0, 0] += 0.01
    write(path / "cluster.xyz", atoms, format="extxyz")
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 2
    assert messages(stderr) == ["rigidmd: error: --resume: structure differs from the "
                                "checkpoint's run (only steps may change between a run and its "
                                "continuation); restore it, or start anew with --overwrite"]


@pytest.mark.parametrize("damage", ["empty", "truncated", "corrupted"])
def test_resume_from_a_damaged_checkpoint_is_one_line(tmp_path, monkeypatch, capsys, damage):
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    checkpoint = path / "out" / "checkpoint.npz"
    data = bytearray(checkpoint.read_bytes())
    if damage == "corrupted":  # a byte of the positions' data (the archive's checksum fails)
        import zipfile

        with zipfile.ZipFile(checkpoint) as archive:
            member = archive.getinfo("positions.npy")
        data[member.header_offset + 30 + len(member.filename) + len(member.extra) + 200] ^= 0xFF
    checkpoint.write_bytes(b"" if damage == "empty" else
                           bytes(data[:len(data) // 2] if damage == "truncated" else data))
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", 40)
    assert status == 2
    assert len(messages(stderr)) == 1 and "Traceback" not in stderr
    assert stderr.startswith(f"rigidmd: error: --resume: checkpoint: '{checkpoint}' is not a "
                             "readable checkpoint (")
    # The advice keeps the outputs first (--restart into another directory).
    assert stderr.rstrip().endswith(
        f"the run cannot be continued from it: start a new run from its last frame with "
        f"--restart {path / 'out' / 'md.traj'} --outdir NEW_DIRECTORY (which keeps these "
        "outputs), or start it again with --overwrite (which removes them)")


def test_resume_without_a_checkpoint_says_what_to_do(tmp_path, monkeypatch, capsys):
    """A deleted checkpoint: --overwrite (a new run would be refused), not 'without --resume'."""
    path = short_project(tmp_path, steps=20)
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 2 and "there is no run to continue" in stderr
    assert "start one without --resume" in stderr
    assert run_here(path, monkeypatch, capsys)[0] == 0
    (path / "out" / "checkpoint.npz").unlink()
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 2
    assert messages(stderr) == [
        f"rigidmd: error: --resume: there is no checkpoint {path / 'out' / 'checkpoint.npz'} "
        "beside md.traj, md.log, so that run cannot be continued; start it again with "
        "--overwrite"]


def test_a_read_only_directory_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys):
    import rigidmd.run.outputs

    path = short_project(tmp_path, steps=20)
    (path / "out").mkdir()

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", args[0])

    monkeypatch.setattr(rigidmd.run.outputs.os, "open", read_only)
    status, _, stderr = run_here(path, monkeypatch, capsys)
    assert status == 2
    assert messages(stderr) == [f"rigidmd: error: outputs.directory: cannot write in "
                                f"{path / 'out'} (the file system is read-only)"]


def test_a_full_disk_names_the_trajectory(tmp_path, monkeypatch, capsys):
    """ASE's writer raises ENOSPC without a file name: the message names md.traj."""
    from ase.io.trajectory import TrajectoryWriter

    path = short_project(tmp_path, checkpoint_interval=20)
    original, calls = TrajectoryWriter.write, []

    def full(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 4:  # step 30
            raise OSError(errno.ENOSPC, "No space left on device")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(TrajectoryWriter, "write", full)
    status, _, stderr = run_here(path, monkeypatch, capsys)
    assert status == 1
    assert messages(stderr) == [
        f"rigidmd: run stopped: cannot write {path / 'out' / 'md.traj'}: the disk is full (at "
        "step 30); the last checkpoint is intact (step 20): continue with rigidmd run run.yaml "
        "--resume"]


def test_a_failure_during_the_run_exits_1_not_2(tmp_path, monkeypatch, capsys):
    """A part that fails mid-run (a BarostatError, say) is no configuration mistake."""
    from rigidmd.couplings.barostats import BarostatError
    from rigidmd.couplings.base import COUPLINGS

    path = short_project(tmp_path, checkpoint_interval=20, thermostat="bussi")
    bussi = COUPLINGS["bussi"]
    original, calls = bussi.first_half, []

    def failing(self, view, h):
        calls.append(1)
        if len(calls) == 51:  # in step 26 (two calls a step)
            raise BarostatError("the cell collapsed")
        return original(self, view, h)

    monkeypatch.setattr(bussi, "first_half", failing)
    status, _, stderr = run_here(path, monkeypatch, capsys)
    assert status == 1
    assert messages(stderr) == [
        "rigidmd: run stopped: the cell collapsed (at step 25); the last checkpoint is intact "
        "(step 20): continue with rigidmd run run.yaml --resume"]


def test_the_summary_says_which_steps_its_statistics_cover(tmp_path, monkeypatch, capsys):
    """After --resume the summary's drift, max |E - E0| and means were of the resumed part
    only, and it did not say so (nor which steps).  Now the summary names the steps its
    statistics cover: from the run's start, or only the part since --resume, and which."""
    path = short_project(tmp_path, steps=50)
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--steps", 20)
    assert status == 0, stderr
    lines = stdout.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("20 steps"))
    assert lines[first + 1].startswith("T_tr = ")  # the temperatures of this moment
    assert lines[first + 2] == "statistics over steps 0-20 (the run from its start)"
    assert lines[first + 3].startswith("total energy: drift ")
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    lines = stdout.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("50 steps"))
    assert lines[first].startswith("50 steps (30 since --resume at step 20, ")
    assert lines[first + 2] == ("statistics over steps 30-50 only: the part run since "
                                "--resume at step 20")
    assert lines[first + 3].startswith("total energy: drift ")
