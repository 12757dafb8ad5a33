"""The sections of a run configuration: structure, run, calculator, outputs
(rigidmd.config.sections)."""

import pytest
from ase import units
from ase.io import write

from rigidmd.config.quantities import ConfigError
from rigidmd.config.sections import (
    CalculatorSection,
    OutputsSection,
    RunSection,
    StructureSection,
)
from rigidmd.systems import water_cluster


def test_the_structure_from_a_file_a_builder_or_a_restart(tmp_path):
    atoms = water_cluster(3, seed=1)
    write(tmp_path / "start.xyz", atoms)
    section = StructureSection.from_config({"structure": "start.xyz", "bodies": "connectivity"},
                                           tmp_path)
    assert section.source == tmp_path / "start.xyz" and section.restart is None
    built = section.build_atoms()
    assert len(built) == 9 and abs(built.positions - atoms.positions).max() < 1e-6
    assert section.resolve_bodies(built).n_bodies == 3
    builder = StructureSection.from_config(
        {"structure": {"builtin": "water_cluster", "n_molecules": 2, "seed": 0}}, tmp_path)
    assert len(builder.build_atoms()) == 6
    write(tmp_path / "md.traj", [atoms, atoms])
    restart = StructureSection.from_config({"restart": "md.traj"}, tmp_path)
    assert restart.source is None and len(restart.build_atoms()) == 9


@pytest.mark.parametrize("raw, match", [
    ({}, "structure: missing"),
    ({"structure": "none.xyz"}, "structure: no such file"),
    ({"structure": {"builtin": "crystal"}}, "structure.builtin: use water_cluster or water_box,"
                                           " got 'crystal'"),
    ({"structure": {"builtin": "water_cluster"}}, "structure.n_molecules: missing for builtin "
                                                  "water_cluster"),
    ({"structure": {"builtin": "water_cluster", "n": 2}}, "structure.n: unknown key; allowed: "
                                                          "builtin, jitter, model, n_molecules"),
    ({"structure": {"builtin": "water_cluster", "n_molecules": 2}, "bodies": "residues"},
     "bodies: use connectivity, mol-id or tags, got 'residues'"),
    ({"structure": {"builtin": "water_cluster", "n_molecules": 2}, "restart": "none.traj"},
     "restart: no such file"),
])
def test_structure_mistakes(tmp_path, raw, match):
    with pytest.raises(ConfigError, match=match):
        StructureSection.from_config(raw, tmp_path)


def test_an_unreadable_file_is_named_without_its_content(tmp_path):
    (tmp_path / "secret.xyz").write_text("token=abc123\n")
    section = StructureSection.from_config({"structure": "secret.xyz"}, tmp_path)
    with pytest.raises(ConfigError, match="structure: cannot read") as err:
        section.build_atoms()
    assert "abc123" not in str(err.value)


def test_the_run_section(tmp_path):
    run = RunSection.from_config({"timestep": "2 fs", "steps": 10,
                                  "velocities": {"temperature": "300 K", "seed": 3}}, tmp_path)
    assert run.integrator == "no_squish" and run.steps == 10
    assert run.timestep == pytest.approx(2 * units.fs)
    assert run.velocities == {"temperature_K": 300.0, "seed": 3, "stationary": True}
    assert RunSection.from_config({"timestep": "1 fs", "steps": 1}, tmp_path).velocities is None


@pytest.mark.parametrize("raw, match", [
    ({"steps": 1}, r"timestep: missing \(e.g. '1 fs'\)"),
    ({"timestep": "0 fs", "steps": 1}, "timestep: must be positive"),
    ({"timestep": "1 fs", "steps": 0}, "steps: expected a whole number >= 1"),
    ({"timestep": "1 fs", "steps": 1, "integrator": "leapfrog"}, "integrator: "),
    ({"timestep": "1 fs", "steps": 1, "integrator": "none.yaml"}, "integrator"),
    ({"timestep": "1 fs", "steps": 1, "velocities": {"temperature": "-1 K"}},
     "velocities.temperature: must be >= 0 K"),
    ({"timestep": "1 fs", "steps": 1, "velocities": {"temperature": "1 K", "seed": -2}},
     "velocities.seed: expected a whole number"),
])
def test_run_mistakes(tmp_path, raw, match):
    with pytest.raises(ConfigError, match=match):
        RunSection.from_config(raw, tmp_path)


