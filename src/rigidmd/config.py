"""Run configurations for the ``rigidmd`` command: reading, checking, building.

A configuration is a YAML mapping (every key optional except ``structure``
and ``steps``)::

    structure: water.xyz          # any file ase.io.read reads, or a builder:
    #   {builtin: water_cluster, n_molecules: 32, seed: 0}  (or water_box, n_side)
    read_options: {format: lammps-data, atom_style: full}   # passed to ase.io.read
    bodies: connectivity          # connectivity | mol-id | tags
    calculator:
      name: tip3p                 # tip3p | tip4p | lammps | a dotted class path
      options: {rc: 9.0}          # keyword arguments of the calculator
      pair: [...]                 # lammps: LAMMPS pair commands
      charges: {O: -0.834, H: 0.417}   # lammps: charge per element
    integrator: no_squish         # or richardson, rozmanov_kusalik, pcdm, exadem
    integrator_options: {}
    thermostat:                   # omit for NVE
      kind: langevin              # langevin | bussi | nose_hoover
      temperature: 300 K
      friction: 0.01 1/fs         # langevin;  taut: 100 fs (bussi);  tdamp: 100 fs
    velocities: {temperature: 250 K, seed: 0}   # draw rigid velocities first
    timestep: 1 fs                # with a unit: fs, ps, or ase (ASE time units)
    steps: 2000
    restart: previous.traj        # continue from the last frame of a trajectory
    outputs:
      directory: .
      trajectory: md.traj
      log: md.log
      interval: 10                # steps between frames and log lines
      plot: energy.png            # energy and temperature against time
      mdanalysis: md.xtc          # needs rigidmd[analysis]

Quantities with units are strings ``"<number> <unit>"``.  Every mistake is
a :class:`ConfigError` naming the field.
"""

import importlib
from pathlib import Path

import numpy as np
from ase import units

__all__ = ["ConfigError", "load_config", "check_config", "parse_quantity", "DEMO_CONFIG"]

TIME_UNITS = {"fs": units.fs, "ps": 1000 * units.fs, "ase": 1.0}
RATE_UNITS = {"1/fs": 1 / units.fs, "1/ps": 1 / (1000 * units.fs), "1/ase": 1.0}
TEMPERATURE_UNITS = {"K": 1.0}

#: The built-in demo: a TIP3P water cluster, 2 ps at 1 fs.
DEMO_CONFIG = {
    "structure": {"builtin": "water_cluster", "n_molecules": 32, "seed": 0},
    "calculator": {"name": "tip3p", "options": {"rc": 40.0}},
    "velocities": {"temperature": "250 K", "seed": 0},
    "timestep": "1 fs",
    "steps": 2000,
    "outputs": {"directory": "rigidmd-demo", "trajectory": "demo.traj", "log": "demo.log",
                "interval": 20, "plot": "demo-energy.png"},
}

_KEYS = {
    "structure", "read_options", "bodies", "calculator", "integrator", "integrator_options",
    "thermostat", "velocities", "timestep", "steps", "restart", "outputs",
}
_OUTPUT_KEYS = {"directory", "trajectory", "log", "interval", "plot", "mdanalysis"}
_CALCULATOR_KEYS = {"name", "options", "pair", "charges", "atom_types"}
_THERMOSTATS = {"langevin": "friction", "bussi": "taut", "nose_hoover": "tdamp"}


class ConfigError(ValueError):
    """A configuration mistake; the message starts with the field at fault."""


def parse_quantity(field, value, unit_table, default_unit=None):
    """``"1 fs"`` → 1 fs in ASE units, with the unit looked up in ``unit_table``.

    A bare number is accepted only when ``default_unit`` is given.
    """
    if isinstance(value, bool):
        raise ConfigError(f"{field}: expected a quantity such as '1 {next(iter(unit_table))}'")
    if isinstance(value, (int, float)):
        if default_unit is None:
            raise ConfigError(
                f"{field}: give a unit, e.g. '{value} {next(iter(unit_table))}' "
                f"(units: {', '.join(unit_table)})")
        return float(value) * unit_table[default_unit]
    parts = str(value).split()
    if len(parts) != 2:
        raise ConfigError(f"{field}: expected '<number> <unit>', got {value!r}")
    number, unit = parts
    try:
        number = float(number)
    except ValueError:
        raise ConfigError(f"{field}: {number!r} is not a number") from None
    if unit not in unit_table:
        raise ConfigError(f"{field}: unknown unit {unit!r}; use one of {', '.join(unit_table)}")
    return number * unit_table[unit]


def _mapping(field, value, allowed=None):
    if not isinstance(value, dict):
        raise ConfigError(f"{field}: expected a mapping, got {type(value).__name__}")
    if allowed is not None:
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            raise ConfigError(
                f"{field}.{unknown[0]}: unknown key; allowed: {', '.join(sorted(allowed))}")
    return value


