"""``rigidmd bias``: a time step's bias of <U> from runs at dt and dt/2 (rigidmd.run.bias)."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from ase import units
from ase.calculators.calculator import Calculator, all_changes

from rigidmd.config import ConfigError, check_config
from rigidmd.run import cli
from rigidmd.run.bias import estimate_bias
from rigidmd.systems import water_molecule

# The trap starts far from equilibrium: the step-size check's warning is expected.
pytestmark = pytest.mark.filterwarnings("ignore:RigidDynamics. the conserved energy changed")


class Trap(Calculator):
    """Every atom in one harmonic well at the origin: U = sum k/2 |x_i|^2 (eV, Å).

    Rigid bodies in it do not see each other.  A body's U is 3k/2 |X + s/3|^2 + C with
    s = sum_i R d_i (fixed length) and C = k/2 sum |d_i|^2 - k |s|^2 / 6: its exact mean
    at temperature T is 3 kT / 2 + C, whatever the orientations do.
    """

    implemented_properties = ["energy", "forces"]

    def __init__(self, k=15.0):
        super().__init__()
        self.k = float(k)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        x = self.atoms.positions
        self.results = {"energy": 0.5 * self.k * float(np.sum(x * x)), "forces": -self.k * x}


def exact_mean_energy(k, temperature_K):
    """<U> per water in :class:`Trap` at temperature_K (eV), exactly."""
    water = water_molecule()
    d = water.positions - water.get_center_of_mass()
    s = d.sum(axis=0)
    return 1.5 * units.kB * temperature_K + 0.5 * k * np.sum(d * d) - k * (s @ s) / 6


def trapped_waters(path, n=32, seed=0):
    """``n`` waters with their centres within 0.05 Å of the origin, randomly turned (they do
    not see each other), each body its tag, written to ``path`` (extxyz)."""
    from ase import Atoms
    from ase.io import write
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    water = water_molecule()
    d = water.positions - water.get_center_of_mass()
    atoms = Atoms()
    for b, rot in enumerate(Rotation.random(n, random_state=seed)):
        one = Atoms(water.get_chemical_symbols(),
                    positions=rot.apply(d) + rng.uniform(-0.05, 0.05, 3))
        one.set_tags([b + 1] * 3)
        atoms += one
    write(path, atoms, format="extxyz")
    return path


#: 32 waters in the trap (translational period 40 fs at k 15 eV/Å² per atom), Langevin.
TRAP = {
    "structure": "trap.xyz",
    "read_options": {"format": "extxyz"},
    "bodies": "tags",
    "calculator": {"name": f"{__name__}.Trap", "options": {"k": 15.0}},
    "velocities": {"temperature": "300 K", "seed": 1},
    "thermostat": {"kind": "langevin", "temperature": "300 K", "friction": "0.01 1/fs",
                   "seed": 2, "fixcm": False},
    "timestep": "5 fs",
    "steps": 1,
}


def trap_config(directory, **changes):
    """The configuration of the trapped waters, its structure written in ``directory``."""
    trapped_waters(directory / "trap.xyz")
    raw = dict(TRAP, **changes)
    raw["_base"] = str(directory)
    return check_config(raw, trust=True)


def test_the_bias_of_a_trap_against_its_exact_mean(tmp_path):
    """32 waters in a harmonic trap, Langevin at 300 K, 4 fs against 2 fs (5 ps each): the
    estimate 4/3 (<U>(dt) - <U>(dt/2)) against the exact bias <U>(dt) - <U>(0), with <U>(0)
    known in closed form (:class:`Trap`).  Measured with 10 ps runs: estimate 1.20 ± 0.13,
    exact 1.15 kJ/mol per body at 4 fs; 3.23 ± 0.19 against 2.95 at 5 fs (the dt^4 term:
    9 %).  Allowed: three standard errors of the difference plus 10 % of the bias."""
    import io

    kj = units.kJ / units.mol
    result = estimate_bias(trap_config(tmp_path, timestep="4 fs"), tmp_path / "out",
                           production_ps=5.0, equilibrate_ps=0.5, progress=io.StringIO(),
                           stream=io.StringIO())
    assert result["status"] == 0 and result["complete"]
    exact = exact_mean_energy(15.0, 300) / kj
    u1, e1 = result["legs"]["dt"]["U_per_body_kJ_mol"]
    u2, e2 = result["legs"]["dt/2"]["U_per_body_kJ_mol"]
    bias, error = result["bias_kJ_mol"]
    assert bias == pytest.approx(4 / 3 * (u1 - u2))
    assert error == pytest.approx(4 / 3 * np.hypot(e1, e2))
    true = u1 - exact
    assert true > 0.8  # the step's bias is there, and large
    spread = np.hypot(e1 / 3, 4 * e2 / 3)  # of bias - true = u1/3 - 4 u2/3 + exact
    assert abs(bias - true) < 3 * spread + 0.1 * true, (bias, true, spread)
    shift, shift_error = result["bias_K"]
    assert shift > 0
    # ΔT = bias / (Var(U)/k_B T²): its error carries the bias's and Var(U)'s (the spread of
    # the half-step run's block variances), not the bias's alone.
    half = result["legs"]["dt/2"]
    assert half["var_U_error"] > 0
    assert shift_error == pytest.approx(shift * np.hypot(error / bias,
                                                         half["var_U_error"] / half["var_U"]))
    # The configurations are hotter at the larger step (the trap's T_conf,tr is exact).
    t1, t2 = (result["legs"][k]["T_conf_tr"][0] for k in ("dt", "dt/2"))
    assert t1 > t2 > 290
    saved = json.loads((tmp_path / "out" / "bias.json").read_text())
    assert saved["bias_kJ_mol"] == pytest.approx(list(result["bias_kJ_mol"]))
    assert "bias of <U>/N at 4 fs" in (tmp_path / "out" / "bias.txt").read_text()


@pytest.mark.parametrize("change, message", [
    ({"thermostat": None}, "thermostat: rigidmd bias needs a thermostat"),
    ({"barostat": {"kind": "monte_carlo", "pressure": "1 bar", "seed": 1}},
     "barostat: rigidmd bias runs at constant volume"),
    ({"relax": {"fmax": 0.1}}, "relax: rigidmd bias starts both runs"),
    ({"thermostat": dict(TRAP["thermostat"], friction="0 1/fs")}, "thermostat.friction: 0"),
    # ran both runs, then ZeroDivisionError and nothing written (the bias/ipi pass)
    ({"thermostat": dict(TRAP["thermostat"], temperature="0 K")},
     "thermostat.temperature: 0 K; rigidmd bias needs a bath above 0 K"),
])
def test_what_it_cannot_estimate_is_refused_in_one_line(tmp_path, change, message):
    raw = {k: v for k, v in dict(TRAP, **change).items() if v is not None}
    trapped_waters(tmp_path / "trap.xyz")
    raw["_base"] = str(tmp_path)
    try:
        config = check_config(raw, trust=True)
    except ConfigError as err:  # (the configuration itself may refuse it first)
        pytest.fail(f"the configuration refused it: {err}")
    with pytest.raises(ConfigError, match=message) as info:
        estimate_bias(config, tmp_path / "out")
    assert "\n" not in str(info.value)
    assert not (tmp_path / "out").exists()


def _command(tmp_path, *flags):
    trapped_waters(tmp_path / "trap.xyz")
    import yaml

    raw = {k: v for k, v in TRAP.items() if k != "steps"}  # not read by rigidmd bias
    (tmp_path / "bias.yaml").write_text(yaml.safe_dump(dict(raw, timestep="4 fs")))
    return ["bias", str(tmp_path / "bias.yaml"), "--trust", "--ps", "2", "--equilibrate-ps",
            "0.2", "--outdir", str(tmp_path / "out"), *flags]


@pytest.mark.parametrize("flags, message", [
    (("--ps", "0"), "--ps: expected a positive number"),
    (("--sample-fs", "nan"), "--sample-fs: expected a positive number"),
    (("--probes", "0"), "--probes: expected a whole number >= 1"),
    (("--blocks", "1"), "--blocks: expected a whole number >= 2"),
    (("--timestep", "4 parsecs"), "--timestep"),
    (("--sample-fs", "1"), "--sample-fs: 1 fs is less than 1 step"),
    (("--equilibrate-ps", "0.001"), "--equilibrate-ps: 0.001 ps is less than 1 step(s) of "
                                    "4 fs (0: none)"),  # (was "1 fs" for a ps option)
    (("--ps", "1e-6"), "--ps: 1e-06 ps is less than 5 step(s) of 4 fs"),
    (("--blocks", "100000"), "--sample-fs: 2 ps sampled every 12 fs gives 167 samples, fewer "
                             "than the 100000 blocks of the errors; raise --ps, or lower "
                             "--sample-fs or --blocks"),
    (("--ps", "0.02", "--sample-fs", "8"), "--sample-fs: 0.02 ps sampled every 8 fs gives 2 "
                                           "samples, fewer than the 5 blocks"),
    (("--ps", "0.2", "--tconf-fs", "100"), "--tconf-fs: 0.2 ps sampled every 100 fs gives 2 "
                                           "samples"),
    (("--resume",), "--resume: no estimate to continue"),
    (("--outdir", ""), "--outdir: empty"),  # wrote into the current folder
])
def test_command_mistakes_are_one_line_and_status_2(tmp_path, capsys, flags, message):
    assert cli.main(_command(tmp_path, *flags)) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rigidmd: error: {message}"), err
    assert err.count("\n") == 1
    assert not (tmp_path / "out" / "bias.json").exists()


def test_a_stopped_estimate_continues_to_the_same_runs(tmp_path, capsys):
    """SIGTERM during the first run: exit 143 after the step, bias.json and the run's
    checkpoint written, the command that continues printed; that command finishes, and its
    samples of U and the kinetic energies are those of an uninterrupted estimate, bit for bit.
    An estimate in the directory is not overwritten; --resume with another argument is
    refused naming it."""
    import rigidmd

    source = os.path.dirname(rigidmd.__path__[0])  # this checkout's package, and Trap
    env = dict(os.environ, PYTHONUNBUFFERED="1",
               PYTHONPATH=os.pathsep.join(
                   [source, os.path.dirname(os.path.dirname(os.path.dirname(__file__)))]))
    (tmp_path / "stopped").mkdir()
    args = _command(tmp_path / "stopped", "--ps", "1")
    proc = subprocess.Popen([sys.executable, "-m", "rigidmd.run.cli", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("run at dt = 4 fs"), line
        time.sleep(0.2)  # (the first run takes about a second)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, err
    assert "so far" in out
    hint = out.split("continue with: ")[1].splitlines()[0]
    assert hint.endswith("--resume")
    saved = json.loads((tmp_path / "stopped" / "out" / "bias.json").read_text())
    assert saved["status"] == 143 and not saved["complete"]
    assert (tmp_path / "stopped" / "out" / "leg-dt.npz").exists()
    # Anything but --resume into it is refused.
    assert cli.main(args) == 2
    assert cli.main([*args, "--probes", "5", "--resume"]) == 2
    assert "rigidmd: error: --probes: 4 in the estimate" in capsys.readouterr().err
    # The hint continues it.
    import shlex

    words = shlex.split(hint)
    assert words[:2] == ["rigidmd", "bias"]
    assert cli.main(words[1:]) == 0
    resumed = json.loads((tmp_path / "stopped" / "out" / "bias.json").read_text())
    assert resumed["complete"] and resumed["status"] == 0
    assert not (tmp_path / "stopped" / "out" / "leg-dt.npz").exists()
    (tmp_path / "whole").mkdir()
    assert cli.main(_command(tmp_path / "whole", "--ps", "1")) == 0
    whole = json.loads((tmp_path / "whole" / "out" / "bias.json").read_text())
    for a, b in zip(resumed["legs_record"], whole["legs_record"], strict=True):
        assert a["samples"] == b["samples"]
        # The configurational temperatures too: a sample's probes depend on the seed, the
        # run and the step alone (before, a resume drew new ones: 5-10 % apart here).
        assert a["tconf_sums"] and a["tconf_sums"] == b["tconf_sums"]


def test_a_failed_step_keeps_the_samples_and_resume_takes_them_again(tmp_path, monkeypatch):
    """A step that fails (non-finite forces) in the second run: the command stops in one
    line (RunStopped: status 1) that says how to continue, bias.json keeps the first run and
    what the second had sampled; --resume runs the second again from its start (no
    checkpoint was written) and samples it once, with no step twice."""
    import io

    from rigidmd.run.runner import RunStopped

    config = trap_config(tmp_path, timestep="4 fs")
    original, calls = Trap.calculate, []

    def failing(self, *args, **kwargs):
        original(self, *args, **kwargs)
        calls.append(1)
        if len(calls) == 500:  # in the second run (the first makes about 360 calls)
            self.results["forces"][0, 0] = np.nan

    monkeypatch.setattr(Trap, "calculate", failing)
    kwargs = dict(production_ps=1.0, equilibrate_ps=0.2, progress=io.StringIO(),
                  stream=io.StringIO())
    with pytest.raises(RunStopped, match=r"non-finite .* \(in the run at dt/2\); .*bias.json "
                       "keeps the samples so far.*--resume") as info:
        estimate_bias(config, tmp_path / "out", hint="rigidmd bias ... --resume", **kwargs)
    assert "\n" not in str(info.value)
    saved = json.loads((tmp_path / "out" / "bias.json").read_text())
    first, second = saved["legs_record"]
    assert first["done"] and not second["done"] and second["samples"]["step"]
    monkeypatch.setattr(Trap, "calculate", original)
    result = estimate_bias(config, tmp_path / "out", resume=True, **kwargs)
    assert result["complete"]
    steps = result["legs_record"][1]["samples"]["step"]
    assert steps == sorted(set(steps)) and len(steps) == len(first["samples"]["step"])
    assert result["legs_record"][0]["samples"] == first["samples"]


def _stop_at_call(monkeypatch, n, how):
    """Make :class:`Trap`'s ``n``-th call raise ``how`` (an exception) or send this process
    the signal ``how``; returns the count of calls."""
    original, calls = Trap.calculate, []

    def calculate(self, *args, **kwargs):
        original(self, *args, **kwargs)
        calls.append(1)
        if len(calls) == n:
            if isinstance(how, signal.Signals):
                os.kill(os.getpid(), how)
            else:
                raise how

    monkeypatch.setattr(Trap, "calculate", calculate)
    return calls


def test_a_second_ctrl_c_keeps_the_samples_and_says_how_to_continue(tmp_path, monkeypatch):
    """KeyboardInterrupt inside a step (a second Ctrl-C): status 130 returned (not raised),
    bias.json records 130 with the samples so far, the message names the run and the
    command that continues; that command completes it."""
    import io

    config = trap_config(tmp_path, timestep="4 fs")
    _stop_at_call(monkeypatch, 200, KeyboardInterrupt())
    out = io.StringIO()
    kwargs = dict(production_ps=1.0, equilibrate_ps=0.2, progress=io.StringIO())
    result = estimate_bias(config, tmp_path / "out", stream=out, hint="HINT --resume", **kwargs)
    assert result["status"] == 130 and not result["complete"]
    saved = json.loads((tmp_path / "out" / "bias.json").read_text())
    assert saved["status"] == 130 and saved["legs_record"][0]["samples"]["step"]
    assert "second Ctrl-C) in the run at dt" in out.getvalue()
    assert "continue with: HINT --resume" in out.getvalue()
    monkeypatch.undo()
    done = estimate_bias(config, tmp_path / "out", resume=True, stream=io.StringIO(),
                         **kwargs)
    assert done["complete"] and done["status"] == 0


def test_files_of_another_estimate_are_never_taken_or_overwritten(tmp_path, monkeypatch):
    """Without --resume a directory holding a stopped run's checkpoint is refused (before,
    a new estimate continued that run, whatever its step); a directory another live process
    holds is refused naming it; --resume refuses a checkpoint of another time step and a
    record whose runs are incomplete, each in one line."""
    import io

    from rigidmd.run.outputs import LOCK_NAME, OutputError

    config = trap_config(tmp_path, timestep="4 fs")
    kwargs = dict(production_ps=1.0, equilibrate_ps=0.2, progress=io.StringIO(),
                  stream=io.StringIO())
    _stop_at_call(monkeypatch, 100, signal.SIGTERM)  # in the first run: its checkpoint
    out = tmp_path / "out"
    assert estimate_bias(config, out, **kwargs)["status"] == 143
    monkeypatch.undo()
    assert (out / "leg-dt.npz").exists()
    for name in ("bias.json", "bias.txt"):
        (out / name).rename(tmp_path / name)  # the checkpoint alone stays
    with pytest.raises(ConfigError, match=r"--outdir: .* already holds an estimate "
                                          r"\(leg-dt.npz\); continue it with --resume"):
        estimate_bias(config, out, **kwargs)
    # A table kept without its record (bias.txt alone) is not overwritten either.
    lone = tmp_path / "lone"
    lone.mkdir()
    (lone / "bias.txt").write_text("a table someone kept\n")
    with pytest.raises(ConfigError, match=r"--outdir: .* already holds an estimate "
                                          r"\(bias.txt\); continue it with --resume"):
        estimate_bias(config, lone, **kwargs)
    assert (lone / "bias.txt").read_text() == "a table someone kept\n"
    for name in ("bias.json", "bias.txt"):
        (tmp_path / name).rename(out / name)
    # Another live process holds the directory.
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        import socket

        (out / LOCK_NAME).write_text(json.dumps({"pid": holder.pid,
                                                 "host": socket.gethostname()}))
        with pytest.raises(OutputError, match=f"--outdir: .* in use by process {holder.pid}"):
            estimate_bias(config, out, resume=True, **kwargs)
    finally:
        holder.kill()
        holder.wait()
    # The first run's checkpoint offered as the second's: refused, naming both steps.
    saved = json.loads((out / "bias.json").read_text())
    saved["legs_record"][0]["done"] = True
    (out / "bias.json").write_text(json.dumps(saved))
    (out / "leg-dt.npz").rename(out / "leg-dt-2.npz")
    with pytest.raises(ConfigError, match=r"leg-dt-2.npz is a run at 4 fs, not this "
                                          r"estimate's dt/2 run at 2 fs"):
        estimate_bias(config, out, resume=True, **kwargs)
    del saved["legs_record"][1]["samples"]
    (out / "bias.json").write_text(json.dumps(saved))
    with pytest.raises(ConfigError, match="is not an estimate rigidmd bias wrote"):
        estimate_bias(config, out, resume=True, **kwargs)


def test_a_time_off_the_step_grid_is_said(tmp_path, capsys):
    """--sample-fs 10 at 4 fs is 2.5 steps: taken as the nearest whole step, and said."""
    assert cli.main(_command(tmp_path, "--ps", "0.4", "--sample-fs", "10", "--tconf-fs",
                             "0")) == 0
    out = capsys.readouterr().out
    assert "--sample-fs: 10 fs is not a whole number of 4 fs steps; taken as 3 steps " \
           "(12 fs)" in out
    saved = json.loads((tmp_path / "out" / "bias.json").read_text())
    assert saved["legs_record"][0]["every"] == 3 and saved["legs_record"][1]["every"] == 6


class Killed(BaseException):
    """What no handler sees (SIGKILL, the out-of-memory killer): the process ends here."""


def test_a_kill_keeps_the_finished_run_and_the_last_save(tmp_path, monkeypatch):
    """The bias/ipi pass: SIGKILL in the second run lost everything (bias.json was written
    only at the end or after a stop), the finished first run included.  Now the record is
    written when a run ends and every SAVE_EVERY_S (here every step) before the run's
    checkpoint; --resume then completes it with the samples of an uninterrupted estimate."""
    import io

    from rigidmd.run import bias

    monkeypatch.setattr(bias, "SAVE_EVERY_S", 0.0)
    config = trap_config(tmp_path, timestep="4 fs")
    kwargs = dict(production_ps=1.0, equilibrate_ps=0.2, progress=io.StringIO(),
                  stream=io.StringIO())
    original = Trap.calculate
    _stop_at_call(monkeypatch, 500, Killed())  # in the second run (the first: ~360 calls)
    with pytest.raises(Killed):
        estimate_bias(config, tmp_path / "out", **kwargs)
    saved = json.loads((tmp_path / "out" / "bias.json").read_text())
    first, second = saved["legs_record"]
    assert first["done"] and not second["done"] and second["samples"]["step"]
    assert saved["status"] is None  # written while running
    assert (tmp_path / "out" / "leg-dt-2.npz").exists()
    monkeypatch.setattr(Trap, "calculate", original)
    resumed = estimate_bias(config, tmp_path / "out", resume=True, **kwargs)
    whole = estimate_bias(config, tmp_path / "whole", **kwargs)
    assert resumed["complete"] and resumed["status"] == 0
    for a, b in zip(resumed["legs_record"], whole["legs_record"], strict=True):
        assert a["samples"] == b["samples"]


def test_the_command_that_continues_works_from_any_folder(tmp_path, monkeypatch):
    """The configuration was given as typed (relative), --outdir resolved: from another
    folder the printed command failed with "no such file"."""
    from rigidmd.run import bias

    args = _command(tmp_path)
    args[1] = "bias.yaml"
    monkeypatch.chdir(tmp_path)
    hints = []
    monkeypatch.setattr(bias, "estimate_bias", lambda *a, hint=None, **k: hints.append(hint)
                        or {"status": 0})
    assert cli.main(args) == 0
    assert f"rigidmd bias {tmp_path / 'bias.yaml'} " in hints[0]