def test_the_calculator_section(tmp_path):
    assert CalculatorSection.from_config({}, tmp_path).name == "tip3p"
    # tip3p is the default of a section that gives only options (was "calculator.name:
    # missing", the documented way to change rc refused).
    options_only = CalculatorSection.from_config({"calculator": {"options": {"rc": 9.0}}},
                                                 tmp_path)
    assert options_only.name == "tip3p" and options_only.options == {"rc": 9.0}
    lammps = CalculatorSection.from_config(
        {"calculator": {"name": "lammps", "pair": "pair_style lj/cut 8\npair_coeff * * 0 1",
                        "atom_types": {"O": 1, "H": 2}}}, tmp_path)
    assert lammps.commands == ["pair_style lj/cut 8", "pair_coeff * * 0 1"]
    water = CalculatorSection.from_config(
        {"calculator": {"name": "lammps", "water_model": {"name": "tip4p2005", "cutoff": 9.0}}},
        tmp_path)
    assert water.water.sites == 4 and water.atom_types == {"O": 1, "H": 2, "X": 3}
    assert any(c.startswith("pair_style") for c in water.commands)


@pytest.mark.parametrize("calc, match", [
    ({"name": 3}, "calculator.name: expected tip3p, tip4p, lammps, ipi or a dotted"),
    ({"name": "lammps"}, "calculator.commands: the lammps calculator needs LAMMPS commands"),
    ({"name": "lammps", "commands": ["a"], "pair": ["b"]}, "calculator.pair: give the LAMMPS "
                                                          "commands once"),
    ({"name": "lammps", "commands": [1]}, "calculator.commands: expected LAMMPS commands"),
    ({"name": "tip3p", "water_model": {"name": "spce"}}, "calculator.water_model: goes with "
                                                         "name: lammps"),
    ({"name": "lammps", "water_model": {"name": "spce"}, "charges": {"O": -1}},
     "calculator.charges: water_model gives the commands"),
])
def test_calculator_mistakes(tmp_path, calc, match):
    with pytest.raises(ConfigError, match=match):
        CalculatorSection.from_config({"calculator": calc}, tmp_path)


def test_the_outputs_section(tmp_path):
    out = OutputsSection.from_config({"outputs": {"directory": "out", "interval": 7,
                                                  "trajectory": "md.traj", "log": "md.log",
                                                  "plot": "e.svg"}},
                                     tmp_path)
    assert out.directory == tmp_path / "out" and out.interval == 7
    assert out.files == {"trajectory": tmp_path / "out" / "md.traj",
                         "log": tmp_path / "out" / "md.log",
                         "plot": tmp_path / "out" / "e.svg"}
    assert out.checkpoint == tmp_path / "out" / "checkpoint.npz"
    assert out.checkpoint_interval == 1001  # 1000 steps rounded up to a frame
    with pytest.raises(ConfigError, match="outputs.checkpoint_interval: 10 is not a multiple "
                                          r"of outputs.interval \(7\)"):
        OutputsSection.from_config({"outputs": {"interval": 7, "checkpoint_interval": 10}},
                                   tmp_path)
    with pytest.raises(ConfigError, match="outputs.plot: e.txt is not an image file"):
        OutputsSection.from_config({"outputs": {"plot": "e.txt"}}, tmp_path)
    # A run's MDAnalysis trajectory is .xtc, which --resume continues: before, .dcd ran and
    # could never be resumed, and .pdb failed only when the run began (after a relaxation).
    with pytest.raises(ConfigError, match="outputs.mdanalysis: md.dcd: a run writes .xtc, "
                                          "which --resume continues"):
        OutputsSection.from_config({"outputs": {"mdanalysis": "md.dcd"}}, tmp_path)
    with pytest.raises(ConfigError, match="outputs.mdanalysis: md.pdb is not an .xtc"):
        OutputsSection.from_config({"outputs": {"mdanalysis": "md.pdb"}}, tmp_path)
    # A plot without the log it is drawn from ran, and said "wrote" a file it never wrote.
    with pytest.raises(ConfigError, match="outputs.plot: e.png is drawn from the MD log"):
        OutputsSection.from_config({"outputs": {"plot": "e.png", "log": None}}, tmp_path)


@pytest.mark.parametrize("key, value, message", [
    ("trajectory", "", "outputs.trajectory: expected a file name (leave the field out, or "
                       "null, for none), got ''"),
    ("log", False, "outputs.log: expected a file name (leave the field out, or null, for "
                   "none), got False"),
    ("checkpoint", "", "outputs.checkpoint: expected a file name, got ''"),
    ("directory", " ", "outputs.directory: expected a file name, got ' '"),
    ("plot", 0, "outputs.plot: expected a file name (leave the field out, or null, for "
                "none), got 0"),
])
def test_an_output_that_names_no_file_is_refused(tmp_path, key, value, message):
    """``trajectory: ""`` or ``log: false`` ran without that output and said nothing (only
    null, or leaving the field out, means none); ``checkpoint: ""`` named the output folder
    itself as the checkpoint file."""
    with pytest.raises(ConfigError) as err:
        OutputsSection.from_config({"outputs": {key: value}}, tmp_path)
    assert str(err.value) == message
    assert list(tmp_path.iterdir()) == []
    none = OutputsSection.from_config({"outputs": {"trajectory": None, "log": "md.log"}},
                                      tmp_path)
    assert set(none.files) == {"log"}


