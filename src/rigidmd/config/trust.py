"""What a configuration may make rigidmd do without ``--trust``: an allow-list.

A configuration is data: reading and running one must not run a program,
import or load code, or write files other than the run's outputs in its own
directory.  Everything a configuration names that could do otherwise is
checked here against what is allowed, before any module it names is
imported, any engine started or any file written; anything not on the
lists is refused with one line naming the field and saying that
``--trust`` allows it.  ``rigidmd run --trust`` (and ``relax --trust``,
``export-lammps --trust``) lifts these limits for a configuration the user
wrote or has read.  What is allowed without it:

* calculators (:data:`ALLOWED_CALCULATORS`): ``tip3p``, ``tip4p``,
  ``lammps``, ``ipi`` and the dotted class paths listed there, each with
  the keyword arguments listed and values of the kinds given (numbers,
  true/false, whole numbers, a choice of words).  A dotted path not on the
  list is refused before its module is imported (importing runs the
  module's code); functions and other callables are never calculators.
  Calculators that start programs or run commands from their options
  (ASE's ``FileIOCalculator`` and ``SocketIOCalculator`` families: CP2K,
  DFTD3, ``command``; ``LAMMPSlib``) are therefore not on it.
* LAMMPS commands (``calculator.commands`` of ``name: lammps``, the
  ``commands`` option of :class:`~rigidmd.lammps.LAMMPSCalculator` or
  :class:`~rigidmd.lammps.LAMMPSEngine` by their dotted paths, and a
  ``kspace_parameters`` option): only the commands that define interactions
  (:data:`SAFE_LAMMPS_COMMANDS`), without ``$`` substitution (which could
  spell any command) and without Python pair styles; their arguments are
  checked too (:func:`check_lammps_commands`): styles on
  :data:`SAFE_LAMMPS_STYLES` only (none that reads a file, evaluates
  expressions or runs code), ``labelmap`` only defining labels, every other
  word a number, a type or a plain word (no path, quote, backquote or ``&``).
  LAMMPS's ``shell``
  (runs programs), ``python`` and ``plugin`` (run code), ``include`` and
  ``jump`` (read other input files), ``if`` and ``run ... every`` (run
  commands given as strings) and the commands that write files (``dump``,
  ``write_*``, ``log``, ``print``) are refused; so is LAMMPS's command
  line (``cmdargs``: ``-log FILE``, ``-in FILE``), with or without a
  ``water_model``.
* files written (:func:`check_output_paths`): ``outputs.directory``
  relative to the configuration's folder and the output files
  (``outputs.trajectory``, ``log``, ``plot``, ``mdanalysis``,
  ``checkpoint``, ``relax.trajectory``, ``relax.log``) relative to it,
  none of them absolute or with a ``..`` part, and none leading outside
  through a symbolic link: a run writes only inside its own directory.  A
  directory given on the command line (``--outdir``) is the user's own
  choice and may be anywhere.
* processes and threads (:func:`check_cores`): at most the machine's cores.
* sockets listened on (:func:`check_listen_address`): ``calculator.address``
  of ``ipi`` and of ``lammps`` (an engine started elsewhere) is a Unix socket
  (``unix:NAME``, a plain name) or a loopback address (``localhost``, ``127.x.x.x``; the
  socket is IPv4: IPv6 addresses are refused).  Any other host (``0.0.0.0``,
  a host name, an interface's address) opens a port other machines can
  reach, and whatever connects
  there is sent the run's positions and cell and its forces are used.

* coupling parts (:func:`coupling_class`): ``thermostat.kind`` and
  ``barostat.kind`` name a registered kind of rigidmd's (``bussi``, ``mtk``, ...);
  a dotted path to a part of your own (``berendsen.BerendsenThermostat``) is
  imported, which runs its module's code, so only with ``--trust``.

Reading (``structure``, ``restart``, an integrator's ``.yaml``) is not
limited: ASE's readers and rigidmd's scheme files run no code.
"""

