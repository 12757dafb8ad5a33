"""An output directory's lock, output lengths for a resume, inputs kept apart
(rigidmd.run.outputs).  Whole runs that resume are in ``test_runner.py``."""

import errno
import json
import os
import socket
import subprocess
import sys

import pytest
from ase.io import Trajectory, read

from rigidmd.run.outputs import (
    LOCK_NAME,
    OutputError,
    OutputLock,
    check_apart_from_inputs,
    describe_os_error,
    output_lengths,
    trim_outputs,
)
from rigidmd.systems import water_cluster


def test_one_run_holds_a_directory(tmp_path):
    with OutputLock(tmp_path) as lock:
        record = json.loads((tmp_path / LOCK_NAME).read_text())
        assert record == {"pid": os.getpid(), "host": socket.gethostname()}
        assert lock.stale is None
    assert not (tmp_path / LOCK_NAME).exists()
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": other.pid,
                                                      "host": socket.gethostname()}))
        with pytest.raises(OutputError, match=f"is in use by process {other.pid}"):
            OutputLock(tmp_path).acquire()
    finally:
        other.kill()
        other.wait()
    lock = OutputLock(tmp_path).acquire()  # the holder died: taken over
    assert lock.stale == {"pid": other.pid, "host": socket.gethostname()}
    lock.release()


def test_a_lock_of_another_host_is_not_guessed(tmp_path):
    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": 1, "host": "node-elsewhere"}))
    with pytest.raises(OutputError, match="locked by process 1 on host 'node-elsewhere', "
                                          "which this machine"):
        OutputLock(tmp_path).acquire()


def test_outputs_are_cut_back_to_their_checkpoint(tmp_path):
    files = {"trajectory": tmp_path / "md.traj", "log": tmp_path / "md.log",
             "later": tmp_path / "later.txt"}
    with Trajectory(files["trajectory"], "w") as traj:
        traj.write(water_cluster(2, seed=1))
    files["log"].write_text("line 1\n")
    lengths = output_lengths(files)
    assert lengths["later"] == {"size": 0}  # later.txt does not exist yet
    assert lengths["log"] == {"size": 7} and lengths["trajectory"]["nitems"] == 1
    with Trajectory(files["trajectory"], "a") as traj:
        traj.write(water_cluster(2, seed=2))
    files["log"].write_text("line 1\nline 2\n")
    files["later"].write_text("written after the checkpoint\n")
    trim_outputs(files, lengths)
    assert len(read(files["trajectory"], ":")) == 1
    assert files["log"].read_text() == "line 1\n" and not files["later"].exists()
    files["log"].write_text("")
    with pytest.raises(OutputError, match=r"outputs.log: .* is shorter than at the checkpoint "
                                          r"\(0 < 7 bytes\).*or copy it back"):
        trim_outputs(files, lengths, advice="or copy it back")


def test_an_output_the_checkpoint_did_not_write_is_kept_and_refused(tmp_path):
    """The MDAnalysis pass: an output left out of the configuration for one resumed segment
    and given again was deleted on the next --resume, with the frames before the gap."""
    files = {"log": tmp_path / "md.log"}
    files["log"].write_text("line 1\n")
    lengths = output_lengths({})  # a checkpoint of a segment run without outputs.log
    with pytest.raises(OutputError, match=r"outputs.log: .*md.log was not written up to the "
                                          r"checkpoint \(outputs.log was not given"):
        trim_outputs(files, lengths)
    assert files["log"].read_text() == "line 1\n"


def test_an_output_on_an_input_is_refused(tmp_path):
    config = tmp_path / "run.yaml"
    config.write_text("steps: 1\n")
    check_apart_from_inputs({"log": tmp_path / "md.log"}, {"configuration": config})
    with pytest.raises(OutputError, match="outputs.log: .* is also the configuration this run "
                                          "reads"):
        check_apart_from_inputs({"outputs.log": tmp_path / "out" / ".." / "run.yaml"},
                                {"configuration": config, "restart": None})
    check_apart_from_inputs({"trajectory": config}, {"restart": config},
                            allowed={("trajectory", "restart")})


def test_os_errors_in_one_line():
    full = OSError(errno.ENOSPC, "No space left on device", "md.traj")
    assert describe_os_error(full) == "cannot write md.traj: the disk is full"
    assert describe_os_error(OSError(errno.EACCES, "x"), "log") == ("cannot write log: "
                                                                    "permission denied")
    assert describe_os_error(OSError(errno.EIO, "I/O error")) == ("cannot write an output "
                                                                   "file: I/O error")
