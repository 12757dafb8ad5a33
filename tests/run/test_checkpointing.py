"""The checkpoints of one run, and the one a resumed run continues
(rigidmd.run.checkpointing)."""

import io

import pytest
from ase.calculators.tip3p import TIP3P
from ase.io import write

from rigidmd import RigidVerlet
from rigidmd.config import ConfigError, check_config
from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.run.checkpointing import RunCheckpoints
from rigidmd.run.directory import RunFiles
from rigidmd.systems import water_cluster


def setup(tmp_path, timestep="1 fs"):
    write(tmp_path / "start.xyz", water_cluster(2, seed=1))
    config = check_config({"structure": "start.xyz", "timestep": timestep, "steps": 6,
                           "outputs": {"directory": "out", "log": "md.log", "interval": 2},
                           "_base": str(tmp_path)})
    files = RunFiles(config.outputs, "resume", io.StringIO())
    return config, files, RunCheckpoints(config, files, io.StringIO())


def test_a_checkpoint_records_the_outputs_and_the_fingerprint(tmp_path):
    config, files, checkpoints = setup(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "md.log").write_text("a line\n")
    atoms = config.structure.build_atoms()
    atoms.calc = TIP3P()
    dyn = RigidVerlet(atoms, config.run.timestep)
    dyn.run(2)
    checkpoints.write(dyn)
    assert checkpoints.step == 2
    saved = read_checkpoint(config.outputs.checkpoint)
    assert saved.extra["outputs"] == {"log": {"size": 7}}
    assert saved.extra["fingerprint"] == checkpoints.fingerprint and saved.extra["steps"] == 6
    assert checkpoints.is_earlier_demo()
    assert checkpoints.read_for_resume().meta["nsteps"] == 2
    _, _, other = setup(tmp_path, timestep="2 fs")
    assert not other.is_earlier_demo()
    with pytest.raises(ConfigError, match="timestep"):
        other.read_for_resume()


def test_nothing_to_resume_says_what_to_do(tmp_path):
    _, _, checkpoints = setup(tmp_path)
    with pytest.raises(ConfigError, match="--resume: there is no run to continue in .*out "
                                          r"\(no checkpoint.npz\); start one without --resume"):
        checkpoints.read_for_resume()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "md.log").write_text("a line\n")
    with pytest.raises(ConfigError, match="there is no checkpoint .* beside md.log, so that run "
                                          "cannot be continued"):
        checkpoints.read_for_resume()
    (tmp_path / "out" / "checkpoint.npz").write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="--resume: .*the run cannot be continued from it"):
        checkpoints.read_for_resume()