import importlib
import ipaddress
import math
import os
import re
import sys
from pathlib import Path, PurePath

from rigidmd.config.quantities import ConfigError, key_name, parse_address

__all__ = ["SAFE_LAMMPS_COMMANDS", "SAFE_LAMMPS_STYLES", "safe_style", "ALLOWED_CALCULATORS",
           "GivenOnCommandLine", "check_lammps_commands", "check_calculator",
           "check_output_paths", "check_listen_address", "check_cores", "machine_cores",
           "calculator_class", "coupling_class"]

#: LAMMPS commands a configuration may give without ``--trust``: interactions only.
SAFE_LAMMPS_COMMANDS = frozenset({
    "pair_style", "pair_coeff", "pair_modify", "kspace_style", "kspace_modify",
    "bond_style", "bond_coeff", "angle_style", "angle_coeff", "dihedral_style",
    "dihedral_coeff", "improper_style", "improper_coeff", "special_bonds", "dielectric",
    "mass", "neighbor", "neigh_modify", "comm_modify", "newton", "labelmap",
})

#: Styles (without an accelerator suffix: ``/omp``, ``/opt``, ``/gpu``, ``/intel``, ``/kk``)
#: a configuration may name without ``--trust``: those whose coefficients are numbers.
#: Styles that read files (``table``, ``eam``, ``tersoff``, ``sw``, ``meam``, ``reaxff``,
#: ``snap``, ...), evaluate expressions (``lepton``) or run code (``python``) are left off.
SAFE_LAMMPS_STYLES = {
    "pair": frozenset({
        "beck", "born", "born/coul/dsf", "born/coul/long", "born/coul/msm", "born/coul/wolf",
        "born/gauss", "buck", "buck/coul/cut", "buck/coul/long", "buck/coul/msm",
        "buck/long/coul/long", "buck/mdf", "coul/cut", "coul/cut/global", "coul/cut/soft",
        "coul/debye", "coul/dsf", "coul/long", "coul/long/soft", "coul/msm", "coul/wolf",
        "coul/slater/cut", "coul/slater/long", "gauss", "gauss/cut", "harmonic/cut",
        "hybrid", "hybrid/overlay", "hybrid/scaled", "lennard/mdf",
        "lj/charmm/coul/charmm", "lj/charmm/coul/charmm/implicit", "lj/charmm/coul/long",
        "lj/charmm/coul/long/soft", "lj/charmm/coul/msm", "lj/charmmfsw/coul/charmmfsh",
        "lj/charmmfsw/coul/long", "lj/class2", "lj/class2/coul/cut",
        "lj/class2/coul/cut/soft", "lj/class2/coul/long", "lj/class2/coul/long/soft",
        "lj/class2/soft", "lj/cubic", "lj/cut", "lj/cut/coul/cut", "lj/cut/coul/cut/soft",
        "lj/cut/coul/debye", "lj/cut/coul/dsf", "lj/cut/coul/long", "lj/cut/coul/long/soft",
        "lj/cut/coul/msm", "lj/cut/coul/wolf", "lj/cut/soft", "lj/cut/tip4p/cut",
        "lj/cut/tip4p/long", "lj/cut/tip4p/long/soft", "lj/expand", "lj/expand/coul/long",
        "lj/gromacs", "lj/gromacs/coul/gromacs", "lj/long/coul/long", "lj/long/tip4p/long",
        "lj/mdf", "lj/sf", "lj/smooth", "lj/smooth/linear", "lj96/cut", "mie/cut", "morse",
        "morse/smooth/linear", "morse/soft", "nm/cut", "nm/cut/coul/cut", "nm/cut/coul/long",
        "soft", "tip4p/cut", "tip4p/long", "tip4p/long/soft", "ufm", "yukawa", "zbl",
        "zero"}),
    "bond": frozenset({
        "class2", "fene", "fene/expand", "fene/nm", "gaussian", "gromos", "harmonic",
        "harmonic/restrain", "harmonic/shift", "harmonic/shift/cut", "hybrid", "mm3",
        "morse", "nonlinear", "none", "quartic", "zero"}),
    "angle": frozenset({
        "charmm", "class2", "class2/p6", "cosine", "cosine/buck6d", "cosine/delta",
        "cosine/periodic", "cosine/shift", "cosine/shift/exp", "cosine/squared",
        "cosine/squared/restricted", "cross", "fourier", "fourier/simple", "gaussian",
        "harmonic", "hybrid", "mm3", "none", "quartic", "zero"}),
    "dihedral": frozenset({
        "charmm", "charmmfsw", "class2", "cosine/shift/exp", "cosine/squared/restricted",
        "fourier", "harmonic", "helix", "hybrid", "multi/harmonic", "nharmonic", "none",
        "opls", "quadratic", "zero"}),
    "improper": frozenset({
        "class2", "cossq", "cvff", "distance", "distharm", "fourier", "harmonic", "hybrid",
        "inversion/harmonic", "none", "ring", "sqdistharm", "umbrella", "zero"}),
    "kspace": frozenset({
        "ewald", "ewald/disp", "ewald/dipole", "msm", "msm/cg", "none", "pppm", "pppm/cg",
        "pppm/dipole", "pppm/disp", "pppm/disp/tip4p", "pppm/stagger", "pppm/tip4p"}),
}
#: Accelerator suffixes LAMMPS adds to a style's name.
ACCELERATOR_SUFFIXES = ("omp", "opt", "gpu", "intel", "kk")
#: Keywords with a ``/`` that the allowed commands take (no file names).
_SLASH_KEYWORDS = frozenset({
    "molecule/intra", "molecule/inter", "table/disp", "disp/auto", "kmax/ewald",
    "cutoff/multi", "compute/tally", "neigh/trim", "lj/coul", "mesh/disp", "order/disp",
    "gewald/disp", "force/disp/real", "force/disp/kspace", "mix/disp"})
