"""What defines a trajectory, for --resume (rigidmd.run.fingerprint)."""

import shlex

from ase.io import write

from rigidmd.config import check_config
from rigidmd.run.fingerprint import (
    calculator_digest,
    differing_fields,
    fingerprint,
    resume_command,
)
from rigidmd.systems import water_cluster


def config(tmp_path, **changes):
    raw = {"structure": "start.xyz", "timestep": "1 fs", "steps": 10,
           "outputs": {"directory": "out", "interval": 5}, "_base": str(tmp_path)}
    raw.update(changes)
    return check_config(raw)


def test_the_fields_that_define_the_trajectory(tmp_path):
    write(tmp_path / "start.xyz", water_cluster(2, seed=1))
    first = fingerprint(config(tmp_path))
    assert set(first) == {"structure", "read_options", "bodies", "calculator", "integrator",
                          "integrator_options", "timestep", "velocities", "outputs.interval",
                          "thermostat", "barostat"}
    assert all(len(digest) == 16 and int(digest, 16) >= 0 for digest in first.values())
    # Steps and output names do not count; the time step does.
    assert fingerprint(config(tmp_path, steps=99, outputs={"directory": "elsewhere",
                                                           "interval": 5})) == first
    changed = fingerprint(config(tmp_path, timestep="2 fs"))
    assert differing_fields(first, changed) == ["timestep"]
    assert differing_fields("0.1.0", changed) is None
    # The structure counts by its content, not its place.
    (tmp_path / "copy").mkdir()
    write(tmp_path / "copy" / "start.xyz", water_cluster(2, seed=1))
    moved = fingerprint(config(tmp_path / "copy"))
    assert differing_fields(first, moved) == []
    write(tmp_path / "start.xyz", water_cluster(2, seed=2))
    assert differing_fields(first, fingerprint(config(tmp_path))) == ["structure"]


def test_what_a_relaxation_relaxes_to_counts_and_its_steps_do_not(tmp_path):
    """A continued relaxation with another fmax or optimizer was accepted (half one
    relaxation, half another); relax.steps may be raised.  A record written before the
    fingerprint had the field is not refused for it."""
    write(tmp_path / "start.xyz", water_cluster(2, seed=1))
    relaxed = fingerprint(config(tmp_path, relax={"fmax": 0.05}))
    assert fingerprint(config(tmp_path, relax={"fmax": 0.05, "steps": 5000})) == relaxed
    other = fingerprint(config(tmp_path, relax={"fmax": 0.2, "optimizer": "FIRE"}))
    assert differing_fields(relaxed, other) == ["relax"]
    older = {k: v for k, v in relaxed.items() if k != "relax"}
    assert differing_fields(older, other) == []
    assert "relax" not in fingerprint(config(tmp_path))


def test_where_the_forces_run_is_not_what_they_are(tmp_path):
    write(tmp_path / "start.xyz", water_cluster(2, seed=1))
    water = {"name": "lammps", "water_model": {"name": "tip3p", "cutoff": 8.0}}
    here = config(tmp_path, calculator=water).calculator
    there = config(tmp_path, calculator={**water, "address": "unix:x"}).calculator
    other = config(tmp_path, calculator={**water, "water_model": {"name": "spce",
                                                                  "cutoff": 8.0}}).calculator
    assert calculator_digest(here) == calculator_digest(there) != calculator_digest(other)


def test_the_resume_command_is_quoted_for_a_shell(tmp_path):
    command = resume_command("my run.yaml", tmp_path / "out", ["--timestep", "1 fs"])
    assert shlex.split(command) == ["rigidmd", "run", "my run.yaml", "--timestep", "1 fs",
                                    "--outdir", str((tmp_path / "out").resolve()), "--resume"]
    assert resume_command(command="relax") == "rigidmd relax --resume"
