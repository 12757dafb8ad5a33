"""Pages generated from the code at build time, so that they cannot drift from it.

* ``docs/_generated/configuration.md``: every configuration key, its unit,
  default and allowed values, read from the tables of :mod:`rigidmd.config`,
  the coupling registry (:data:`rigidmd.couplings.base.COUPLINGS`) and the tables the
  sections check against (schemes, optimizers, water models, trusted LAMMPS
  commands).
* ``docs/api/<module>.md``: one page per public module listing every name of
  its ``__all__`` with its rendered docstring.
* ``docs/examples/<script>.md``: one page per script in ``examples/``.

Each file is rewritten only when its text changes, so incremental builds stay
incremental.  The functions are plain Python (no Sphinx needed) so that
``tests/project/test_docs.py`` can check what they produce.
"""

import ast
import dataclasses
import importlib
import importlib.util
import inspect
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent

#: The modules whose ``__all__`` is the public API, in the order the reference shows
#: them (a module that does not exist in this checkout is left out).
PUBLIC_MODULES = (
    ("rigidmd", "Dynamics, thermostats, barostats, bodies, velocities, checkpoints"),
    ("rigidmd.systems", "Builders: water clusters and boxes, CO2 mixtures, ice Ih"),
    ("rigidmd.water", "Water models: geometry, charges, Lennard-Jones, LAMMPS commands"),
    ("rigidmd.relax", "Rigid relaxation (bodies and cell) with ASE's optimizers"),
    ("rigidmd.lammps", "LAMMPS forces: in-process calculator, engine, data files, export"),
    ("rigidmd.ipi", "Forces from any i-PI engine"),
    ("rigidmd.openmm", "Water models as OpenMM systems, for comparison"),
    ("rigidmd.mdanalysis", "MDAnalysis Universes, writers and water analyses"),
    ("rigidmd.config", "Configuration files of the rigidmd command"),
    ("rigidmd.couplings", "Extension API: write a thermostat, a barostat or another coupling part"),
)


def write_if_changed(path, text):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


# --------------------------------------------------------------------------- API


def public_modules():
    """``(module name, summary)`` of the public modules present in this checkout."""
    return [(name, summary) for name, summary in PUBLIC_MODULES
            if importlib.util.find_spec(name) is not None]


def _summary(module, name):
    """The first paragraph of a class's or function's docstring, on one line."""
    obj = getattr(module, name)
    if not (inspect.isclass(obj) or inspect.isroutine(obj)):
        return "constant"
    paragraph = (inspect.getdoc(obj) or "").split("\n\n")[0]
    return " ".join(paragraph.split()) or "(no docstring)"


def _directive(module, name):
    obj = getattr(module, name)
    full = f"{module.__name__}.{name}"
    if inspect.isclass(obj):
        if issubclass(obj, BaseException):
            return f".. autoexception:: {full}\n"
        return f".. autoclass:: {full}\n   :members:\n   :show-inheritance:\n"
    if inspect.isroutine(obj):
        return f".. autofunction:: {full}\n"
    return f".. autodata:: {full}\n   :no-value:\n"


def api_page(module_name, summary):
    """The MyST source of one module's page: its docstring, a table, every name."""
    module = importlib.import_module(module_name)
    names = list(module.__all__)
    rows = "".join(f"   * - :py:obj:`~{module_name}.{n}`\n     - {_summary(module, n)}\n"
                   for n in names)
    rst = [f".. automodule:: {module_name}\n   :no-members:\n",
           ".. list-table::\n   :widths: 30 70\n\n" + rows]
    rst += [_directive(module, name) for name in names]
    return (f"# `{module_name}`\n\n{summary}.\n\n```{{eval-rst}}\n" + "\n".join(rst)
            + "```\n")


def write_api(outdir=DOCS / "api"):
    """One page per public module, and the list of them for the index's toctree."""
    modules = public_modules()
    for name, summary in modules:
        write_if_changed(Path(outdir) / f"{name}.md", api_page(name, summary))
    rows = "".join(f"| [`{name}`]({name}.md) | {summary} |\n" for name, summary in modules)
    toc = "".join(f"{name}\n" for name, _ in modules)
    write_if_changed(DOCS / "_generated" / "api_modules.md",
                     "| module | what |\n|---|---|\n" + rows
                     + f"\n```{{toctree}}\n:hidden:\n\n{toc}```\n")


# -------------------------------------------------------------- configuration