#: The command whose style each ``*_style``/``*_coeff`` command names.
_STYLE_OF = {"pair_style": "pair", "bond_style": "bond", "angle_style": "angle",
             "dihedral_style": "dihedral", "improper_style": "improper",
             "kspace_style": "kspace", "pair_coeff": "pair", "bond_coeff": "bond",
             "angle_coeff": "angle", "dihedral_coeff": "dihedral",
             "improper_coeff": "improper", "pair_modify": "pair"}
_LABEL_KINDS = ("atom", "bond", "angle", "dihedral", "improper")
#: A word of an allowed command: a number, a type or type range (``*``, ``1*3``) or a
#: plain word (keyword, type label); never quotes, backquotes, ``&`` or a path.
_NUMBER_WORD = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_TYPE_RANGE = re.compile(r"\d*\*\d*")
_PLAIN_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_+\-.=]*")

TRUST_HINT = "rigidmd run --trust allows it (give it only for a configuration you trust)"


def safe_style(category, word):
    """Whether ``word`` is a ``category`` style on :data:`SAFE_LAMMPS_STYLES` (with or
    without an accelerator suffix)."""
    allowed = SAFE_LAMMPS_STYLES[category]
    base, _, suffix = word.rpartition("/")
    return word in allowed or (suffix in ACCELERATOR_SUFFIXES and base in allowed)


