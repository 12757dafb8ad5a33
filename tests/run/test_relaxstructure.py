"""A configuration's ``relax:`` section relaxing a structure into its directory
(rigidmd.run.relaxstructure).  The ``rigidmd relax`` command around it is in
``test_command.py``; continuing from a stopped relaxation in ``test_state.py``."""

import io
from pathlib import Path

import pytest
from ase.calculators.tip3p import TIP3P
from ase.io import read

from rigidmd import RigidBodies
from rigidmd.config import RelaxSection
from rigidmd.run.relaxstructure import (
    RelaxationNotConverged,
    RelaxationStopped,
    RelaxProgress,
    relax_structure,
    state_path,
)
from rigidmd.systems import water_cluster


def section(**fields):
    return RelaxSection.from_config({"relax": fields})


def cluster():
    atoms = water_cluster(4, seed=3)
    atoms.calc = TIP3P(rc=20.0)
    return atoms


def test_a_relaxation_writes_its_trajectory_and_log(tmp_path):
    atoms = cluster()
    start = atoms.get_potential_energy()
    out = io.StringIO()
    result = relax_structure(atoms, RigidBodies.resolve(atoms), section(fmax="0.05 eV/A"),
                             tmp_path / "out", out, progress=io.StringIO())
    assert result.converged and atoms.get_potential_energy() < start
    frames = read(tmp_path / "out" / "relax.traj", ":")
    assert len(frames) == result.steps + 1
    assert frames[-1].get_potential_energy() == pytest.approx(atoms.get_potential_energy())
    assert (tmp_path / "out" / "relax.log").read_text().strip()
    assert not state_path(tmp_path / "out" / "relax.traj").exists()  # converged: no state


def test_a_relaxation_that_runs_out_of_steps(tmp_path):
    atoms = cluster()
    with pytest.raises(RelaxationNotConverged):
        relax_structure(atoms, RigidBodies.resolve(atoms), section(fmax=1e-6, steps=2),
                        tmp_path, io.StringIO(), progress=io.StringIO())
    assert len(read(tmp_path / "relax.traj", ":")) == 3


def test_the_state_file_and_the_progress_line():
    assert state_path(Path("out/relax.traj")) == Path("out/relax.state.npz")
    stream = io.StringIO()
    progress = RelaxProgress(100, fmax=0.05, stream=stream)
    progress(10, -1.5, 0.3)
    progress(11, -1.6, 0.2)  # neither a tenth step nor converged: no line
    progress(12, -1.7, 0.01)  # converged: a line
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("relax step  10/100  energy -1.500000 eV  fmax 0.3000 eV/Å "
                               "(target 0.05)")
    assert RelaxationStopped("stopped", 143).status == 143