def _attribute_docs(cls):
    """Field name -> description from a section class's numpydoc ``Attributes``."""
    from numpydoc.docscrape import NumpyDocString

    out = {}
    for attr in NumpyDocString(inspect.getdoc(cls) or "")["Attributes"]:
        for name in attr.name.split(","):
            out[name.strip()] = (attr.type, " ".join(attr.desc))
    return out


def _units(table):
    return ", ".join(f"`{u}`" for u in table)


def _default(cls, name):
    for f in dataclasses.fields(cls):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
    return dataclasses.MISSING


def _yaml(value):
    """A default as a configuration file spells it (``true``, ``null``, ``1e-5``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, float):
        return re.sub(r"e([-+])0*(\d)", lambda m: f"e{m[1].lstrip('+')}{m[2]}", f"{value:g}")
    return str(value)


def _builder_defaults(builder):
    """``{field: default}`` of a built-in structure: its builder's signature in
    :mod:`rigidmd.systems` (the configuration passes only the fields it is given)."""
    import rigidmd.systems

    signature = inspect.signature(getattr(rigidmd.systems, builder))
    return {name: p.default for name, p in signature.parameters.items()
            if p.default is not inspect.Parameter.empty}


class _Source(str):
    """A default that is an expression of the code, not a literal (its source text)."""


def _mapping_defaults(function, mapping):
    """``{key: default}`` of every ``<mapping>.get("key", default)`` in ``function``'s
    source, and ``{key: unit}`` of its ``parse_quantity(..., default_unit=unit)`` calls on
    ``<mapping>["key"]``: the defaults a section applies, read from the code that applies
    them.  A default that is not a literal is its source text (a :class:`_Source`)."""
    import textwrap

    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    defaults, units = {}, {}
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if (isinstance(func, ast.Attribute) and func.attr == "get"
                and isinstance(func.value, ast.Name) and func.value.id == mapping
                and len(node.args) == 2 and isinstance(node.args[0], ast.Constant)):
            try:
                defaults[node.args[0].value] = ast.literal_eval(node.args[1])
            except ValueError:
                defaults[node.args[0].value] = _Source(ast.unparse(node.args[1]))
        name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
        unit = [k.value for k in node.keywords if k.arg == "default_unit"]
        if name == "parse_quantity" and unit and isinstance(unit[0], ast.Constant):
            for arg in node.args:
                if (isinstance(arg, ast.Subscript) and isinstance(arg.value, ast.Name)
                        and arg.value.id == mapping and isinstance(arg.slice, ast.Constant)):
                    units[arg.slice.value] = unit[0].value
    return defaults, units


def _water_model_table(fields, models):
    """The table of ``calculator.water_model``: each field's type and unit, whether it is
    required, its default (read from ``sections.water_commands``) and what it sets."""
    from rigidmd.config import sections
    from rigidmd.config.quantities import LENGTH_UNITS

    defaults, units = _mapping_defaults(sections.water_commands, "spec")
    cutoff_unit = units.get("cutoff")
    kinds = {"name": "str",
             "cutoff": f"length: {_units(LENGTH_UNITS)}"
                       + (f" (a bare number is in {'Å' if cutoff_unit == 'A' else cutoff_unit})"
                          if cutoff_unit else ""),
             "kspace": "`pppm`, `ewald` or `null`", "accuracy": "number, 0 < a < 1",
             "tail": "`true`, `false`"}
    meanings = {
        "name": "The water model: " + ", ".join(f"`{m}`" for m in models) + ".",
        "cutoff": "Real-space cut-off of the Lennard-Jones and Coulomb terms.",
        "kspace": "Long-range electrostatics; `null`: plain cut-off Coulomb, for clusters.",
        "accuracy": "Relative force accuracy of the k-space solver (not read without "
                    "k-space).",
        "tail": "Long-range Lennard-Jones corrections to energy and pressure (LAMMPS's "
                "`pair_modify tail yes`), for a periodic box; `tail: true` with "
                "`kspace: null` is refused."}
    #: Defaults that are expressions of other fields, in words.
    words = {"kspace is not None": "`true` with k-space, `false` with `kspace: null`"}
    rows = ["| field | type / unit | required | default | meaning |\n|---|---|---|---|---|\n"]
    for field in fields:
        default = defaults.get(field, dataclasses.MISSING)
        if default is dataclasses.MISSING:
            required, shown = "yes", ""
        elif isinstance(default, _Source):
            required, shown = "no", words.get(default, f"`{default}`")
        else:
            required, shown = "no", f"`{_yaml(default)}`"
        rows.append(f"| `{field}` | {kinds.get(field, '')} | {required} | {shown} | "
                    f"{meanings.get(field, '')} |\n")
    return "".join(rows)


def _cell(value):
    """A table cell: RST roles in MyST's spelling, no pipes or line breaks."""
    text = re.sub(r":(\w+):`", r"{\1}`", str(value))
    return text.replace("|", "\\|").replace("\n", " ")


