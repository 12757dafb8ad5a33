"""A ``rigidmd run`` killed outright (SIGKILL) while its ``relax:`` section relaxes.

A signal lets the run write its checkpoint; SIGKILL (or a node lost) does not.
The checkpoint that records the relaxation is therefore written before it
begins, and ``--resume`` continues the relaxation from the last whole frame of
its trajectory, then runs the MD.  Before, the run left ``relax.traj`` and
``relax.log`` with no checkpoint, ``--resume`` refused, and the only way on was
``--overwrite``: every frame relaxed so far was lost.
"""

import numpy as np
from ase.calculators.tip3p import TIP3P
from ase.io import read
from helpers import RELAX_CONFIG, finish, start, start_cli_run, wait_for_lines

from rigidmd.relax.filter import RigidFilter

# 64 waters to fmax 2e-5 eV/Å: about 370 FIRE steps (2-3 s here), so the kill after 20
# lines of the relaxation's log lands in it, and what is left takes a few seconds.
CONFIG = RELAX_CONFIG.replace("n_molecules: 6", "n_molecules: 64").replace(
    "fmax: 0.01, steps: STEPS", "fmax: 0.00002, steps: 5000")


def test_a_run_killed_while_relaxing_resumes_the_relaxation(tmp_path):
    out = tmp_path / "out"
    proc = start_cli_run(tmp_path, CONFIG)
    wait_for_lines(out / "relax.log", 20, proc)
    proc.kill()
    proc.wait(timeout=60)
    assert not (out / "md.traj").exists(), "the relaxation ended before the kill"
    frames = read(out / "relax.traj", ":")
    assert len(frames) >= 20
    # A plain start again is refused and replaces nothing; --resume continues.
    status, _, err = finish(start(tmp_path))
    assert status == 2 and "continue it with --resume" in err
    status, said, err = finish(start(tmp_path, "--resume"))
    assert status == 0, err
    assert f"continuing the relaxation of {out / 'relax.traj'} after step " \
           f"{len(frames) - 1}" in said
    resumed = read(out / "relax.traj", ":")
    assert len(resumed) > len(frames)
    for a, b in zip(frames, resumed[:len(frames)], strict=True):  # kept, not rewritten
        np.testing.assert_array_equal(a.positions, b.positions)
    last = resumed[-1]
    last.calc = TIP3P(rc=40.0)
    assert np.linalg.norm(RigidFilter(last, bodies="tags").get_forces(), axis=1).max() < 2e-5
    md = read(out / "md.traj", ":")
    assert len(md) == 3
    np.testing.assert_allclose(md[0].positions, last.positions, rtol=0, atol=1e-9)


def test_a_run_killed_before_its_first_relaxed_frame_starts_again(tmp_path):
    """The relaxation's checkpoint is there but its trajectory holds no whole frame (killed
    between the two): --resume starts the run again instead of refusing."""
    out = tmp_path / "out"
    proc = start_cli_run(tmp_path, CONFIG)
    wait_for_lines(out / "relax.log", 1, proc)
    proc.kill()
    proc.wait(timeout=60)
    (out / "relax.traj").write_bytes(b"")  # as if killed before the first frame
    status, said, err = finish(start(tmp_path, "--resume"))
    assert status == 0, err
    assert "the relaxation had written no frame of relax.traj: starting the run again" in said
    assert len(read(out / "md.traj", ":")) == 3


def test_a_damaged_relaxation_trajectory_is_named_and_kept(tmp_path):
    """--resume after a kill with a trajectory that cannot be read: one line naming it, and
    nothing is replaced (the run does not start again over the relaxation's outputs)."""
    out = tmp_path / "out"
    proc = start_cli_run(tmp_path, CONFIG)
    wait_for_lines(out / "relax.log", 1, proc)
    proc.kill()
    proc.wait(timeout=60)
    (out / "relax.traj").write_bytes(b"not a trajectory")
    status, _, err = finish(start(tmp_path, "--resume"))
    assert status == 2 and f"cannot read {out / 'relax.traj'}" in err, err
    assert (out / "relax.traj").read_bytes() == b"not a trajectory"
    assert (out / "checkpoint.npz").exists() and not (out / "md.traj").exists()

