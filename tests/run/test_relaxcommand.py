"""``rigidmd relax`` and a configuration's ``relax:`` section as product paths: the command,
its errors, signals, --resume, and export-lammps from the relaxed structure."""

import numpy as np
import pytest
from ase.calculators.tip3p import TIP3P
from helpers import RELAX_CONFIG, tip3p_calls

from rigidmd.relax.filter import RigidFilter
from rigidmd.systems import water_cluster


def rigidmd(*args, cwd):
    import os
    import subprocess
    import sys

    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "rigidmd.run.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)


def test_relax_command_and_relax_section_before_md(tmp_path):
    from ase.io import read

    (tmp_path / "relax.yaml").write_text(RELAX_CONFIG.replace("STEPS", "2000"))
    result = rigidmd("relax", "relax.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "relaxed RigidBodies(n_bodies=6" in result.stdout
    frames = read(tmp_path / "out" / "relax.traj", ":")
    last = frames[-1]
    last.calc = TIP3P(rc=40.0)
    generalized = RigidFilter(last, bodies="tags").get_forces()  # frames carry bodies in tags
    assert np.linalg.norm(generalized, axis=1).max() < 0.01
    assert "FIRE:" in (tmp_path / "out" / "relax.log").read_text()
    assert not (tmp_path / "out" / "md.traj").exists()
    # Into the relaxation's folder without a flag: --resume is not offered (it only refused:
    # no checkpoint), --overwrite is (the new-user pass).
    result = rigidmd("run", "relax.yaml", cwd=tmp_path)
    assert result.returncode == 2 and "nothing there can be continued (no checkpoint: a " \
        "relaxation by rigidmd relax" in result.stderr and "--resume" not in result.stderr
    # rigidmd run: relaxes, then MD from the relaxed structure.
    result = rigidmd("run", "relax.yaml", "--overwrite", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    md = read(tmp_path / "out" / "md.traj", ":")
    assert np.abs(md[0].positions - last.positions).max() < 1e-9
    assert md[0].get_kinetic_energy() > 0


def test_relaxation_short_of_its_steps_is_one_line_and_keeps_the_structure(tmp_path):
    from ase.io import read

    (tmp_path / "relax.yaml").write_text(RELAX_CONFIG.replace("STEPS", "3"))
    result = rigidmd("run", "relax.yaml", cwd=tmp_path)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()  # progress lines, then one line for the stop
    assert "did not reach fmax 0.01 eV/Å in 3 steps" in lines[-1] and "Traceback" not in \
        result.stderr
    assert lines[-1].endswith("raise relax.steps and continue with: rigidmd run relax.yaml "
                              "--resume")  # the relaxation, then the MD
    assert all(line.startswith("relax step ") for line in lines[:-1])
    assert len(read(tmp_path / "out" / "relax.traj", ":")) == 4  # start and 3 steps
    assert not (tmp_path / "out" / "md.traj").exists()


@pytest.mark.parametrize("relax_section, message", [
    ("{fmax: -1}", "relax.fmax: must be positive"),
    ("{optimizer: Newton}", "relax.optimizer: 'Newton' is not one of"),
    ("{cell: cubic}", "relax.cell: expected false, true or one of"),
    ("{pressure: 1 bar}", "relax.pressure: a target pressure needs relax.cell"),
    ("{cell: iso}", "relax.cell: iso relaxes the cell, which needs a structure periodic in all "
                    "three directions"),
    ("{tol: 1}", "relax.tol: unknown key"),
])
def test_relax_section_errors_are_one_line(tmp_path, relax_section, message):
    text = RELAX_CONFIG.replace("{fmax: 0.01, steps: STEPS, optimizer: FIRE}", relax_section)
    (tmp_path / "relax.yaml").write_text(text)
    result = rigidmd("relax", "relax.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert message in result.stderr


def test_relax_section_refuses_a_restart_before_touching_the_outputs(tmp_path):
    from ase.io import write

    write(tmp_path / "start.traj", water_cluster(6, seed=2))
    text = RELAX_CONFIG.replace("STEPS", "10") + "restart: start.traj\n"
    (tmp_path / "relax.yaml").write_text(text)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "md.traj").write_text("earlier run")
    result = rigidmd("run", "relax.yaml", "--overwrite", cwd=tmp_path)
    assert result.returncode == 2
    assert "relax: a restart continues a run's dynamics" in result.stderr
    assert (tmp_path / "out" / "md.traj").read_text() == "earlier run"


# ---------------------------------------------------------------- rigidmd relax as a product path
def relax_config(tmp_path, steps=2000, structure="{builtin: water_cluster, n_molecules: 6, "
                 "seed: 2}"):
    text = RELAX_CONFIG.replace("STEPS", str(steps)).replace(
        "{builtin: water_cluster, n_molecules: 6, seed: 2}", structure).replace(
        ", optimizer: FIRE", "")
    path = tmp_path / "relax.yaml"
    path.write_text(text)
    from rigidmd.config import load_config

    return load_config(path)


def signal_at_call(monkeypatch, n, *signums):
    """Send ``signums`` to this process at the ``n``-th generalized force call."""
    import os

    original, calls = signal_at_call.original, []

    def get_forces(self, **kwargs):
        calls.append(1)
        if len(calls) == n:
            for signum in signums:
                os.kill(os.getpid(), signum)
        return original(self, **kwargs)

    monkeypatch.setattr(RigidFilter, "get_forces", get_forces)


signal_at_call.original = RigidFilter.get_forces


def test_rigidmd_relax_says_how_to_continue_as_a_command_a_shell_runs(tmp_path, monkeypatch):
    """The continue hint of rigidmd relax is rigidmd run's (one source): the output directory
    absolute and quoted for a shell, and --trust repeated when it was given (it was
    ``rigidmd relax CONFIG --outdir DIR --resume`` unquoted, without --trust)."""
    import io
    import shlex
    import signal

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    raw["outputs"]["directory"] = "my out"
    signal_at_call(monkeypatch, 2, signal.SIGTERM)
    out = io.StringIO()
    assert relax_only(raw, out, trust=True, config_path="relax.yaml") == 143
    hint = out.getvalue().strip().splitlines()[-1].rpartition("continue with: ")[2]
    assert shlex.split(hint) == ["rigidmd", "relax", "relax.yaml", "--trust", "--outdir",
                                 str((tmp_path / "my out").resolve()), "--resume"]


@pytest.mark.parametrize("signums, status, said", [
    (("SIGTERM",), 143, "stopped by SIGTERM"), (("SIGINT",), 130, "stopped by SIGINT"),
    (("SIGINT", "SIGINT"), 130, "interrupted at once (second Ctrl-C)")])
def test_a_signal_stops_rigidmd_relax_after_a_step_and_resume_finishes(
        tmp_path, monkeypatch, signums, status, said):
    """Issue 34 item 9: the stop finishes the step and its frame, says how to continue and
    exits 143/130 (a second Ctrl-C too, without a traceback); --resume continues from the
    last frame, appending.  Issue 36: after a stop signal it continues with the optimizer's
    memory (relax.state.npz), taking the steps of the uninterrupted relaxation: the same
    frames bit for bit and the same force calls in all; after a second Ctrl-C (no whole
    step, no state) it says that the memory starts afresh and reaches a minimum."""
    import io
    import signal

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    reference = tmp_path / "reference"
    reference.mkdir()
    calls = tip3p_calls(monkeypatch)
    assert relax_only(relax_config(reference), io.StringIO()) == 0
    uninterrupted, uninterrupted_calls = read(reference / "out" / "relax.traj", ":"), len(calls)
    assert not (reference / "out" / "relax.state.npz").exists()  # removed once converged
    calls.clear()

    signal_at_call(monkeypatch, 12, *(getattr(signal, name) for name in signums))
    out = io.StringIO()
    assert relax_only(raw, out, config_path="relax.yaml") == status
    message = out.getvalue().strip().splitlines()[-1]
    assert said in message
    assert message.endswith(f"continue with: rigidmd relax relax.yaml --outdir "
                            f"{tmp_path / 'out'} --resume")
    frames = read(tmp_path / "out" / "relax.traj", ":")
    assert 2 <= len(frames) < len(uninterrupted)  # the start, and at least one step
    from rigidmd.run.outputs import LOCK_NAME

    assert not (tmp_path / "out" / LOCK_NAME).exists()
    once = len(signums) == 1  # a whole step: the state is written
    assert (tmp_path / "out" / "relax.state.npz").exists() == once
    monkeypatch.setattr(RigidFilter, "get_forces", signal_at_call.original)
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    calls_in_all = len(calls)  # both parts of the relaxation
    assert f"after step {len(frames) - 1}" in out.getvalue()
    resumed = read(tmp_path / "out" / "relax.traj", ":")
    for a, b in zip(frames, resumed[:len(frames)], strict=True):  # appended, nothing rewritten
        np.testing.assert_array_equal(a.positions, b.positions)
    if once:
        assert "continuing with the optimizer's memory" in out.getvalue()
        assert len(resumed) == len(uninterrupted) and calls_in_all == uninterrupted_calls
        for a, b in zip(uninterrupted, resumed, strict=True):
            np.testing.assert_array_equal(a.positions, b.positions)
    last = resumed[-1]
    last.calc = TIP3P(rc=40.0)
    assert np.linalg.norm(RigidFilter(last, bodies="tags").get_forces(), axis=1).max() < 0.01
    if not once:
        assert "the optimizer's memory starts afresh: no " in out.getvalue()
        # A fresh memory need not follow the uninterrupted path (measured: -2.07150 eV
        # against -2.07111 eV, two minima of the 6-water cluster); it goes downhill.
        stopped_at = frames[-1]
        stopped_at.calc = TIP3P(rc=40.0)
        assert last.get_potential_energy() < stopped_at.get_potential_energy()


@pytest.mark.parametrize("signame, status", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_run_stopped_while_relaxing_resumes_the_relaxation_then_the_md(
        tmp_path, monkeypatch, capsys, signame, status):
    """``rigidmd run`` with a relax: section, stopped during its relaxation, said to start
    again with --overwrite (relaxing again from the structure).  Now it says the exact
    --resume command, which continues the relaxation from its last frame (appending to
    its trajectory) and then runs the MD from the relaxed structure."""
    import shlex
    import signal

    from ase.io import read

    from rigidmd.run.cli import main

    config = tmp_path / "relax.yaml"
    config.write_text(RELAX_CONFIG.replace("STEPS", "2000").replace(", optimizer: FIRE", ""))
    out = tmp_path / "out"
    signal_at_call(monkeypatch, 12, getattr(signal, signame))
    assert main(["run", str(config)]) == status
    said = capsys.readouterr().out.strip().splitlines()[-1]
    assert said.startswith(f"relax: stopped by {signame}; the structure reached is the last "
                           f"frame of {out / 'relax.traj'}; continue with: rigidmd run "), said
    hint = said.split("continue with: ")[1]
    assert "--resume" in hint and "--overwrite" not in hint
    frames = read(out / "relax.traj", ":")
    assert 2 <= len(frames) < 30 and not (out / "md.traj").exists()
    stopped = (out / "relax.traj").read_bytes()
    # A plain run again is refused, and replaces nothing.
    assert main(["run", str(config)]) == 2
    assert "already holds relax.traj, relax.log, checkpoint.npz" in capsys.readouterr().err
    assert (out / "relax.traj").read_bytes() == stopped
    monkeypatch.undo()
    assert main(shlex.split(hint)[1:]) == 0
    said = capsys.readouterr().out
    assert f"continuing the relaxation of {out / 'relax.traj'} after step {len(frames) - 1}" \
        in said
    resumed = read(out / "relax.traj", ":")
    for a, b in zip(frames, resumed[:len(frames)], strict=True):  # appended, nothing rewritten
        np.testing.assert_array_equal(a.positions, b.positions)
    last = resumed[-1]
    last.calc = TIP3P(rc=40.0)
    assert np.linalg.norm(RigidFilter(last, bodies="tags").get_forces(), axis=1).max() < 0.01
    md = read(out / "md.traj", ":")
    assert len(md) == 3  # steps 0, 10 and 20
    np.testing.assert_allclose(md[0].positions, last.positions, rtol=0, atol=1e-9)
    assert md[0].get_kinetic_energy() > 0  # velocities drawn for the relaxed bodies


def test_rigidmd_relax_never_deletes_its_input(tmp_path):
    """Issue 34 item 8: continuing from the relaxation's own relax.traj as a structure deleted
    it before the first frame; now that is refused (naming --resume) and the file is kept,
    an earlier relaxation is replaced only with --overwrite, and --resume continues it."""
    import io

    from ase.io import read

    from rigidmd.config.quantities import ConfigError
    from rigidmd.run.outputs import OutputError
    from rigidmd.run.relaxcommand import relax_only
    from rigidmd.run.relaxstructure import RelaxationNotConverged

    with pytest.raises(RelaxationNotConverged, match="raise relax.steps and continue with"):
        relax_only(relax_config(tmp_path, steps=5), io.StringIO())
    traj = tmp_path / "out" / "relax.traj"
    before = traj.read_bytes()
    stopped = read(traj, ":")
    own = relax_config(tmp_path, structure="out/relax.traj")
    for mode in ("new", "overwrite"):
        with pytest.raises(ConfigError, match="is this relaxation's own trajectory; continue "
                                              "it with --resume"):
            relax_only(own, io.StringIO(), mode=mode)
        assert traj.read_bytes() == before
    with pytest.raises(OutputError, match="holds an earlier relaxation; continue it with "
                                          "--resume or replace it with --overwrite"):
        relax_only(relax_config(tmp_path), io.StringIO())
    assert traj.read_bytes() == before
    assert relax_only(own, io.StringIO(), mode="resume") == 0
    resumed = read(traj, ":")
    assert len(stopped) == 6 and len(resumed) > 6
    for a, b in zip(stopped, resumed[:6], strict=True):  # earlier frames kept, new appended
        np.testing.assert_array_equal(a.positions, b.positions)


def test_export_lammps_starts_from_the_relaxed_structure(tmp_path):
    """Issue 34 item 5: the deck started from the unrelaxed structure; with a relax: section
    export-lammps relaxes as rigidmd run does and writes the relaxed positions."""
    from ase.io import read

    (tmp_path / "relax.yaml").write_text(RELAX_CONFIG.replace("STEPS", "2000"))
    result = rigidmd("export-lammps", "relax.yaml", "deck", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "relaxed RigidBodies(n_bodies=6" in result.stdout
    relaxed = read(tmp_path / "deck" / "relax.traj")
    lines = (tmp_path / "deck" / "data.rigidmd").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Atoms")) + 2
    rows = [line.split() for line in lines[start:start + len(relaxed)]]
    order = np.array([int(row[0]) for row in rows]) - 1
    positions = np.array([[float(v) for v in row[4:7]] for row in rows])[np.argsort(order)]
    # The data file's positions carry 8 decimals or more (measured gap 5e-9 Å).
    assert np.abs(positions - relaxed.positions).max() < 1e-6
    unrelaxed = water_cluster(6, seed=2).positions
    assert np.abs(positions - unrelaxed).max() > 0.05


def run_signalled_after_relaxation(tmp_path, signame, argv):
    """``rigidmd ARGV`` in a process of its own, sent ``signame`` in the moment after the
    relaxation converged (its own handlers gone, the command not yet ended)."""
    import os
    import subprocess
    import sys
    import textwrap

    script = tmp_path / "late_signal.py"
    script.write_text(textwrap.dedent(f"""
        import os, signal, sys
        from rigidmd.run.relaxstructure import RelaxProgress
        finish = RelaxProgress.finish
        def late(self):  # after the relaxation's own handlers are gone
            finish(self)
            os.kill(os.getpid(), signal.{signame})
        RelaxProgress.finish = late
        from rigidmd.run.cli import main
        sys.exit(main({argv!r}))
    """))
    (tmp_path / "relax.yaml").write_text(RELAX_CONFIG.replace("STEPS", "2000"))
    return subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, env=dict(os.environ, PYTHONUNBUFFERED="1"))


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGINT"])
def test_a_signal_just_after_export_lammps_relaxation_is_noted_and_the_deck_written(
        tmp_path, signame):
    """A signal in the moment after export-lammps's relaxation converged (its handlers
    gone, the deck not yet written) killed the command without a word (exit -15, -2), the
    deck's files maybe half written.  Now it is noted: the deck is written whole, the
    command says so and exits 0."""
    result = run_signalled_after_relaxation(tmp_path, signame, ["export-lammps", "relax.yaml",
                                                                "deck"])
    assert result.returncode == 0, (result.returncode, result.stderr)
    assert result.stdout.strip().splitlines()[-1] == (
        f"export-lammps: {signame} arrived after the relaxation had ended; the deck is "
        "complete")
    assert "Traceback" not in result.stderr
    assert (tmp_path / "deck" / "in.rigidmd").stat().st_size > 0
    assert "Atoms" in (tmp_path / "deck" / "data.rigidmd").read_text()


def test_relax_log_continues_its_step_count_on_resume(tmp_path):
    """``rigidmd relax --resume`` appended to relax.log a second header and steps counted
    from 0 again (the initial point logged twice); now the log reads as one relaxation: one
    header, the steps 0, 1, 2, ... each once, the last equal to the trajectory's frames less
    one, and the summary counts the steps of both parts."""
    import io

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only
    from rigidmd.run.relaxstructure import RelaxationNotConverged

    with pytest.raises(RelaxationNotConverged):
        relax_only(relax_config(tmp_path, steps=5), io.StringIO())
    out = io.StringIO()
    assert relax_only(relax_config(tmp_path, steps=2000), out, mode="resume") == 0
    lines = (tmp_path / "out" / "relax.log").read_text().splitlines()
    headers = [line for line in lines if "Step" in line]
    steps = [int(line.split()[1]) for line in lines if "Step" not in line]
    assert len(headers) == 1
    frames = read(tmp_path / "out" / "relax.traj", ":")
    assert steps == list(range(len(frames))), steps
    assert f"in {len(frames) - 1} steps" in out.getvalue()
def test_rigidmd_relax_refuses_a_log_on_its_configuration(tmp_path):
    """Issue 45 item 13: the relaxation's log was not checked against the inputs
    (``relax: {log: ../relax.yaml}`` with --trust, which allows a path outside the
    directory, replaced the configuration); it is refused before anything is written,
    naming the field."""
    import io

    from rigidmd.run.outputs import OutputError
    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    raw["relax"]["log"] = "../relax.yaml"
    before = (tmp_path / "relax.yaml").read_bytes()
    with pytest.raises(OutputError, match=r"^relax.log: .*relax.yaml is also the configuration "
                                          "this run reads"):
        relax_only(raw, io.StringIO(), trust=True, config_path=str(tmp_path / "relax.yaml"))
    assert (tmp_path / "relax.yaml").read_bytes() == before
    assert not (tmp_path / "out").exists()


def fail_in_step(monkeypatch, cls, n):
    """Make the optimizer ``cls`` move its atoms to a trial point and raise in step ``n``, as
    ASE's line searches do when they find no descent."""
    original, steps = cls.step, []

    def step(self, *args, **kwargs):
        steps.append(1)
        if len(steps) == n:
            self.optimizable.set_x(self.optimizable.get_x() + 0.05)  # a trial point
            raise RuntimeError("LineSearch failed!")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(cls, "step", step)


def test_an_optimizer_s_exception_is_one_line_with_the_structure_reached(
        tmp_path, monkeypatch, capsys):
    """Issue 45 item 18: ASE's line search raising RuntimeError (PreconLBFGS with a cell)
    ended rigidmd relax and rigidmd run with a traceback; now one line that names the step,
    the structure reached (the last frame, where the atoms are back) and the command that
    continues, exit status 1."""
    from ase.io import read
    from ase.optimize.precon import PreconLBFGS

    from rigidmd.run.cli import main

    config = tmp_path / "relax.yaml"
    config.write_text(RELAX_CONFIG.replace("STEPS", "2000").replace("FIRE", "PreconLBFGS"))
    outdir = {"relax": f" --outdir {tmp_path / 'out'}", "run": ""}  # as each command says it
    for command in ("relax", "run"):
        fail_in_step(monkeypatch, PreconLBFGS, 4)
        assert main([command, str(config), "--overwrite"]) == 1
        err = capsys.readouterr().err.strip().splitlines()[-1]
        trajectory = tmp_path / "out" / "relax.traj"
        said = "relax stopped:" if command == "relax" else "run stopped: relax:"
        assert err == (f"rigidmd: {said} PreconLBFGS failed after step 3 "
                       f"(RuntimeError: LineSearch failed!); the atoms are back at the "
                       f"structure of step 3, the last frame of {trajectory}; continue with: "
                       f"rigidmd {command} {config}{outdir[command]} --resume"), err
        assert len(read(trajectory, ":")) == 4  # the start and 3 steps


def test_relax_leaves_the_atoms_at_the_last_whole_step_and_says_so(monkeypatch):
    """Issue 45 item 20: a relaxation stopped by NaN forces said the atoms are "left at step
    0" (the dynamics' step); they were at the failed trial point.  Now they are back at the
    last whole step of the optimizer, and the message says which."""
    from rigidmd.core.forces import NonFiniteForceError
    from rigidmd.relax import relax

    atoms = water_cluster(4, seed=1)
    atoms.calc = TIP3P(rc=40.0)
    calls = tip3p_calls(monkeypatch)
    original = TIP3P.calculate  # counts the calls

    def calculate(self, *args, **kwargs):
        original(self, *args, **kwargs)
        if len(calls) == 6:
            self.results["forces"][2] = np.nan

    monkeypatch.setattr(TIP3P, "calculate", calculate)
    frames = []
    with pytest.raises(NonFiniteForceError) as err:
        relax(atoms, fmax=1e-6, optimizer="FIRE",
              observers=[lambda *_: frames.append(atoms.positions.copy())])
    message = str(err.value)
    assert message.startswith(f"relax: FIRE failed after step {len(frames) - 1} (calculator "
                              "returned non-finite forces on atom(s) [2]); the atoms are back "
                              f"at the structure of step {len(frames) - 1}"), message
    assert "step 0;" not in message and "left at" not in message
    np.testing.assert_array_equal(atoms.positions, frames[-1])


def damage_state(path, name, change):
    """Rewrite the array ``name`` of the state file at ``path`` with ``change(array)``."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays[name] = change(arrays[name])
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize("name, change, said", [
    ("view.q_ref", lambda q: 2 * q, "body 0 has a reference orientation of norm 2, not 1"),
    ("view.x", lambda x: np.where(np.arange(x.size).reshape(x.shape) == 4, np.nan, x),
     "view.x holds a non-finite number"),
    ("opt.s", lambda s: s * np.nan, "opt.s holds a non-finite number"),
])
def test_a_damaged_relaxation_state_is_not_used(tmp_path, monkeypatch, name, change, said):
    """Issue 45 item 19: a damaged relax.state.npz was used unchecked: NaN gave internal
    messages, reference orientations x2 appended 500 steps of molecules with O-H 5.67 Å to
    relax.traj.  Now it is checked as checkpoints are: the memory starts afresh, saying why,
    and the relaxation continues from the trajectory's last frame with whole molecules."""
    import io
    import signal

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    signal_at_call(monkeypatch, 12, signal.SIGTERM)
    assert relax_only(raw, io.StringIO()) == 143
    state = tmp_path / "out" / "relax.state.npz"
    damage_state(state, name, change)
    monkeypatch.setattr(RigidFilter, "get_forces", signal_at_call.original)
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    assert f"relax: the optimizer's memory starts afresh: {state}: a damaged relaxation state " \
           f"({said})" in out.getvalue(), out.getvalue()
    for frame in read(tmp_path / "out" / "relax.traj", ":"):
        oh = np.linalg.norm(frame.positions[1::3] - frame.positions[0::3], axis=1)
        np.testing.assert_allclose(oh, 0.9572, atol=1e-6)  # whole waters (TIP3P's O-H)


def assert_resume_refused(other, field, out):
    """``rigidmd relax --resume`` with the configuration ``other`` is refused in one line
    naming ``field``, and nothing in ``out`` changes."""
    import io

    from rigidmd.config.quantities import ConfigError
    from rigidmd.run.relaxcommand import relax_only

    files = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(ConfigError, match=rf"^--resume: the {field} differs from the "
                                          rf"relaxation's \(.*relax.state.npz records {field} "
                                          rf"\S+, the configuration gives {field} \S+\); "
                                          r"restore it, or start anew with --overwrite$"):
        relax_only(other, io.StringIO(), mode="resume")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files


def test_rigidmd_relax_resume_refuses_another_calculator(tmp_path, monkeypatch):
    """Issue 45 item 19: ``rigidmd relax --resume`` with another calculator continued
    silently, appending frames of another energy surface (``rigidmd run --resume`` refuses
    it).  Now it is refused in one line before anything is written; the same calculator
    continues."""
    import io
    import signal

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    signal_at_call(monkeypatch, 12, signal.SIGTERM)
    assert relax_only(raw, io.StringIO()) == 143
    monkeypatch.setattr(RigidFilter, "get_forces", signal_at_call.original)
    other = dict(raw, calculator={"name": "tip3p", "options": {"rc": 30.0}})
    assert_resume_refused(other, "calculator", tmp_path / "out")
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    assert "continuing with the optimizer's memory" in out.getvalue()


@pytest.mark.parametrize("where", ["trajectory", "log"])
def test_a_full_disk_while_relaxing_names_the_file(tmp_path, monkeypatch, capsys, where):
    """Issue 45 item 19: a full disk during ``rigidmd relax`` said "cannot write an output
    file" (ASE's write errors carry no file name); now the file is named."""
    import errno

    from ase.io.ulm import Writer

    from rigidmd.run.cli import main

    config = tmp_path / "relax.yaml"
    config.write_text(RELAX_CONFIG.replace("STEPS", "2000"))
    writes = []

    def full(*args, **kwargs):
        writes.append(1)
        if len(writes) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")

    if where == "trajectory":
        original = Writer.write  # under ASE's trajectory writer
        monkeypatch.setattr(Writer, "write",
                            lambda self, *a, **k: (full(), original(self, *a, **k)))
    else:
        from ase.optimize.fire import FIRE

        original = FIRE.log
        monkeypatch.setattr(FIRE, "log", lambda self, *a, **k: (full(), original(self, *a, **k)))
    assert main(["relax", str(config)]) == 1  # as a failed write of rigidmd run
    err = capsys.readouterr().err.strip().splitlines()[-1]
    path = tmp_path / "out" / ("relax.traj" if where == "trajectory" else "relax.log")
    assert err.startswith(f"rigidmd: relax stopped: cannot write {path}: the disk is full; "
                          f"continue with: rigidmd relax {config}"), err


def test_rigidmd_relax_resume_of_a_converged_relaxation_says_it_is_complete(tmp_path):
    """Issue 45 item 21: ``rigidmd relax --resume`` of a converged relaxation said it was
    "continuing ... after step N" and that "the optimizer's memory starts afresh", as if work
    were left.  Now it says the relaxation is complete, and writes nothing."""
    import io

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path)
    assert relax_only(raw, io.StringIO()) == 0
    files = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    said = out.getvalue().strip().splitlines()
    assert len(said) == 1 and said[0].startswith(
        f"relax: the relaxation in {tmp_path / 'out' / 'relax.traj'} is complete: it converged "
        "at step "), said
    assert said[0].endswith("below fmax 0.01); nothing is left to do")
    assert {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()} == files


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGINT"])
def test_a_signal_just_after_the_relaxation_is_noted_not_a_kill(tmp_path, signame):
    """Issue 45 item 21: a signal in the moment after convergence (the relaxation's handlers
    gone, the command not yet ended) killed rigidmd relax without a word (exit -15, -2).
    Now it is noted: the relaxation is complete, and the command says so and exits 0."""
    result = run_signalled_after_relaxation(tmp_path, signame, ["relax", "relax.yaml"])
    assert result.returncode == 0, (result.returncode, result.stderr)
    assert result.stdout.strip().splitlines()[-1] == (
        f"relax: {signame} arrived after the relaxation had ended; it is complete and its "
        "outputs are whole")
    assert "Traceback" not in result.stderr


def test_a_signal_just_after_a_run_s_relaxation_stops_the_md_with_a_checkpoint(tmp_path):
    """Issue 45 item 21: ``rigidmd run`` with a relax: section, signalled in the moment after
    the relaxation converged (its handlers gone, the MD's not yet there), was killed without
    a word (exit -15).  Now the signal is noted and obeyed as in the MD: a checkpoint at its
    start, the command that resumes, exit 143."""
    result = run_signalled_after_relaxation(tmp_path, "SIGTERM", ["run", "relax.yaml"])
    assert result.returncode == 143, (result.returncode, result.stderr)
    assert "stopped by SIGTERM after step 0" in result.stdout  # (ASE observes step 0 too)
    assert "continue with: rigidmd run relax.yaml --resume" in result.stdout
    assert "Traceback" not in result.stderr


def test_a_damaged_trajectory_continues_from_the_state_file(tmp_path, monkeypatch):
    """Issue 45 item 19: a damaged relax.traj could not be continued ("cannot read") though
    relax.state.npz held the positions.  Now --resume continues from the state, keeping the
    damaged file beside it, and reaches the uninterrupted relaxation's minimum."""
    import io
    import signal

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only

    reference = tmp_path / "reference"
    reference.mkdir()
    assert relax_only(relax_config(reference), io.StringIO()) == 0
    minimum = read(reference / "out" / "relax.traj")

    raw = relax_config(tmp_path)
    signal_at_call(monkeypatch, 12, signal.SIGTERM)
    assert relax_only(raw, io.StringIO()) == 143
    monkeypatch.setattr(RigidFilter, "get_forces", signal_at_call.original)
    traj = tmp_path / "out" / "relax.traj"
    damaged = traj.read_bytes()[:-100]  # its frame table cut off
    traj.write_bytes(damaged)
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    assert (f"relax: {traj} cannot be read (" in out.getvalue() and "it is kept as "
            "relax.damaged.traj, and the relaxation continues from the positions in "
            f"{tmp_path / 'out' / 'relax.state.npz'} in a new relax.traj, whose steps count "
            "from 0 again") in out.getvalue()
    assert "continuing with the optimizer's memory" in out.getvalue()
    assert (tmp_path / "out" / "relax.damaged.traj").read_bytes() == damaged
    np.testing.assert_array_equal(read(traj).positions, minimum.positions)
    # The new trajectory starts with its start frame and the log's steps count from it (the
    # frame was missing and the count went on from the old one), so a later --resume, which
    # counts the trajectory's frames, continues the log's count.
    log = (tmp_path / "out" / "relax.log").read_text().splitlines()
    assert int(log[-1].split()[1]) == len(read(traj, ":")) - 1


@pytest.mark.parametrize("change, field", [
    ({"cell": False, "pressure": None}, "relax.cell"),  # (a pressure needs a cell)
    ({"pressure": "1000 bar"}, "relax.pressure"),
])
def test_rigidmd_relax_resume_refuses_another_cell_or_pressure(tmp_path, change, field):
    """``rigidmd relax --resume`` compared only the calculator: a cell relaxation continued
    with a fixed cell (or another pressure) appended frames of another surface in silence.
    Now refused in one line, nothing written; a tighter fmax continues."""
    import io

    from rigidmd.run.relaxcommand import relax_only
    from rigidmd.run.relaxstructure import RelaxationNotConverged

    text = RELAX_CONFIG.replace(
        "{builtin: water_cluster, n_molecules: 6, seed: 2}", "{builtin: water_box, n_side: 2}"
    ).replace("{name: tip3p, options: {rc: 40.0}}",
              "{name: ase.calculators.lj.LennardJones, "
              "options: {sigma: 2.5, epsilon: 0.005, rc: 6.0}}").replace(
        "{fmax: 0.01, steps: STEPS, optimizer: FIRE}",
        "{fmax: 0.001, steps: 3, cell: iso, pressure: 0 bar}")
    (tmp_path / "relax.yaml").write_text(text)
    from rigidmd.config import load_config

    raw = load_config(tmp_path / "relax.yaml")
    with pytest.raises(RelaxationNotConverged):  # 3 steps: the state is written
        relax_only(raw, io.StringIO())
    assert (tmp_path / "out" / "relax.state.npz").exists()
    other = dict(raw, relax={key: value for key, value in {**raw["relax"], **change}.items()
                             if value is not None})
    assert_resume_refused(other, field, tmp_path / "out")
    tighter = dict(raw, relax=dict(raw["relax"], fmax=0.0005, steps=5))
    out = io.StringIO()
    with pytest.raises(RelaxationNotConverged):
        relax_only(tighter, out, mode="resume")
    assert "continuing with the optimizer's memory" in out.getvalue(), out.getvalue()


@pytest.mark.parametrize("relax, outputs, message", [
    ("log: relax.traj", "", "relax.log: relax.traj is also relax.trajectory"),
    ("log: relax.state.npz", "", "relax.log: relax.state.npz is also the relaxation's state "
                                 "file (beside relax.trajectory)"),
    ("trajectory: md.traj", "", "relax.trajectory: md.traj is also outputs.trajectory"),
    ("log: md.log", "", "relax.log: md.log is also outputs.log"),
    # (an ASE trajectory under another format's name is refused first: the new-user pass)
    ("trajectory: checkpoint.npz", "", "relax.trajectory: checkpoint.npz would hold an ASE "
                                       "trajectory under another format's name"),
    ("trajectory: sub/x.traj", "", "relax.trajectory: the folder"),
    ("log: .rigidmd.lock", "", "relax.log: .rigidmd.lock is also the lock file"),
])
def test_relaxation_outputs_on_one_path_are_refused_before_anything_is_written(
        tmp_path, relax, outputs, message):
    """Nothing checked the relaxation's outputs against each other or the run's: the
    trajectory replaced the log, the MD trajectory replaced the relaxation's frames, a log
    named as the state file was deleted at convergence (all with exit status 0), and a
    trajectory in a missing folder failed after the log was created."""
    text = RELAX_CONFIG.replace("STEPS", "50").replace("optimizer: FIRE}",
                                                        f"optimizer: FIRE, {relax}}}")
    (tmp_path / "relax.yaml").write_text(text)
    for command in ("run", "relax"):
        if command == "relax" and "outputs." in message:
            continue  # rigidmd relax writes no MD outputs
        result = rigidmd(command, "relax.yaml", cwd=tmp_path)
        assert result.returncode == 2, (command, result.stderr)
        assert result.stderr.strip() == f"rigidmd: error: {message}" or \
            result.stderr.strip().startswith(f"rigidmd: error: {message}"), result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "out").exists()


def test_relax_overwrite_keeps_the_earlier_relaxation_when_the_new_one_is_refused(tmp_path):
    """``rigidmd relax --overwrite`` deleted the earlier relaxation, then refused the new
    one (a cell relaxation without stress; a FixAtoms holding part of a body), leaving an
    empty relax.log; and without --overwrite it made the directory and an empty log."""
    from ase.constraints import FixAtoms
    from ase.io import write

    (tmp_path / "relax.yaml").write_text(RELAX_CONFIG.replace("STEPS", "5"))
    result = rigidmd("relax", "relax.yaml", cwd=tmp_path)
    assert result.returncode == 1, result.stderr  # 5 steps: not converged, frames kept
    before = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    assert "relax.traj" in before
    start = water_cluster(6, seed=2)
    start.set_constraint(FixAtoms(indices=[0, 1]))  # part of body 0
    write(tmp_path / "fixed.traj", start)
    for structure, message in (
            (None, None),
            ("fixed.traj", "relax: RigidFilter: FixAtoms holds some but not all atoms of "
                           "body 0")):
        text = RELAX_CONFIG.replace("STEPS", "5")
        if structure:
            text = text.replace("{builtin: water_cluster, n_molecules: 6, seed: 2}", structure)
        else:
            text = text.replace("{builtin: water_cluster, n_molecules: 6, seed: 2}",
                                "{builtin: water_box, n_side: 2}").replace(
                "optimizer: FIRE}", "optimizer: FIRE, cell: iso}").replace("rc: 40.0", "rc: 3.0")
            message = "relax.cell: iso relaxes the cell, which needs the stress"
        (tmp_path / "other.yaml").write_text(text)
        for flags in (["--overwrite"], ["--outdir", "new"]):
            result = rigidmd("relax", "other.yaml", *flags, cwd=tmp_path)
            assert result.returncode == 2 and message in result.stderr, result.stderr
            assert {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()} == before
            assert not (tmp_path / "new").exists()


def test_the_relaxation_log_keeps_up_with_its_trajectory(tmp_path, monkeypatch):
    """relax.log was block-buffered: a relaxation killed outright (103 frames written) left
    it empty.  Each step's line is in the file when the step's frame is."""
    import io

    from rigidmd.run.relaxcommand import relax_only

    seen = []
    original = RigidFilter.get_forces

    def get_forces(self, *args, **kwargs):
        log = tmp_path / "out" / "relax.log"
        if log.exists():
            seen.append(len(log.read_text().splitlines()))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(RigidFilter, "get_forces", get_forces)
    assert relax_only(relax_config(tmp_path, steps=2000), io.StringIO()) == 0
    assert max(seen) > 10  # lines were on disk while the relaxation ran


def test_a_relaxation_stopped_at_step_0_resumes_exactly_and_its_log_continues(
        tmp_path, monkeypatch):
    """SIGTERM in the first force call (step 0) of ``rigidmd relax``, then --resume: the state
    file written at step 0 was refused ("the optimizer's memory starts afresh: ... a damaged
    relaxation state", its preconditioner's scales not yet estimated written as NaN) and
    relax.log got a second header and step 0 twice.  Now the continuation is the
    uninterrupted relaxation, frame for frame, in the same force calls, and the log reads as
    one relaxation: one header, the steps 0, 1, 2, ... each once."""
    import io
    import signal

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only

    reference = tmp_path / "reference"
    reference.mkdir()
    calls = tip3p_calls(monkeypatch)
    assert relax_only(relax_config(reference), io.StringIO()) == 0
    uninterrupted, uninterrupted_calls = read(reference / "out" / "relax.traj", ":"), len(calls)
    calls.clear()

    raw = relax_config(tmp_path)
    signal_at_call(monkeypatch, 1, signal.SIGTERM)
    assert relax_only(raw, io.StringIO(), config_path="relax.yaml") == 143
    assert len(read(tmp_path / "out" / "relax.traj", ":")) == 1
    assert (tmp_path / "out" / "relax.state.npz").exists()
    monkeypatch.setattr(RigidFilter, "get_forces", signal_at_call.original)
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    assert "continuing with the optimizer's memory" in out.getvalue(), out.getvalue()
    resumed = read(tmp_path / "out" / "relax.traj", ":")
    assert len(resumed) == len(uninterrupted) and len(calls) == uninterrupted_calls
    for a, b in zip(uninterrupted, resumed, strict=True):
        np.testing.assert_array_equal(a.positions, b.positions)
    lines = (tmp_path / "out" / "relax.log").read_text().splitlines()
    assert len([line for line in lines if "Step" in line]) == 1
    steps = [int(line.split()[1]) for line in lines if "Step" not in line]
    assert steps == list(range(len(resumed))), steps


def test_a_converged_rigidmd_relax_is_complete_for_its_resume(tmp_path):
    """``rigidmd relax`` (water_cluster(6, seed=6), fmax 0.02) said converged with a torque
    of 0.0218 eV/Å (|τ|/ℓ: the rotation rows' force, J_rᵀτ/ℓ, read 0.0188), and --resume,
    whose check is a new filter of the last frame, took another step and appended a frame.
    Now the relaxation stops by that same reading, and --resume says it is complete."""
    import io

    from ase.io import read

    from rigidmd.run.relaxcommand import relax_only

    raw = relax_config(tmp_path, structure="{builtin: water_cluster, n_molecules: 6, "
                                           "seed: 6}")
    raw["calculator"]["options"]["rc"] = 20.0
    raw["relax"]["fmax"] = 0.02
    assert relax_only(raw, io.StringIO()) == 0
    frames = len(read(tmp_path / "out" / "relax.traj", ":"))
    out = io.StringIO()
    assert relax_only(raw, out, mode="resume") == 0
    assert "is complete: it converged at step" in out.getvalue(), out.getvalue()
    assert len(read(tmp_path / "out" / "relax.traj", ":")) == frames
