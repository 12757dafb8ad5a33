"""Run configurations for the ``rigidmd`` command: reading, checking, building.

A configuration is a YAML mapping (every key optional except ``structure``
(or ``restart``), ``timestep`` and ``steps``)::

    structure: water.xyz          # any file ase.io.read reads, or a builder:
    #   {builtin: water_cluster, n_molecules: 32, seed: 0}  (or water_box, n_side)
    read_options: {format: lammps-data, atom_style: full}   # passed to ase.io.read
    bodies: mol-id                # mol-id | tags | connectivity (default: the first
                                  # the atoms have: mol-id, tags, else connectivity)
    calculator:
      name: tip3p                 # tip3p | tip4p | lammps | an ASE calculator class's path
      options: {rc: 9.0}          # keyword arguments of the calculator
      commands: [...]             # lammps: pair_style, pair_coeff, kspace_style, ...
      charges: {O: -0.834, H: 0.417}   # lammps: charge per element
    integrator: no_squish         # or richardson, rozmanov_kusalik, pcdm, exadem
    integrator_options: {}
    thermostat:                   # omit for NVE
      kind: langevin              # langevin | bussi | nose_hoover
      temperature: 300 K
      friction: 0.01 1/fs         # langevin;  taut: 100 fs (bussi);  tdamp: 100 fs
    barostat:                     # omit for constant volume (a periodic cell and a
      kind: mtk                   # calculator with stress); mtk | crescale | monte_carlo
      pressure: 1 bar             # bar, atm, GPa, Pa or eV/A^3
      pdamp: 1 ps                 # mtk;  crescale: taup: 1 ps, compressibility: 4.5e-5 1/bar
      couple: iso                 # iso | aniso | tri
                                  # monte_carlo (no stress needed): every: 25, seed: 0,
                                  # adapt_moves: 500
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
      checkpoint: checkpoint.npz  # the default; written every checkpoint_interval steps
      checkpoint_interval: 1000   # (default) and at every stop; rigidmd run --resume reads it
    relax:                        # relax first (rigid bodies, optionally the cell); see
      fmax: 0.05                  # rigidmd.config.relaxsection; rigidmd relax CONFIG
      optimizer: BFGS             # relaxes only
    diagnostics:                  # measurements that leave the trajectory alone (see
      configurational_temperature: {interval: 100, probes: 4}   # rigidmd.config.diagnostics)

Quantities with units are strings ``"<number> <unit>"``.  Every mistake is
a :class:`ConfigError` naming the field.  Each group of keys is checked by
its section (:mod:`rigidmd.config.sections`); :func:`check_config` assembles
them into a :class:`RunConfig`.
"""

from dataclasses import dataclass
from pathlib import Path

from rigidmd.config.diagnostics import DiagnosticsSection
from rigidmd.config.quantities import (
    ConfigError,
    key_name,
)
from rigidmd.config.relaxsection import RelaxSection
from rigidmd.config.sections import (
    CalculatorSection,
    CouplingSection,
    OutputsSection,
    RunSection,
    StructureSection,
)
from rigidmd.config.splitsection import CalculatorChoice, SplitCalculatorSection
from rigidmd.config.trust import check_output_paths, coupling_class

__all__ = ["RunConfig", "load_config", "check_config", "known_keys", "DEMO_CONFIG"]

#: The built-in demo: a TIP3P water cluster, 2 ps at 1 fs.
DEMO_CONFIG = {
    "structure": {"builtin": "water_cluster", "n_molecules": 32, "seed": 0},
    "calculator": {"name": "tip3p", "options": {"rc": 40.0}},
    "velocities": {"temperature": "250 K", "seed": 0},
    "timestep": "1 fs",
    "steps": 2000,
    "outputs": {"directory": "rigidmd-demo", "trajectory": "demo.traj", "log": "demo.log",
                "interval": 20, "plot": "demo-energy.png", "checkpoint": "demo-checkpoint.npz"},
}

_SECTIONS = {"structure": StructureSection, "run": RunSection, "calculator": CalculatorChoice,
             "coupling": CouplingSection, "outputs": OutputsSection, "relax": RelaxSection,
             "diagnostics": DiagnosticsSection}


@dataclass
class RunConfig:
    """A checked configuration: one object per section (quantities in ASE units)."""

    structure: StructureSection
    run: RunSection
    calculator: CalculatorSection | SplitCalculatorSection
    coupling: CouplingSection
    outputs: OutputsSection
    relax: RelaxSection | None = None
    diagnostics: DiagnosticsSection | None = None


def known_keys():
    """Every top-level key a configuration may hold."""
    return {key for section in _SECTIONS.values() for key in section.KEYS}


