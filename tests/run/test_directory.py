"""The output files of one run in its directory (rigidmd.run.directory)."""

import io

import pytest

from rigidmd.config import ConfigError, RelaxSection
from rigidmd.config.sections import OutputsSection
from rigidmd.run.directory import RunFiles
from rigidmd.run.outputs import LOCK_NAME


def outputs(tmp_path, **extra):
    return OutputsSection.from_config({"outputs": {"directory": "out", "trajectory": "md.traj",
                                                   "log": "md.log", **extra}}, tmp_path)


def test_the_files_of_a_run(tmp_path):
    files = RunFiles(outputs(tmp_path, plot="e.png"), "new", io.StringIO(),
                     relax=RelaxSection.from_config({"relax": {}}))
    out = tmp_path / "out"
    assert files.appended() == {"trajectory": out / "md.traj", "log": out / "md.log"}
    assert files.all() == [out / "relax.traj", out / "relax.log", out / "md.traj",
                           out / "md.log", out / "e.png", out / "checkpoint.npz"]
    named = files.named()
    assert named["outputs.trajectory"] == out / "md.traj"
    assert named["the lock file"] == out / LOCK_NAME
    assert {"relax.trajectory", "relax.log", "relax state"} <= set(named)


def test_a_new_run_refuses_an_earlier_runs_outputs(tmp_path):
    files = RunFiles(outputs(tmp_path), "new", io.StringIO())
    lock = files.open()
    assert files.made_directories and (tmp_path / "out" / LOCK_NAME).exists()
    (tmp_path / "out" / "md.log").write_text("earlier\n")
    # No checkpoint beside it: --resume could only refuse, so it is not offered.
    with pytest.raises(ConfigError, match="already holds md.log from an earlier run; nothing "
                                          "there can be continued"):
        files.prepare(earlier_demo=lambda: False)
    (tmp_path / "out" / "checkpoint.npz").write_bytes(b"a run's")
    with pytest.raises(ConfigError, match="already holds md.log, checkpoint.npz from an earlier "
                                          "run; continue it with --resume, or replace it with "
                                          "--overwrite"):
        files.prepare(earlier_demo=lambda: False)
    lock.release()
    demo = RunFiles(outputs(tmp_path), "demo", io.StringIO())
    with pytest.raises(ConfigError, match="holds md.log, checkpoint.npz, which are not an earlier "
                                          "demo's"):
        demo.prepare(earlier_demo=lambda: False)


def test_a_run_that_never_started_leaves_nothing(tmp_path):
    stream = io.StringIO()
    files = RunFiles(outputs(tmp_path), "new", stream)
    lock = files.open()
    (tmp_path / "out" / "md.log").write_text("header\n")
    files.created.append(tmp_path / "out" / "md.log")
    files.abandon(lock, started=False)
    assert "the run did not start: removed md.log, which it had opened" in stream.getvalue()
    assert not (tmp_path / "out").exists()


def test_the_advice_keeps_a_trajectory_first(tmp_path):
    files = RunFiles(outputs(tmp_path), "resume", io.StringIO())
    assert files.fresh_start_advice() == "start it again with --overwrite (which removes them)"
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "md.traj").write_bytes(b"")
    assert files.fresh_start_advice().startswith(
        f"start a new run from its last frame with --restart {tmp_path / 'out' / 'md.traj'}")


def test_a_run_that_never_started_removes_exactly_the_directories_it_made(tmp_path):
    """``outputs.directory: a/b/c`` was made with its parents, and only ``c`` removed when
    the run could not start (a calculator refused): a/ and a/b/ were left behind."""
    (tmp_path / "keep").mkdir()
    section = OutputsSection.from_config({"outputs": {"directory": "keep/a/b/c",
                                                       "log": "md.log"}}, tmp_path)
    files = RunFiles(section, "new", io.StringIO())
    lock = files.open()
    assert (tmp_path / "keep/a/b/c" / LOCK_NAME).exists()
    files.abandon(lock, started=False)
    assert (tmp_path / "keep").is_dir() and not any((tmp_path / "keep").iterdir())
    # A run that had started keeps its outputs, and so the directories above them.
    files = RunFiles(section, "new", io.StringIO())
    lock = files.open()
    (tmp_path / "keep/a/b/c/md.log").write_text("step 0\n")
    files.abandon(lock, started=True)
    assert (tmp_path / "keep/a/b/c/md.log").is_file()
    # A directory that was there before is not the run's to remove.
    (tmp_path / "keep/a/b/c/md.log").unlink()
    files = RunFiles(section, "new", io.StringIO())
    lock = files.open()
    assert not files.made_directories
    files.abandon(lock, started=False)
    assert (tmp_path / "keep/a/b/c").is_dir()