@pytest.mark.parametrize("field", ["charges: {O: -2.0, H: 1.0}", "atom_types: {O: 1, H: 2}",
                                   "commands: ['pair_style zero 1.0']"])
def test_lammps_fields_of_another_calculator_are_refused(field):
    """They change nothing for tip3p, and were ignored in silence (charges too)."""
    import yaml

    from rigidmd.config import check_config

    raw = {"structure": {"builtin": "water_cluster", "n_molecules": 2}, "steps": 1,
           "timestep": "1 fs", "calculator": {"name": "tip3p", **yaml.safe_load(field)}}
    name = field.split(":")[0]
    with pytest.raises(ConfigError, match=f"calculator.{name}: goes with name: lammps, not "
                                          "'tip3p'"):
        check_config(raw)


def test_tip3p_puts_its_charges_on_the_atoms():
    """For what reads them (the run's PSF topology, a dielectric constant): before, the
    topology of a tip3p run had zero charges and ε read 1."""
    from rigidmd.config import check_config

    config = check_config({"structure": {"builtin": "water_cluster", "n_molecules": 2},
                           "calculator": {"name": "tip3p"}, "steps": 1, "timestep": "1 fs"})
    atoms = config.structure.build_atoms()
    config.calculator.build(atoms)
    assert list(atoms.get_initial_charges()) == pytest.approx([-0.834, 0.417, 0.417] * 2)


@pytest.mark.parametrize("field", ["structure", "restart"])
def test_a_file_field_that_is_no_file_name_is_refused_in_one_line(tmp_path, field):
    """Found by the configuration fuzz test: a mapping under ``restart:`` became a path of
    its text, and ``is_file`` raised the system's OSError (file name too long)."""
    raw = {"structure": {"builtin": "water_cluster", "n_molecules": 2}}
    for value, match in [([{"a": 1}], f"^{field}: expected a file name, got list$"),
                         ("x" * 5000, f"^{field}: not a usable file name \\(OSError: "),
                         ("a\0b", f"^{field}: no such file "),  # pathlib: no such file
                         ("missing.xyz", f"^{field}: no such file ")]:
        with pytest.raises(ConfigError, match=match):
            StructureSection.from_config(raw | {field: value}, tmp_path)


def test_the_water_box_builder_takes_whole(tmp_path):
    """``whole`` is water_box's own argument (molecules whole across the faces, the
    default, or wrapped atom by atom); the section refused it as an unknown key."""
    for whole in (True, False):
        section = StructureSection.from_config(
            {"structure": {"builtin": "water_box", "n_side": 2, "seed": 1, "whole": whole}},
            tmp_path)
        atoms = section.build_atoms()
        scaled = atoms.get_scaled_positions(wrap=False)
        inside = bool(((scaled >= 0) & (scaled < 1)).all())
        assert inside != whole  # whole molecules stick out of the cell; wrapped atoms do not
    with pytest.raises(ConfigError, match="^structure.whole: use true or false, got 'yes'$"):
        StructureSection.from_config(
            {"structure": {"builtin": "water_box", "n_side": 2, "whole": "yes"}}, tmp_path)


def test_an_empty_frame_selection_and_a_missing_atom_type_are_named(tmp_path):
    """``read_options: {index: "5:"}`` on a 3-frame file failed with IndexError (a
    traceback); LAMMPS ``atom_types`` without H stopped the run at step 0 (exit 1) where
    the same mistake in ``charges`` is a configuration error (exit 2)."""
    from rigidmd.config import check_config

    frames = [water_cluster(2, seed=s) for s in range(3)]
    write(tmp_path / "three.xyz", frames)
    section = StructureSection.from_config(
        {"structure": "three.xyz", "read_options": {"index": "5:"}}, tmp_path)
    with pytest.raises(ConfigError, match=r"^read_options.index: '5:' selects no frame of "):
        section.build_atoms()
    raw = {"structure": {"builtin": "water_cluster", "n_molecules": 2}, "timestep": "1 fs",
           "steps": 2, "_base": str(tmp_path),
           "calculator": {"name": "lammps", "commands": ["pair_style lj/cut 4.0",
                                                         "pair_coeff * * 0.0 1.0"],
                          "atom_types": {"O": 1}}}
    checked = check_config(raw)
    atoms = checked.structure.build_atoms()
    with pytest.raises(ConfigError, match=r"^calculator.atom_types: no LAMMPS type for H"):
        checked.calculator.build(atoms)