def configuration_reference():
    """The MyST text of the full configuration reference, from the code's tables."""
    from rigidmd.config import DEMO_CONFIG, known_keys
    from rigidmd.config.diagnostics import DiagnosticsSection
    from rigidmd.config.quantities import UNIT_TABLES
    from rigidmd.config.relaxsection import RelaxSection
    from rigidmd.config.sections import (
        BODY_RULES,
        BUILDER_FIELDS,
        REQUIRED_BUILDER_FIELD,
        WATER_MODEL_FIELDS,
        CalculatorSection,
        CouplingSection,
        OutputsSection,
        RunSection,
        StructureSection,
    )
    from rigidmd.config.trust import SAFE_LAMMPS_COMMANDS
    from rigidmd.core.schemes import BUILTIN_SCHEMES
    from rigidmd.couplings.base import COUPLINGS, INTEGER_LIMITS
    from rigidmd.relax.cell import CELL_MODES
    from rigidmd.relax.filter import OPTIMIZERS
    from rigidmd.water import WATER_MODELS

    sections = (StructureSection, RunSection, CalculatorSection, CouplingSection,
                OutputsSection, RelaxSection, DiagnosticsSection)
    documented = {key for section in sections for key in section.KEYS}
    if documented != known_keys():  # a new section must be added to this page
        raise RuntimeError(f"configuration keys not in the reference: "
                           f"{sorted(known_keys() - documented)}")
    out = []
    add = out.append
    add("## Top-level keys\n\n| key | section | required |\n|---|---|---|\n")
    required = {"structure": "yes (or `restart`)", "timestep": "yes", "steps": "yes"}
    for section in sections:
        for key in section.KEYS:
            add(f"| `{key}` | {section.__name__} | {required.get(key, 'no')} |\n")
    add("\n## Quantities and their units\n\nA quantity is a string `\"<number> <unit>\"` "
        "(`\"2 fs\"`, `\"1 bar\"`); it is converted to ASE units when the file is read.\n\n"
        "| quantity | units accepted |\n|---|---|\n")
    for quantity, table in UNIT_TABLES.items():
        add(f"| {quantity} | {_units(table)} |\n")

    add("\n## `structure`, `read_options`, `bodies`, `restart`\n\n")
    docs = _attribute_docs(StructureSection)
    add("| key | type | meaning |\n|---|---|---|\n")
    for key, attr in (("structure", "source"), ("read_options", "read_options"),
                      ("bodies", "bodies"), ("restart", "restart")):
        kind, text = docs[attr]
        add(f"| `{key}` | {_cell(kind)} | {_cell(text)} |\n")
    add(f"\n`bodies` allows: {', '.join(f'`{r}`' for r in BODY_RULES)}.\n\n"
        "### Built-in structures (`structure: {builtin: NAME, ...}`)\n\n"
        "| builder | field | type | smallest | largest | required | default |\n"
        "|---|---|---|---|---|---|---|\n")
    for builder, fields in BUILDER_FIELDS.items():
        builder_defaults = _builder_defaults(builder)
        for name, kind, low, high in fields:
            allowed = ", ".join(WATER_MODELS) if kind == "water_model" else kind
            if name in ("spacing", "jitter"):
                allowed = f"{kind} (Å)"
            required = REQUIRED_BUILDER_FIELD.get(builder) == name
            default = builder_defaults.get(name)
            default = "" if required or name not in builder_defaults else f"`{_yaml(default)}`"
            add(f"| `{builder}` | `{name}` | {allowed} | {'' if low is None else low} | "
                f"{'' if high is None else high} | {'yes' if required else 'no'} | "
                f"{default} |\n")

    add("\n## `integrator`, `integrator_options`, `timestep`, `steps`, `velocities`\n\n")
    docs = _attribute_docs(RunSection)
    add("| key | type / unit | default | meaning |\n|---|---|---|---|\n")
    defaults = {"integrator": "`no_squish`", "integrator_options": "`{}`"}
    missing = {"integrator_options": "Keyword arguments of the integrator (e.g. `tol`, "
               "`max_iter` of `rozmanov_kusalik`).", "steps": "Number of steps (at least 1)."}
    for key in RunSection.KEYS:
        kind, text = docs[key]
        text = text or missing.get(key, "")
        unit = " (time: " + _units(UNIT_TABLES["time"]) + ")" if key == "timestep" else ""
        add(f"| `{key}` | {_cell(kind)}{unit} | {defaults.get(key, '')} | {_cell(text)} |\n")
    add(f"\n`integrator` allows {', '.join(f'`{s}`' for s in BUILTIN_SCHEMES)}, a YAML "
        "file of operators, or a list of operators.  `velocities` takes `temperature` "
        f"({_units(UNIT_TABLES['temperature'])}), an optional integer `seed` (absent: a "
        "fresh random seed each run, so two runs of one file start from different "
        "velocities; give a seed to repeat a run) and `stationary` (default `true`: the "
        "total momentum zeroed after the draw, as LAMMPS's `velocity create ... mom "
        "yes`).\n\n")

    add("## `calculator`\n\n")
    docs = _attribute_docs(CalculatorSection)
    add("| field | type | meaning |\n|---|---|---|\n")
    for name in CalculatorSection.FIELDS:
        kind, text = docs.get(name, docs.get("water", ("", "")))
        if name == "name":
            text = ("`tip3p` (the default, also when the section gives only `options`), "
                    "`tip4p` (ASE's), `lammps`, `ipi`, or an ASE calculator class's dotted "
                    "path (`ase.calculators.emt.EMT`).")
        if name == "pair":
            kind, text = "list of str", "Another name for `commands`."
        if name == "water_model":
            kind, text = docs["water"]
        add(f"| `{name}` | {_cell(kind)} | {_cell(text)} |\n")
    add("\n### `calculator: {name: lammps, water_model: {...}}`\n\n")
    add(_water_model_table(WATER_MODEL_FIELDS, WATER_MODELS))
    add("\nWithout `--trust`, `commands` may hold only these LAMMPS commands: "
        f"{', '.join(f'`{c}`' for c in sorted(SAFE_LAMMPS_COMMANDS))}.\n\n")
    add("A force split for multiple time steps (the guide's Multiple time steps page) "
        "gives `fast` (a calculator section as above), `slow` (another) or `full` (the slow "
        "level is `full` less `fast`), and `substeps` (inner steps per `timestep`, a whole "
        "number from 1 to 1000): `calculator: {fast: {name: tip3p, options: {rc: 7.0, "
        "width: 3.0}}, full: {name: tip3p, options: {rc: 40.0}}, substeps: 4}`.\n\n")

    add("## `thermostat` and `barostat`\n\nEach names a `kind`; the other fields are the "
        "kind's parameters.  A barostat takes the thermostat's temperature unless it "
        "gives its own.  A part of your own is named by its dotted path "
        "(`kind: berendsen.BerendsenThermostat`), with `--trust` only (see "
        "[Write a thermostat of your own](../howto/write-a-thermostat.md)).\n\n")
    for section in ("thermostat", "barostat"):
        for kind, cls in COUPLINGS.items():
            if cls.section != section:
                continue
            summary = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
            add(f"### `{section}: {{kind: {kind}}}`\n\n{summary}\n\n"
                "| field | quantity | units | required | default | allowed |\n"
                "|---|---|---|---|---|---|\n")
            for p in cls.parameters:
                table = UNIT_TABLES.get(p.quantity)
                unit = _units(table) if table else ""
                allowed = ", ".join(f"`{c}`" for c in p.choices)
                if p.quantity == "integer":
                    most = INTEGER_LIMITS.get(p.name)
                    allowed = "≥ 1" if most is None else f"1 to {most}"
                if p.quantity == "flag":
                    allowed = "`true`, `false`"
                if p.quantity == "seed":
                    allowed = "integer ≥ 0 (absent: a fresh random seed)"
                default = "" if p.default is None else f"`{p.default}`"
                if p.name == "fixcm":  # None: resolved by the dynamics
                    default = "`true` (`false` with a barostat)"
                add(f"| `{p.field}` | {p.quantity} | {unit} | "
                    f"{'yes' if p.required else 'no'} | {default} | {allowed} |\n")
            add("\n")

    add("## `outputs`\n\n")
    docs = _attribute_docs(OutputsSection)
    add("| field | type | default | meaning |\n|---|---|---|---|\n")
    for name in OutputsSection.FIELDS:
        kind, text = docs.get(name, docs.get("trajectory", ("", "")))
        default = _default(OutputsSection, name)
        default = {"directory": "`.`", "checkpoint": "`checkpoint.npz`"}.get(
            name, "" if default in (None, dataclasses.MISSING) else f"`{default}`")
        if name in ("trajectory", "log", "plot", "mdanalysis"):
            kind = "path or absent"
            text = f"The {name} file, in `directory`; absent or `null`: none."
        add(f"| `{name}` | {_cell(kind)} | {default} | {_cell(text)} |\n")

    add("\n## `relax`\n\n")
    docs = _attribute_docs(RelaxSection)
    add("| field | type / unit | default | meaning |\n|---|---|---|---|\n")
    allowed = {"optimizer": ", ".join(f"`{o}`" for o in OPTIMIZERS),
               "cell": "`false`, `true`, " + ", ".join(f"`{c}`" for c in CELL_MODES),
               "pressure": "pressure: " + _units(UNIT_TABLES["pressure"]),
               "fmax": "eV/Å (a number or `\"0.05 eV/A\"`)"}
    for name in RelaxSection.FIELDS:
        kind, text = docs.get(name, docs.get("trajectory", ("", "")))
        text = allowed.get(name, text)
        add(f"| `{name}` | {_cell(kind)} | `{_default(RelaxSection, name)}` | "
            f"{_cell(text)} |\n")

    add("\n## `diagnostics`\n\nMeasurements that leave the trajectory as it is; each reports "
        "in the run's summary.\n\n| field | key | type | default | meaning |\n"
        "|---|---|---|---|---|\n"
        "| `configurational_temperature` | `interval` | integer ≥ 1 | required | steps "
        "between samples of the translational and rotational configurational temperatures "
        "(see *The step's error* in the guide) |\n"
        "| | `probes` | integer ≥ 1 | `4` | Hutchinson probes per sample; each costs two "
        "force calls |\n"
        "| | `seed` | integer ≥ 0 | `0` | the probes' random numbers |\n")

    add("\n## The demo's configuration\n\n`rigidmd demo` runs this configuration "
        "(`rigidmd.config.DEMO_CONFIG`):\n\n```text\n")
    import yaml

    add(yaml.safe_dump(DEMO_CONFIG, sort_keys=False))
    add("```\n")
    return "".join(out)