def _check_words(where, line, name, words):
    """Refuse a word of an allowed command that could name a file, a style that reads one,
    or text LAMMPS would read in another way (ConfigError naming ``where``)."""
    category = _STYLE_OF.get(name)
    shown = line.strip()
    if name == "labelmap":
        if words[1:2] not in ([kind] for kind in (*_LABEL_KINDS, "clear")):
            raise ConfigError(f"{where}: {shown!r}: labelmap may only define type labels "
                              f"(labelmap atom|bond|angle|dihedral|improper N LABEL ...; "
                              f"labelmap write writes a file); {TRUST_HINT}")
    hybrid = name.endswith("_style") and words[1:2] != [] and words[1].startswith("hybrid")
    for position, word in enumerate(words[1:], start=1):
        style_word = name.endswith("_style") and position == 1
        if not style_word and (_NUMBER_WORD.fullmatch(word) or _TYPE_RANGE.fullmatch(word)):
            continue
        styled = category is not None and safe_style(category, word)
        if name.endswith("_style") and (position == 1 or hybrid or "/" in word):
            if not styled:
                article = "an" if category[0] in "aeiou" else "a"
                raise ConfigError(
                    f"{where}: {shown!r}: {word} is not {article} {category} style a configuration "
                    f"may name without --trust (styles that read files, such as table, eam, "
                    f"tersoff and sw, or run code, such as python, are not; see "
                    f"rigidmd.config.trust.SAFE_LAMMPS_STYLES); {TRUST_HINT}")
            continue
        if styled or word in _SLASH_KEYWORDS or (
                _PLAIN_WORD.fullmatch(word) and word.lower() != "write"):
            continue
        raise ConfigError(f"{where}: {shown!r}: {word!r} is not a number, a type or a plain "
                          f"word (file names, quotes, backquotes and '&' are not read from a "
                          f"configuration); {TRUST_HINT}")


class GivenOnCommandLine(str):
    """A path the user gave on the command line (``--outdir``): not the configuration's."""


# Kinds of option values: (description, test).
def _is_number(value):
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


_NUMBER = ("a number", _is_number)
_POSITIVE = ("a positive number", lambda v: _is_number(v) and v > 0)
_NON_NEGATIVE = ("a number >= 0", lambda v: _is_number(v) and v >= 0)
_FLAG = ("true or false", lambda v: isinstance(v, bool))
_WHOLE = ("a whole number >= 0",
          lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0)
_COUNT = ("a whole number >= 1",
          lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1)
_WHOLE_LIST = ("a list of whole numbers", lambda v: isinstance(v, list) and all(
    isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in v))
_TYPES = ("a mapping of element to LAMMPS type (a whole number >= 1)",
          lambda v: isinstance(v, dict) and all(
              isinstance(k, str) and isinstance(t, int) and not isinstance(t, bool) and t >= 1
              for k, t in v.items()))
_COMMANDS = ("LAMMPS commands (a list of strings)", lambda v: isinstance(v, str) or (
    isinstance(v, list) and all(isinstance(c, str) for c in v)))
_HOSTS = ("a list of host names or IPv4 addresses", lambda v: isinstance(v, list) and v and all(
    isinstance(x, str) and x.strip() for x in v))
_KSPACE = ("a kspace_modify command", lambda v: isinstance(v, str) and v.split()[:1] == [
    "kspace_modify"])


def _choice(*words):
    return (f"one of {', '.join(words)}", lambda v: v in words)


#: Options of ASE's water models.
_WATER = {"rc": _POSITIVE, "width": _POSITIVE}
#: Options of the in-process LAMMPS calculator (``name: lammps``).
_LAMMPS = {"exclude_intramolecular": _FLAG, "ase_constants": _FLAG, "skin": _NON_NEGATIVE,
           "threads": _COUNT, "kspace_parameters": _KSPACE}
#: Options of a LAMMPS engine in its own process (``name: lammps`` with ``processes``).
_ENGINE = {"exclude_intramolecular": _FLAG, "ase_constants": _FLAG, "skin": _NON_NEGATIVE,
           "triclinic": _FLAG, "timeout": _POSITIVE, "connect_timeout": _POSITIVE,
           "peers": _HOSTS}
_DOTTED_LAMMPS = {"commands": _COMMANDS, "atom_types": _TYPES, "molecule_ids": _WHOLE_LIST}