#: Numbers as YAML 1.2 writes them.  YAML 1.1 (PyYAML's) also reads ``1:30`` as 90
#: (base 60), ``010`` as 8 (octal), ``0x1f``, ``0b11`` and ``1_000``: these stay text, so
#: the field that wanted a number says so.
_YAML_INT = r"^[-+]?(?:0|[1-9][0-9]*)$"
#: A float has a point or an exponent (``1e-4`` too, which YAML 1.1 leaves text).
_YAML_FLOAT = (r"^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
               r"|[-+]?[0-9]+[eE][-+]?[0-9]+"
               r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")


#: Deepest nesting of mappings and lists a configuration may have (its own are 4 deep):
#: PyYAML composes and constructs recursively, and 5000 ``[`` crashed it (RecursionError).
MAX_DEPTH = 50
#: Nodes that aliases (``*name``) may add to a configuration beyond those written: nested
#: aliases multiply (646 bytes took 135 s and 3.1 GB), a few repeated settings do not.
MAX_ALIAS_NODES = 10_000


class _Refused(Exception):
    """The YAML text is refused before it is built (the message, without the file)."""


def _check_aliases(root):
    """Refuse a document whose aliases expand it past :data:`MAX_ALIAS_NODES` more nodes
    than written, nest it deeper than :data:`MAX_DEPTH`, or make it contain itself.

    One pass over the composed graph, each node once (an anchor's size and depth are
    remembered), without recursion.
    """
    size, depth, written, open_nodes = {}, {}, set(), set()
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            open_nodes.discard(key)
            children = _children(node)
            size[key] = 1 + sum(size[id(c)] for c in children)
            depth[key] = 1 + max((depth[id(c)] for c in children), default=0)
            if depth[key] > MAX_DEPTH:
                raise _Refused(f"aliases nest it deeper than {MAX_DEPTH} levels (line "
                               f"{node.start_mark.line + 1})")
            continue
        if key in size:
            continue
        if key in open_nodes:
            raise _Refused(f"an alias at line {node.start_mark.line + 1} refers to a mapping or "
                           "list that contains it")
        written.add(key)
        open_nodes.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node) if id(c) not in size)
    extra = size[id(root)] - len(written)
    if extra > MAX_ALIAS_NODES:
        raise _Refused(f"its aliases (*name) expand it by {extra} values, more than "
                       f"{MAX_ALIAS_NODES}; write the values out")


def _mapping_paths(root):
    """``id(mapping node) -> "thermostat"``: where each mapping of the document sits, by its
    keys from the top (the first place, for a mapping an alias repeats)."""
    import yaml

    paths, stack = {}, [(root, "")]
    while stack:
        node, path = stack.pop()
        if isinstance(node, yaml.MappingNode):
            if id(node) in paths:
                continue
            paths[id(node)] = path
            for key, value in node.value:
                name = key.value if isinstance(key, yaml.ScalarNode) else "?"
                name = key_name(name)
                stack.append((value, f"{path}.{name}" if path else name))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((item, f"{path}[{i}]") for i, item in enumerate(node.value))
    return paths


def _children(node):
    import yaml

    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _strict_loader():
    """A YAML safe loader that refuses a key given twice in one mapping, nesting deeper than
    :data:`MAX_DEPTH` and aliases that expand the document by more than
    :data:`MAX_ALIAS_NODES` values (and reads numbers as YAML 1.2 does: see ``_YAML_INT``)."""
    import re

    import yaml

    class StrictLoader(yaml.SafeLoader):
        _depth = 0

        def compose_node(self, parent, index):
            self._depth += 1
            try:
                if self._depth > MAX_DEPTH:
                    mark = self.peek_event().start_mark
                    raise _Refused(f"it nests deeper than {MAX_DEPTH} levels (line "
                                   f"{mark.line + 1})")
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def compose_document(self):
            node = super().compose_document()
            _check_aliases(node)
            self.mapping_paths = _mapping_paths(node)  # for the messages, "thermostat.taut"
            return node

    numbers = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")
    StrictLoader.yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag not in numbers]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
    StrictLoader.add_implicit_resolver(numbers[0], re.compile(_YAML_INT), list("-+0123456789"))
    StrictLoader.add_implicit_resolver(numbers[1], re.compile(_YAML_FLOAT),
                                       list("-+0123456789."))

    def construct_mapping(loader, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=deep)
            if key in seen:
                path = getattr(loader, "mapping_paths", {}).get(id(node), "")
                first, again = seen[key], key_node.start_mark
                where = (f"lines {first.line + 1} and {again.line + 1}"
                         if first.line != again.line else
                         f"line {again.line + 1}, columns {first.column + 1} and "
                         f"{again.column + 1}")
                raise ConfigError(f"{path + '.' if path else ''}{key_name(key)}: given twice "
                                  f"({where}); keep one")
            seen[key] = key_node.start_mark
        return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)

    StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                 construct_mapping)
    return StrictLoader