def write_configuration(path=DOCS / "_generated" / "configuration.md"):
    write_if_changed(path, configuration_reference())


# ---------------------------------------------------------- validation tables

#: The recorded run that ``docs/validation/lammps.md``'s figure and table both show.
LAMMPS_GAP_OUTPUT = ROOT / "examples" / "output" / "validate_against_lammps.txt"


def lammps_gap_rows(path=LAMMPS_GAP_OUTPUT):
    """``(columns, rows)`` of ``examples/validate_against_lammps.py``'s recorded output:
    the header's columns after system and constants (``step 0``, ..., ``max|dE| eV``) and per
    row ``(system, constants, [cells as printed])``."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    header = next((line for line in lines if line.startswith("system")), None)
    if header is None:
        raise RuntimeError(f"{_shown(path)}: no header line 'system  constants  step 0 ...'")
    columns = re.findall(r"step \d+|max\|dE\| eV", header)
    rows = []
    for line in lines:
        match = re.match(r"^(.+?)\s{2,}(ASE|LAMMPS)\s+(.*)$", line)
        if match:
            cells = match.group(3).split()
            if len(cells) != len(columns):
                raise RuntimeError(f"{_shown(path)}: {len(cells)} numbers in the row "
                                   f"{line.strip()!r}, {len(columns)} columns in its header")
            rows.append((match.group(1).strip(), match.group(2), cells))
    if not rows:
        raise RuntimeError(f"{_shown(path)}: no rows '<system>  ASE|LAMMPS  <gaps>'")
    return columns, rows


def lammps_gap_table(path=LAMMPS_GAP_OUTPUT):
    """The Markdown table of the position gaps to LAMMPS, every cell as the recorded run
    printed it (the run the figure beside it is drawn from)."""
    columns, rows = lammps_gap_rows(path)
    names = [c.replace("max|dE| eV", "max \\|ΔE\\| (eV)") for c in columns]
    out = ["| system | LAMMPS constants | " + " | ".join(names) + " |\n",
           "|---" * (len(columns) + 2) + "|\n"]
    for system, constants, cells in rows:
        system = re.sub(r"(?<=[A-Z])2", "₂", system).replace("+", " + ")
        out.append(f"| {system} | {constants}'s | " + " | ".join(cells) + " |\n")
    return "".join(out)


def write_validation_tables(outdir=DOCS / "_generated"):
    write_if_changed(Path(outdir) / "lammps_gap.md", lammps_gap_table())


# ------------------------------------------------------------------- examples


def example_scripts():
    return sorted((ROOT / "examples").glob("*.py"))


def example_output(script):
    """The committed output of an example (``examples/output/<name>.txt``), or None.

    Its first line is the command that printed it (``$ python examples/...``);
    ``tests/project/test_examples.py`` runs each command and checks that the text is
    still what the script prints, numbers aside (timings and short runs vary).
    """
    path = script.parent / "output" / f"{script.stem}.txt"
    return path if path.is_file() else None


def example_page(script):
    """A page for one example: its docstring, how to run it, its code and its output."""
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or script.stem
    title, _, body = doc.partition("\n")
    rel = f"../../examples/{script.name}"
    page = (f"# {title.strip().rstrip('.')}\n\n`examples/{script.name}`\n\n"
            f"```{{eval-rst}}\n{body.strip()}\n```\n\n## The script\n\n"
            f"```{{literalinclude}} {rel}\n:language: python\n"
            f":lines: {_code_start(script)}-\n```\n")
    output = example_output(script)
    if output is None:
        return page + ("\n## Output\n\nNone recorded: the script needs a package the "
                       "test extra does not install (see its docstring), so no test could "
                       "keep a recorded output current.\n")
    return page + ("\n## Output\n\nWhat the command on the first line printed (standard "
                   "output), recorded in `examples/output/`; timings, and the numbers of a "
                   "shortened run, differ from machine to machine and run to run.\n\n"
                   f"```{{literalinclude}} ../../examples/output/{output.name}\n"
                   ":language: text\n```\n")


def _code_start(script):
    """The first line after the module docstring."""
    tree = ast.parse(script.read_text(encoding="utf-8"))
    return tree.body[0].end_lineno + 2 if isinstance(tree.body[0], ast.Expr) else 1


def write_examples(outdir=DOCS / "examples"):
    for script in example_scripts():
        write_if_changed(Path(outdir) / f"{script.stem}.md", example_page(script))


# -------------------------------------------------------------------- figures

FIGURES = DOCS / "figures"


def figure_scripts():
    """The scripts that draw the site's figures: ``docs/figures/*.py`` but ``_common``."""
    return sorted(p for p in FIGURES.glob("*.py") if not p.name.startswith("_"))