#: What a configuration may name as ``calculator.name`` without ``--trust``, and the
#: ``calculator.options`` each takes (option name -> (kind, test of the value)).
ALLOWED_CALCULATORS = {
    "tip3p": _WATER,
    "tip4p": _WATER,
    "lammps": _LAMMPS,
    "ipi": {"timeout": _POSITIVE, "connect_timeout": _POSITIVE, "peers": _HOSTS},
    "ase.calculators.emt.EMT": {"asap_cutoff": _FLAG},
    "ase.calculators.lj.LennardJones": {"sigma": _POSITIVE, "epsilon": _NUMBER,
                                        "rc": _POSITIVE, "ro": _POSITIVE, "smooth": _FLAG},
    "ase.calculators.morse.MorsePotential": {
        "epsilon": _NUMBER, "r0": _POSITIVE, "rho0": _POSITIVE, "rcut1": _POSITIVE,
        "rcut2": _POSITIVE},
    "ase.calculators.tip3p.TIP3P": _WATER,
    "ase.calculators.tip4p.TIP4P": _WATER,
    "tblite.ase.TBLite": {
        "method": _choice("GFN2-xTB", "GFN1-xTB", "IPEA1-xTB"), "charge": _NUMBER,
        "multiplicity": _COUNT, "accuracy": _POSITIVE, "electronic_temperature": _NON_NEGATIVE,
        "max_iterations": _COUNT, "mixer_damping": _POSITIVE, "verbosity": _WHOLE},
    "rigidmd.lammps.LAMMPSCalculator": {**_LAMMPS, **_DOTTED_LAMMPS},
    "rigidmd.lammps.LAMMPSEngine": {**_ENGINE, **_DOTTED_LAMMPS, "processes": _COUNT,
                                    "threads": _COUNT},
}

#: Why some options are left off the lists (said in the message).
_WHY = {"cmdargs": "LAMMPS's command line can read input files, write files and load code; ",
        "command": "a command runs a program; ",
        "directory": "a calculator's directory is where it writes files; ",
        "label": "a calculator's label names the files it writes; ",
        "workdir": "the engine writes its input files there; ",
        "restart": "a restart file is read by the calculator's own reader; "}

#: Output fields that name files, and the folder each is relative to.
OUTPUT_FILES = {"outputs": ("trajectory", "log", "plot", "mdanalysis", "checkpoint"),
                "relax": ("trajectory", "log")}


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
        words = line.split("#", 1)[0].split()  # (LAMMPS: '#' starts a comment)
        if not words:
            continue
        name = words[0]
        if "$" in line:
            raise ConfigError(f"{where}: {line.strip()!r}: LAMMPS substitutes $ variables "
                              f"before it reads a command, which could spell any command; "
                              f"{TRUST_HINT}")
        if name not in SAFE_LAMMPS_COMMANDS:
            raise ConfigError(
                f"{where}: {line.strip()!r}: {name} is not an interaction command (LAMMPS's "
                "shell, python, plugin, include, if and file-writing commands run programs, "
                f"code or other input files); {TRUST_HINT}")
        if name == "pair_style" and any(w == "python" or w.startswith("python/")
                                        for w in words[1:]):
            raise ConfigError(f"{where}: {line.strip()!r}: pair style python imports Python "
                              f"code; {TRUST_HINT}")
        _check_words(where, line, name, words)