def load_config(path):
    """Read a YAML configuration file (not yet checked).

    Relative paths inside the file are resolved against the file's directory.
    A key given twice in one mapping is refused (YAML would keep the last).
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config: no such file {str(path)!r}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"config: {path} is not a text (UTF-8) file; give a YAML "
                          "configuration") from None
    try:
        data = yaml.load(text, Loader=_strict_loader())  # noqa: S506 - a SafeLoader subclass
    except _Refused as err:
        raise ConfigError(f"config: {path} is refused: {err}") from None
    except yaml.YAMLError as err:
        where = getattr(err, "problem_mark", None)
        line = f" at line {where.line + 1}" if where is not None else ""
        problem = getattr(err, "problem", None) or " ".join(str(err).split())
        if "yaml.org,2002:merge" in problem:
            raise ConfigError(f"config: {path}{line}: YAML merge keys (<<) are not supported "
                              "in a configuration; write the values out") from None
        raise ConfigError(f"config: {path} is not valid YAML{line} ({problem})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config: {path} must hold a mapping of settings")
    if "_base" in data:  # the folder paths are read from: the file's own, never the file's say
        raise ConfigError("_base: unknown key (paths are relative to the configuration's "
                          "folder)")
    _refuse_nul(data)
    data["_base"] = str(path.resolve().parent)
    return data


def _refuse_nul(value, where=""):
    """Refuse a NUL character in any text of the configuration, naming the field (the
    operating system refuses it in a path with a message that names none)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _refuse_nul(item, f"{where}.{key_name(key)}" if where else key_name(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _refuse_nul(item, f"{where}[{i}]")
    elif isinstance(value, str) and "\0" in value:
        raise ConfigError(f"{where}: contains a NUL character (\\0); remove it")


def check_integrator(checked):
    """Refuse (ConfigError naming ``integrator``) an integrator the run's other sections
    cannot step with: one without a ``middle`` operator for a part that acts in the middle
    of the step (``langevin_baoab``), or one other than NO_SQUISH (or ``baoab``) for a
    force split, whose inner steps are NO_SQUISH's.

    Parameters
    ----------
    checked : RunConfig
    """
    from rigidmd.core.schemes import resolve_scheme, scheme_with_middle

    run = checked.run
    scheme = resolve_scheme(run.integrator, **run.integrator_options)
    shown = run.integrator if isinstance(run.integrator, str) else scheme.name
    middle = [spec for spec in checked.coupling.specs if spec.cls.acts_in_middle]
    try:
        scheme = scheme_with_middle(scheme, run.integrator, [spec.kind for spec in middle])
    except ValueError:
        raise ConfigError(f"integrator: {shown} has no 'middle' operator, where "
                          f"{middle[0].section} {middle[0].kind} acts; use no_squish (the "
                          "default, split for it) or baoab") from None
    if checked.calculator.name == "multiple_time_step" and not any(
            scheme == resolve_scheme(name) for name in ("no_squish", "baoab")):
        raise ConfigError(f"integrator: a force split (calculator: fast, slow, substeps) runs "
                          f"its inner steps by NO_SQUISH, not {shown}; use no_squish (the "
                          "default) or baoab")


def check_config(config, trust=False):
    """Validate a raw configuration mapping and build its sections.

    Parameters
    ----------
    config : dict
        As :func:`load_config` returns; ``_base`` is the directory relative
        paths are resolved against (default: the current directory).
    trust : bool, default False
        Allow what is not on the allow-list of :mod:`rigidmd.config.trust`:
        any calculator class and option, LAMMPS commands beyond the
        interactions (``shell``, ``python``, ...), output paths outside the
        run's directory (``rigidmd run --trust``).

    Returns
    -------
    RunConfig
    """
    config = dict(config)
    base = Path(config.pop("_base", "."))
    _refuse_nul(config)
    known = known_keys()
    unknown = sorted(set(config) - known, key=str)
    if unknown:
        raise ConfigError(f"{key_name(unknown[0])}: unknown key; allowed: "
                          f"{', '.join(sorted(known))}")
    check_output_paths(config, trust, base)
    for section in CouplingSection.KEYS:  # a part of the user's own: --trust, then its kind
        raw = config.get(section)
        if isinstance(raw, dict) and isinstance(raw.get("kind"), str) and "." in raw["kind"]:
            config[section] = dict(raw, kind=coupling_class(section, raw["kind"], trust,
                                                            base).kind)
    checked = RunConfig(**{name: section.from_config(config, base)
                           for name, section in _SECTIONS.items()})
    checked.calculator.check_trust(trust)
    for spec in checked.coupling.specs:  # what a part refuses for the step: named here
        try:
            spec.part().check_timestep(checked.run.timestep)
        except ValueError as err:
            raise ConfigError(f"{spec.section}: {err}") from None
    check_integrator(checked)
    if checked.relax is not None:
        outputs = checked.outputs
        others = {f"outputs.{key}": getattr(outputs, key)
                  for key in ("trajectory", "log", "plot", "mdanalysis", "checkpoint")
                  if getattr(outputs, key) is not None}
        if outputs.mdanalysis is not None:
            others["the MDAnalysis topology"] = outputs.mdanalysis.with_suffix(".psf")
        checked.relax.check_paths(outputs.directory, others)
    return checked