def test_read_options_mistakes_name_the_option(tmp_path):
    """``read_options: {fromat: xyz}`` said "ASE's reader ... failed with TypeError: not a
    structure in that format?"; ``{format: 5}`` said to give a format."""
    write(tmp_path / "w.xyz", water_cluster(2, seed=1))
    for options, message in (({"fromat": "xyz"}, r"^read_options.fromat: not an option of "),
                             ({"format": 5}, r"^read_options.format: expected a format name")):
        section = StructureSection.from_config({"structure": "w.xyz", "read_options": options},
                                               tmp_path)
        with pytest.raises(ConfigError, match=message):
            section.build_atoms()


@pytest.mark.parametrize("threads, options", [(2, 1), (2, 2)])
def test_threads_given_twice_are_refused(tmp_path, threads, options):
    """``calculator: {threads: 2, options: {threads: 1}}`` ran 1 thread without a word
    (``options.setdefault("threads", ...)``); two counts are refused in one line."""
    calc = {"name": "lammps", "commands": ["pair_style lj/cut 3.0", "pair_coeff * * 0 1"],
            "threads": threads, "options": {"threads": options}}
    with pytest.raises(ConfigError, match=rf"^calculator.options.threads: {options} beside "
                                          rf"calculator.threads: {threads}; give the OpenMP "
                                          "threads once, as calculator.threads$"):
        CalculatorSection.from_config({"calculator": calc}, tmp_path)


def test_read_options_are_the_restarts_without_a_structure_file(tmp_path):
    """``restart: prev.data`` with ``read_options: {format: lammps-data, ...}`` was read
    without its options (``read(restart, index=-1)``: "cannot read"); they are the
    restart's when no structure file takes them, ``index`` -1 unless given."""
    frames = [water_cluster(2, seed=s) for s in range(3)]
    for atoms in frames:
        atoms.center(vacuum=10)
    write(tmp_path / "prev.data", frames[0], format="lammps-data", atom_style="full",
          masses=True)
    options = {"format": "lammps-data", "atom_style": "full"}
    for structure in ({}, {"structure": {"builtin": "water_cluster", "n_molecules": 2}}):
        section = StructureSection.from_config(
            {**structure, "restart": "prev.data", "read_options": options}, tmp_path)
        atoms = section.build_atoms()
        assert atoms.get_chemical_formula() == "H4O2" and atoms.calc is None
    write(tmp_path / "three.xyz", frames, format="extxyz")
    last = StructureSection.from_config({"restart": "three.xyz",
                                         "read_options": {"format": "extxyz"}}, tmp_path)
    assert abs(last.build_atoms().positions - frames[2].positions).max() < 1e-6
    first = StructureSection.from_config({"restart": "three.xyz",
                                          "read_options": {"index": 0}}, tmp_path)
    assert abs(first.build_atoms().positions - frames[0].positions).max() < 1e-6
    # A structure file's options are its own: the restart (a .traj) is read by its name.
    write(tmp_path / "start.xyz", frames[0], format="extxyz")
    write(tmp_path / "md.traj", frames)
    both = StructureSection.from_config({"structure": "start.xyz", "restart": "md.traj",
                                         "read_options": {"format": "extxyz"}}, tmp_path)
    assert abs(both.build_atoms().positions - frames[2].positions).max() < 1e-6


def test_read_options_with_a_builtin_structure_are_refused(tmp_path):
    """``read_options`` beside ``structure: {builtin: ...}`` were ignored without a word."""
    with pytest.raises(ConfigError, match=r"^read_options: the builtin water_cluster reads no "
                                          "file; read_options go with a structure file or a "
                                          "restart$"):
        StructureSection.from_config(
            {"structure": {"builtin": "water_cluster", "n_molecules": 2},
             "read_options": {"format": "xyz"}}, tmp_path)


@pytest.mark.parametrize("integrator, options, message", [
    ("rozmanov_kusalik", {"tol": -1},
     "integrator_options.tol: must be positive (for rozmanov_kusalik_rotate), got -1"),
    ("rozmanov_kusalik", {"tol": 1e-10, "max_iter": 0},
     "integrator_options.max_iter: must be a positive integer (for rozmanov_kusalik_rotate), "
     "got 0"),
    ("rozmanov_kusalik", {"tol": "small"},
     "integrator_options.tol: must be a number, got 'small' (for rozmanov_kusalik_rotate)"),
    ("no_squish", {"tol": 1e-10},
     "integrator_options.tol: integrator 'no_squish' takes no parameter 'tol'"),
])
def test_integrator_options_mistakes_name_the_option(tmp_path, integrator, options, message):
    """``integrator_options: {tol: -1}`` was refused as "integrator: scheme entry 2
    (rozmanov_kusalik_rotate): tol must be positive", naming the integrator."""
    with pytest.raises(ConfigError) as err:
        RunSection.from_config({"timestep": "1 fs", "steps": 1, "integrator": integrator,
                                "integrator_options": options}, tmp_path)
    assert str(err.value) == message
