"""What a configuration file may make rigidmd run: no code of its own unless trusted.

A configuration is data: reading one must not run a program, load code or
write files other than the run's outputs.  Two of its fields could do all
of that, and are checked here before anything is imported or started:

* ``calculator.name``, a dotted path: it must name an ASE calculator
  class (a subclass of ``ase.calculators.calculator.BaseCalculator``);
  functions and other callables (``os.system``) are refused always.
  Without ``--trust`` these are refused too: a module of Python's standard
  library (importing one may run code: ``antigravity``), and the calculator
  classes that start programs or run commands given in their options
  (ASE's ``FileIOCalculator``, ``GenericFileIOCalculator`` and
  ``SocketIOCalculator`` and their subclasses, ``LAMMPSlib``, ``lammpsrun``).
* LAMMPS commands (``calculator.commands`` of ``name: lammps``, or the
  ``commands`` option of :class:`~rigidmd.lammps.LAMMPSCalculator` named by
  its dotted path): without ``--trust`` only the commands that define
  interactions (:data:`SAFE_LAMMPS_COMMANDS`) are accepted, without ``$``
  substitution (which could spell any command) and without Python pair
  styles.  LAMMPS's ``shell`` (runs programs), ``python`` and ``plugin``
  (run code), ``include`` and ``jump`` (read other input files), ``if``
  and ``run ... every`` (run commands given as strings) and the commands
  that write files (``dump``, ``write_*``, ``log``, ``print``) are refused;
  so is the calculator's ``cmdargs`` option (LAMMPS's command line).

``rigidmd run --trust`` (and ``export-lammps --trust``) lifts these checks
for a configuration the user wrote or has read.
"""

import importlib
import sys

from rigidmd.config.quantities import ConfigError

__all__ = ["SAFE_LAMMPS_COMMANDS", "check_lammps_commands", "calculator_class"]

#: LAMMPS commands a configuration may give without ``--trust``: interactions only.
SAFE_LAMMPS_COMMANDS = frozenset({
    "pair_style", "pair_coeff", "pair_modify", "kspace_style", "kspace_modify",
    "bond_style", "bond_coeff", "angle_style", "angle_coeff", "dihedral_style",
    "dihedral_coeff", "improper_style", "improper_coeff", "special_bonds", "dielectric",
    "mass", "neighbor", "neigh_modify", "comm_modify", "newton", "labelmap",
})

#: Calculator classes that run programs or commands given in their options.
_RUNS_PROGRAMS = (
    ("ase.calculators.calculator", "FileIOCalculator"),
    ("ase.calculators.genericfileio", "GenericFileIOCalculator"),
    ("ase.calculators.socketio", "SocketIOCalculator"),
    ("ase.calculators.lammpslib", "LAMMPSlib"),
    ("ase.calculators.lammpsrun", "LAMMPS"),
)

_TRUST_HINT = "give it only in a configuration you trust, with rigidmd run --trust"


def check_lammps_commands(where, commands):
    """Refuse (ConfigError naming ``where``) LAMMPS commands that could run code or write files.

    Parameters
    ----------
    where : str
        The configuration field, e.g. ``"calculator.commands"``.
    commands : sequence of str
        One LAMMPS command per item (a multi-line item is split into lines).
    """
    lines = [line for command in commands for line in str(command).splitlines()]
    for line in lines:
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        name = words[0]
        if "$" in line:
            raise ConfigError(f"{where}: {line.strip()!r}: LAMMPS substitutes $ variables "
                              f"before it reads a command, which could spell any command; "
                              f"{_TRUST_HINT}")
        if name not in SAFE_LAMMPS_COMMANDS:
            raise ConfigError(
                f"{where}: {line.strip()!r}: {name} is not an interaction command (LAMMPS's "
                "shell, python, plugin, include, if and file-writing commands run programs, "
                f"code or other input files); {_TRUST_HINT}")
        if name == "pair_style" and any(w == "python" or w.startswith("python/")
                                        for w in words[1:]):
            raise ConfigError(f"{where}: {line.strip()!r}: pair style python imports Python "
                              f"code; {_TRUST_HINT}")


def _lammps_options(where, options):
    if "cmdargs" in options:
        raise ConfigError(f"{where}.cmdargs: LAMMPS's command line can read input files and "
                          f"load code; {_TRUST_HINT}")


def check_lammps_calculator(options, commands):
    """``name: lammps`` without ``--trust``: its commands and options."""
    check_lammps_commands("calculator.commands", commands)
    _lammps_options("calculator.options", options)


def calculator_class(name, options, trust):
    """The ASE calculator class a dotted ``calculator.name`` names, checked.

    Parameters
    ----------
    name : str
        ``module.Class``.
    options : dict
        ``calculator.options`` (checked for a LAMMPSCalculator's commands).
    trust : bool
        ``--trust``: allow standard-library modules, classes that run programs
        and any LAMMPS command.

    Returns
    -------
    type
        A subclass of ``ase.calculators.calculator.BaseCalculator``.
    """
    from ase.calculators.calculator import BaseCalculator

    module_name, _, class_name = name.rpartition(".")
    if not module_name or not class_name:
        raise ConfigError(f"calculator.name: {name!r} is not tip3p, tip4p, lammps or a dotted "
                          "path such as ase.calculators.emt.EMT")
    top = module_name.split(".")[0]
    if not trust and top in getattr(sys, "stdlib_module_names", ()):
        raise ConfigError(f"calculator.name: {name!r} is in Python's standard library, which "
                          f"has no ASE calculator (importing a module runs it); {_TRUST_HINT}")
    try:
        found = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as err:
        raise ConfigError(f"calculator.name: cannot import {name!r} ({err})") from None
    if not (isinstance(found, type) and issubclass(found, BaseCalculator)):
        kind = "a class" if isinstance(found, type) else f"a {type(found).__name__}"
        raise ConfigError(f"calculator.name: {name!r} is {kind}, not an ASE calculator class "
                          "(a subclass of ase.calculators.calculator.BaseCalculator)")
    if trust:
        return found
    for module, cls_name in _RUNS_PROGRAMS:
        try:
            base = getattr(importlib.import_module(module), cls_name)
        except (ImportError, AttributeError):  # pragma: no cover - an older or newer ASE
            continue
        if issubclass(found, base):
            raise ConfigError(f"calculator.name: {name!r} starts programs or runs commands "
                              f"given in its options (an ASE {cls_name}); {_TRUST_HINT}")
    from rigidmd.lammps.calculator import LAMMPSCalculator

    if issubclass(found, LAMMPSCalculator):
        commands = options.get("commands", [])
        check_lammps_commands("calculator.options.commands",
                              [commands] if isinstance(commands, str) else list(commands))
        _lammps_options("calculator.options", options)
    return found