def load_config(path):
    """Read a YAML configuration file (not yet checked)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config: no such file {str(path)!r}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ConfigError(f"config: {path} is not valid YAML ({err})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config: {path} must hold a mapping of settings")
    # Relative paths in the file are relative to the file.
    data.setdefault("_base", str(path.resolve().parent))
    return data


def check_config(config):
    """Validate a configuration and normalise it (units to ASE, paths resolved).

    Returns
    -------
    dict
        With ``timestep`` in ASE time units, thermostat times and rates in
        ASE units, temperatures in K and paths as :class:`pathlib.Path`.
    """
    config = dict(config)
    base = Path(config.pop("_base", "."))
    unknown = sorted(set(config) - _KEYS)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown key; allowed: {', '.join(sorted(_KEYS))}")
    out = {}
    if "structure" not in config and "restart" not in config:
        raise ConfigError("structure: missing (a file name or {builtin: water_cluster, ...})")
    structure = config.get("structure")
    if isinstance(structure, dict):
        _mapping("structure", structure)
        if structure.get("builtin") not in ("water_cluster", "water_box"):
            raise ConfigError("structure.builtin: use water_cluster or water_box")
        out["structure"] = dict(structure)
    elif structure is not None:
        path = base / str(structure)
        if not path.is_file():
            raise ConfigError(f"structure: no such file {str(path)!r}")
        out["structure"] = path
    out["read_options"] = dict(_mapping("read_options", config.get("read_options", {})))
    if "restart" in config:
        path = base / str(config["restart"])
        if not path.is_file():
            raise ConfigError(f"restart: no such file {str(path)!r}")
        out["restart"] = path
    bodies = config.get("bodies", "connectivity")
    if bodies not in ("connectivity", "mol-id", "tags"):
        raise ConfigError(f"bodies: use connectivity, mol-id or tags, got {bodies!r}")
    out["bodies"] = bodies

    calc = _mapping("calculator", config.get("calculator", {"name": "tip3p"}), _CALCULATOR_KEYS)
    if "name" not in calc:
        raise ConfigError("calculator.name: missing (tip3p, tip4p, lammps or a dotted path)")
    out["calculator"] = dict(calc)
    _mapping("calculator.options", calc.get("options", {}))
    if calc["name"] == "lammps" and not calc.get("pair"):
        raise ConfigError("calculator.pair: the lammps calculator needs LAMMPS pair commands")

    out["integrator"] = config.get("integrator", "no_squish")
    out["integrator_options"] = dict(_mapping("integrator_options",
                                              config.get("integrator_options", {})))
    try:
        from rigidmd.schemes import resolve_scheme

        integrator = out["integrator"]
        if isinstance(integrator, str) and integrator.endswith((".yaml", ".yml")):
            integrator = str(base / integrator)
            out["integrator"] = integrator
        resolve_scheme(integrator, **out["integrator_options"])
    except (ValueError, TypeError) as err:
        raise ConfigError(f"integrator: {err}") from None

    if "thermostat" in config:
        th = _mapping("thermostat", config["thermostat"])
        kind = th.get("kind")
        if kind not in _THERMOSTATS:
            raise ConfigError(f"thermostat.kind: use {', '.join(_THERMOSTATS)}, got {kind!r}")
        allowed = {"kind", "temperature", _THERMOSTATS[kind], "seed"}
        if kind == "nose_hoover":
            allowed |= {"tchain", "tloop"}
        _mapping("thermostat", th, allowed)
        if "temperature" not in th:
            raise ConfigError("thermostat.temperature: missing (e.g. '300 K')")
        param = _THERMOSTATS[kind]
        if param not in th:
            raise ConfigError(f"thermostat.{param}: missing for {kind}")
        checked = {"kind": kind,
                   "temperature_K": parse_quantity("thermostat.temperature", th["temperature"],
                                                   TEMPERATURE_UNITS),
                   "seed": th.get("seed")}
        table = RATE_UNITS if param == "friction" else TIME_UNITS
        checked[param] = parse_quantity(f"thermostat.{param}", th[param], table)
        for key in ("tchain", "tloop"):
            if key in th:
                checked[key] = th[key]
        out["thermostat"] = checked

    if "velocities" in config:
        vel = _mapping("velocities", config["velocities"], {"temperature", "seed"})
        out["velocities"] = {
            "temperature_K": parse_quantity("velocities.temperature", vel.get("temperature"),
                                            TEMPERATURE_UNITS),
            "seed": vel.get("seed"),
        }

    if "timestep" not in config:
        raise ConfigError("timestep: missing (e.g. '1 fs')")
    out["timestep"] = parse_quantity("timestep", config["timestep"], TIME_UNITS)
    if not out["timestep"] > 0:
        raise ConfigError("timestep: must be positive")
    steps = config.get("steps")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ConfigError(f"steps: expected a whole number >= 0, got {steps!r}")
    out["steps"] = steps

    outputs = _mapping("outputs", config.get("outputs", {}), _OUTPUT_KEYS)
    directory = base / str(outputs.get("directory", "."))
    interval = outputs.get("interval", 10)
    if isinstance(interval, bool) or not isinstance(interval, int) or interval < 1:
        raise ConfigError(f"outputs.interval: expected a whole number >= 1, got {interval!r}")
    out["outputs"] = {
        "directory": directory,
        "interval": interval,
        **{key: directory / str(outputs[key])
           for key in ("trajectory", "log", "plot", "mdanalysis") if outputs.get(key)},
    }
    if "mdanalysis" in out["outputs"]:
        try:
            importlib.import_module("MDAnalysis")
        except ImportError:
            raise ConfigError('outputs.mdanalysis: needs MDAnalysis '
                              '(pip install "rigidmd[analysis]")') from None
    return out


def build_calculator(spec, atoms):
    """An ASE calculator from a checked ``calculator`` section."""
    name = spec["name"]
    options = dict(spec.get("options", {}))
    try:
        if name == "tip3p":
            from ase.calculators.tip3p import TIP3P

            return TIP3P(**options)
        if name == "tip4p":
            from ase.calculators.tip4p import TIP4P

            return TIP4P(**options)
        if name == "lammps":
            from rigidmd.lammps import load_lammps

            load_lammps()
            from ase.calculators.lammpslib import LAMMPSlib

            charges = spec.get("charges")
            if charges:
                _mapping("calculator.charges", charges)
                missing = sorted(set(atoms.get_chemical_symbols()) - set(charges))
                if missing:
                    raise ConfigError(f"calculator.charges: no charge for {missing[0]}")
                atoms.set_initial_charges([charges[s] for s in atoms.get_chemical_symbols()])
            symbols = list(dict.fromkeys(atoms.get_chemical_symbols()))
            atom_types = spec.get("atom_types") or {s: i + 1 for i, s in enumerate(symbols)}
            return LAMMPSlib(lmpcmds=list(spec["pair"]), atom_types=atom_types,
                             lammps_header=["units metal", "atom_style full",
                                            "atom_modify map array sort 0 0"],
                             keep_alive=True, **options)
        module_name, _, class_name = name.rpartition(".")
        if not module_name:
            raise ConfigError(f"calculator.name: {name!r} is not tip3p, tip4p, lammps or a "
                              "dotted path such as ase.calculators.emt.EMT")
        try:
            cls = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as err:
            raise ConfigError(f"calculator.name: cannot import {name!r} ({err})") from None
        return cls(**options)
    except TypeError as err:
        raise ConfigError(f"calculator.options: {err}") from None


def build_atoms(config):
    """The starting Atoms of a checked configuration (restart frame, file or builder)."""
    from ase.io import read

    if "restart" in config:
        try:
            atoms = read(config["restart"], index=-1)
        except Exception as err:  # ASE raises many kinds for unreadable files
            raise ConfigError(f"restart: cannot read {str(config['restart'])!r} ({err})") from None
        atoms.calc = None
        return atoms
    structure = config["structure"]
    if isinstance(structure, dict):
        from rigidmd import systems

        options = {k: v for k, v in structure.items() if k != "builtin"}
        try:
            return getattr(systems, structure["builtin"])(**options)
        except TypeError as err:
            raise ConfigError(f"structure: {err}") from None
    try:
        atoms = read(structure, **config["read_options"])
    except Exception as err:  # noqa: BLE001 - any reader failure is a config mistake
        raise ConfigError(f"structure: cannot read {str(structure)!r} ({err})") from None
    if isinstance(atoms, list):
        atoms = atoms[-1]
    return atoms


def thermostat_kwargs(config):
    """Class and keyword arguments of the dynamics for a checked configuration."""
    from rigidmd import RigidBussi, RigidLangevin, RigidNoseHoover, RigidVerlet

    th = config.get("thermostat")
    if th is None:
        return RigidVerlet, {}
    rng = np.random.default_rng(th.get("seed"))
    if th["kind"] == "langevin":
        return RigidLangevin, {"temperature_K": th["temperature_K"], "friction": th["friction"],
                               "rng": rng}
    if th["kind"] == "bussi":
        return RigidBussi, {"temperature_K": th["temperature_K"], "taut": th["taut"], "rng": rng}
    extra = {k: th[k] for k in ("tchain", "tloop") if k in th}
    return RigidNoseHoover, {"temperature_K": th["temperature_K"], "tdamp": th["tdamp"], **extra}