def _shown(path):
    """``path`` relative to the repository where it is inside it (as a message names it)."""
    try:
        return Path(path).resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


def write_figures(outdir=DOCS / "_generated" / "figures"):
    """Draw every figure from committed data into ``outdir`` (``NAME.png`` per script).

    A figure is drawn again only when its script, a shared module (``_common.py``,
    ``_timestep.py``) or a data file it may read is newer than the PNG; the scripts read
    files, they run no simulation.  A script that fails stops the build with a
    ``RuntimeError`` naming the script (and its error, which names the data file).
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    if str(FIGURES) not in sys.path:
        sys.path.insert(0, str(FIGURES))
    inputs = [*FIGURES.glob("_*.py"), *(FIGURES / "data").glob("*"),
              *(ROOT / "benchmarks").glob("*.txt"), *(ROOT / "benchmarks").glob("*.jsonl"),
              *(ROOT / "validation").glob("*.txt"), *(ROOT / "validation").glob("*.json"),
              *(ROOT / "examples" / "output").glob("*.txt")]
    newest_input = max(p.stat().st_mtime for p in inputs)
    drawn = []
    for script in figure_scripts():
        target = outdir / f"{script.stem}.png"
        if (target.is_file()
                and target.stat().st_mtime >= max(newest_input, script.stat().st_mtime)):
            continue
        try:
            spec = importlib.util.spec_from_file_location(f"rigidmd_figure_{script.stem}",
                                                          script)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            module.draw(target)
        except Exception as err:
            target.unlink(missing_ok=True)  # (a half-written PNG would count as drawn)
            message = " ".join(str(err).split()) or "(no message)"
            raise RuntimeError(f"figure script {_shown(script)} failed to draw {target.name}: "
                               f"{type(err).__name__}: {message}") from err
        drawn.append(target)
    return drawn


def generate(app=None):
    write_configuration()
    write_validation_tables()
    write_api()
    write_examples()
    write_figures()


def setup(app):
    app.connect("builder-inited", generate, priority=100)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