def machine_cores():
    """The cores this process may run on (its CPU affinity; ``os.cpu_count()`` elsewhere)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def check_cores(counts):
    """Refuse (ConfigError naming the field) more processes or threads than the machine has.

    Parameters
    ----------
    counts : dict
        Field name -> whole number or None (not given).  Processes times threads per
        process must not exceed :func:`machine_cores`: a configuration must not start a
        thousand LAMMPS processes.
    """
    cores = machine_cores()
    given = {key: value for key, value in counts.items()
             if isinstance(value, int) and not isinstance(value, bool) and value >= 1}
    total = math.prod(given.values())
    if total > cores:
        field_name = max(given, key=lambda key: given[key])
        asked = " x ".join(f"{key.rpartition('.')[2]} {value}" for key, value in given.items())
        raise ConfigError(f"{field_name}: {asked} needs more cores than this machine gives "
                          f"the run ({cores}); {TRUST_HINT}")


def check_listen_address(where, address):
    """Refuse (ConfigError naming ``where``) a TCP address other machines can reach.

    Parameters
    ----------
    where : str
        The configuration field, e.g. ``"calculator.address"``.
    address : str
        ``unix:NAME`` or ``HOST:PORT`` (read by
        :func:`rigidmd.config.quantities.parse_address`).

    Notes
    -----
    A Unix socket, ``localhost`` and loopback addresses (``127.0.0.0/8``) are
    reachable from this machine only (IPv6 addresses are refused by the parser).
    Any other host, a name included (it may resolve to any interface), needs
    ``--trust``.
    """
    parsed = parse_address(where, address)
    if "unixsocket" in parsed:
        return
    host = parsed["host"]
    if host.lower() == "localhost":
        return
    try:
        if ipaddress.ip_address(host).is_loopback:
            return
    except ValueError:
        pass  # a host name, or "" (every interface)
    shown = repr(host) if host else "'' (every interface)"
    raise ConfigError(f"{where}: {str(address)!r} listens on {shown}, which other machines "
                      f"can reach (an engine connecting there is sent the run's positions and its "
                      f"forces are used); without --trust a configuration may listen only on "
                      f"a Unix socket (unix:NAME) or loopback (localhost:PORT, 127.0.0.1:PORT); "
                      f"{TRUST_HINT}")


def _check_options(where, name, options, allowed):
    """Each option on the list for ``name``, with a value of its kind."""
    for key, value in options.items():
        if key not in allowed:
            listed = ", ".join(allowed) or "none"
            why = _WHY.get(key, "")
            raise ConfigError(f"{where}.{key_name(key)}: {why}not an option a configuration may "
                              f"pass to {name} without --trust (allowed: {listed}); {TRUST_HINT}")
        kind, test = allowed[key]
        if not test(value):
            raise ConfigError(f"{where}.{key_name(key)}: expected {kind}, got {value!r}")
    if "commands" in options:
        commands = options["commands"]
        check_lammps_commands(f"{where}.commands",
                              [commands] if isinstance(commands, str) else commands)
    if "kspace_parameters" in options:
        check_lammps_commands(f"{where}.kspace_parameters", [options["kspace_parameters"]])


def check_calculator(section, trust=False):
    """Refuse what ``section`` (a CalculatorSection) may not name or pass; its class.

    Parameters
    ----------
    section : rigidmd.config.sections.CalculatorSection
    trust : bool
        ``--trust``: any calculator class, option and LAMMPS command.

    Returns
    -------
    type or None
        The class a dotted ``name`` names (None for the built-in names).
    """
    for field_name, test in (("charges", _is_number), ("atom_types", _COUNT[1])):
        for element, value in getattr(section, field_name).items():
            if not test(value):
                kind = "a number (e)" if field_name == "charges" else "a whole number >= 1"
                raise ConfigError(f"calculator.{field_name}.{key_name(element)}: expected {kind}, "
                                  f"got {value!r}")
    name = section.name
    if section.address is not None and not trust:
        check_listen_address("calculator.address", section.address)
    if not trust:
        options = section.options if isinstance(section.options, dict) else {}
        check_cores({"calculator.processes": section.processes,
                     "calculator.threads": section.threads,
                     "calculator.options.processes": options.get("processes"),
                     "calculator.options.threads": options.get("threads")})
    if name in ("tip3p", "tip4p", "lammps", "ipi"):
        if trust:
            return None
        allowed = ALLOWED_CALCULATORS[name]
        engine = name == "lammps" and (section.processes is not None
                                       or section.address is not None)
        if engine:
            allowed = _ENGINE
        if name == "lammps" and section.water is None:
            check_lammps_commands("calculator.commands", section.commands)
        shown = {"tip3p": "ASE's TIP3P", "tip4p": "ASE's TIP4P", "ipi": "the i-PI calculator",
                 "lammps": "a LAMMPS engine" if engine else "the LAMMPS calculator"}[name]
        _check_options("calculator.options", shown, section.options, allowed)
        return None
    return calculator_class(name, section.options, trust)


def calculator_class(name, options, trust):
    """The ASE calculator class a dotted ``calculator.name`` names, checked.

    Without ``trust`` the name must be on :data:`ALLOWED_CALCULATORS` (checked
    before its module is imported) and the options on its list.

    Parameters
    ----------
    name : str
        ``module.Class``.
    options : dict
        ``calculator.options``.
    trust : bool
        ``--trust``: any class (still an ASE calculator class), any option.

    Returns
    -------
    type
        A subclass of ``ase.calculators.calculator.BaseCalculator``.
    """
    module_name, _, class_name = str(name).rpartition(".")
    if not module_name or not class_name:
        raise ConfigError(f"calculator.name: {name!r} is not tip3p, tip4p, lammps, ipi or a "
                          "dotted path such as ase.calculators.emt.EMT")
    if not trust and name not in ALLOWED_CALCULATORS:
        dotted = ", ".join(key for key in ALLOWED_CALCULATORS if "." in key)
        raise ConfigError(f"calculator.name: {name!r} is not a calculator a configuration may "
                          f"name without --trust (allowed: tip3p, tip4p, lammps, ipi, "
                          f"{dotted}); {TRUST_HINT}")
    from ase.calculators.calculator import BaseCalculator

    try:
        found = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as err:
        raise ConfigError(f"calculator.name: cannot import {name!r} ({err})") from None
    if not (isinstance(found, type) and issubclass(found, BaseCalculator)):
        kind = "a class" if isinstance(found, type) else f"a {type(found).__name__}"
        raise ConfigError(f"calculator.name: {name!r} is {kind}, not an ASE calculator class "
                          "(a subclass of ase.calculators.calculator.BaseCalculator)")
    if not trust:
        _check_options("calculator.options", name.rpartition(".")[2], options,
                       ALLOWED_CALCULATORS[name])
    return found


def _inside(field_name, value, trust, optional=True):
    """Refuse an absolute path or one with a ``..`` part (ConfigError naming the field).

    ``optional``: null (or empty) means no such output.
    """
    if optional and value in (None, ""):
        return
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{field_name}: expected a file or folder name, got {value!r}")
    if trust or isinstance(value, GivenOnCommandLine):
        return
    path = PurePath(value)
    if path.is_absolute() or ".." in path.parts:
        raise ConfigError(f"{field_name}: {value!r} is outside the run's directory (a "
                          f"configuration writes only inside it: give a relative path without "
                          f"'..'); {TRUST_HINT}")


#: Files a run writes in its directory when the configuration names none.
DEFAULT_FILES = {"outputs.checkpoint": "checkpoint.npz", "relax.trajectory": "relax.traj",
                 "relax.log": "relax.log"}


def _resolved_inside(field_name, value, path, root, may_be_root=False):
    """Refuse ``path`` if, with its symbolic links followed, it is not inside ``root``
    (or ``root`` itself, for a folder: ``may_be_root``)."""
    resolved = Path(path).resolve()
    if resolved == root and not may_be_root:
        raise ConfigError(f"{field_name}: {str(value)!r} is the run's directory itself, a folder; "
                          "give a file name")
    if not (may_be_root and resolved == root) and root not in resolved.parents:
        raise ConfigError(f"{field_name}: {str(value)!r} leads outside the run's directory "
                          f"through a symbolic link (to {str(resolved)!r}); a configuration "
                          f"writes only inside it; {TRUST_HINT}")


def check_output_paths(raw, trust=False, base=None):
    """Refuse output paths outside the run's directory (see the module's docstring).

    Parameters
    ----------
    raw : dict
        The configuration as read (``outputs`` and ``relax`` mappings).
    trust : bool
        ``--trust``: paths anywhere.
    base : path-like, optional
        The configuration's folder.  Given, the rule also holds for the paths with their
        symbolic links followed: ``outputs.directory`` inside ``base`` (unless given on
        the command line), each output file (named or default) inside the directory.
    """
    outputs = raw.get("outputs")
    if isinstance(outputs, dict) and "directory" in outputs:
        _inside("outputs.directory", outputs["directory"], trust, optional=False)
    for section, keys in OUTPUT_FILES.items():
        values = raw.get(section)
        if isinstance(values, dict):
            for key in keys:
                if key in values:
                    _inside(f"{section}.{key}", values[key], trust,
                            optional=(section, key) != ("outputs", "checkpoint"))
    if trust or base is None:
        return
    outputs = outputs if isinstance(outputs, dict) else {}
    given = outputs.get("directory", ".")
    directory = Path(base) / given
    if not isinstance(given, GivenOnCommandLine):
        _resolved_inside("outputs.directory", given, directory, Path(base).resolve(),
                         may_be_root=True)
    root = directory.resolve()
    files = dict(DEFAULT_FILES)  # (rigidmd relax writes relax's without a relax: section)
    files["outputs.directory"] = ".rigidmd.lock"  # the run's lock (rigidmd.run.outputs)
    calc = raw.get("calculator")
    if isinstance(calc, dict):  # the input of an engine started elsewhere (a split's level's)
        for level in (None, "fast", "slow", "full"):
            spec = calc if level is None else calc.get(level)
            if isinstance(spec, dict) and spec.get("address") is not None:
                where = "calculator" if level is None else f"calculator.{level}"
                files[f"{where}.address"] = "engine" if level is None else f"engine/{level}"
    for section, keys in OUTPUT_FILES.items():
        values = raw.get(section)
        if isinstance(values, dict):
            files.update({f"{section}.{key}": values[key] for key in keys
                          if isinstance(values.get(key), str) and values[key]})
    for field_name, value in files.items():
        _resolved_inside(field_name, value, directory / value, root)


def coupling_class(section, name, trust, base=None):
    """The coupling part class a dotted ``thermostat.kind`` (or ``barostat.kind``) names.

    Without ``trust`` it is refused before its module is imported (importing runs
    the module's code).  With it, the module is imported from Python's path, then
    from the configuration's folder ``base`` (so that ``berendsen.py`` beside the
    configuration is found by the ``rigidmd`` command too); the class must be a
    :class:`rigidmd.couplings.Coupling` of that ``section``, registered with
    :func:`rigidmd.couplings.register` (which its module's import does).

    Parameters
    ----------
    section : str
        ``"thermostat"`` or ``"barostat"``.
    name : str
        ``module.Class``.
    trust : bool
        ``--trust``.
    base : str or os.PathLike, optional
        The configuration's folder.

    Returns
    -------
    type
        The registered class; its ``kind`` is the name in :data:`rigidmd.couplings.COUPLINGS`.
    """
    field = f"{section}.kind"
    module_name, _, class_name = str(name).rpartition(".")
    if not module_name or not class_name:
        raise ConfigError(f"{field}: {name!r} is not a dotted path module.Class")
    if not trust:
        raise ConfigError(f"{field}: {name!r} is a coupling part of your own; importing it runs "
                          f"its module's code, so {TRUST_HINT}")
    from rigidmd.couplings import COUPLINGS, Coupling

    folder = None if base is None else str(Path(base).resolve())
    added = folder is not None and folder not in sys.path
    if added:
        sys.path.append(folder)  # after the installed packages: a local file shadows nothing
    try:
        found = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as err:
        raise ConfigError(f"{field}: cannot import {name!r} ({err})") from None
    finally:
        if added:
            sys.path.remove(folder)
    if not (isinstance(found, type) and issubclass(found, Coupling)):
        raise ConfigError(f"{field}: {name!r} is not a coupling part (a subclass of "
                          "rigidmd.couplings.Coupling)")
    if found.section != section:
        raise ConfigError(f"{field}: {name!r} is a {found.section or 'part of no section'}, "
                          f"not a {section}")
    if COUPLINGS.get(found.kind) is not found:
        raise ConfigError(f"{field}: {name!r} is not registered; decorate the class with "
                          "@rigidmd.couplings.register")
    return found
