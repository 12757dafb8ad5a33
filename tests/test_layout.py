"""The package's layout, read with ``ast``: no private access across objects, no import cycles.

Checked over every module under ``src/rigidmd`` (lazy imports inside functions
count: a lazy import is still a dependency); modules are grouped in packages
by concern (``core``, ``couplings``, ``run``, ``systems``, ...: see
``docs/developer/layout.md``), with few left at the top, and no module or class
grows past what a reader takes in.
"""

import ast
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[1] / "src" / "rigidmd"
#: Longest module accepted (lines).
MAX_LINES = 700
#: Most modules left flat in ``src/rigidmd`` (``__init__.py`` not counted).
MAX_TOP_MODULES = 12
#: Longest class accepted (lines, docstring included).
MAX_CLASS_LINES = 350


def modules():
    """``{dotted name: path}`` of every module of the package."""
    found = {}
    for path in sorted(SOURCE.rglob("*.py")):
        parts = list(path.relative_to(SOURCE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def private_accesses(tree):
    """``(line, text)`` of each ``x._name`` where ``x`` is not ``self``, ``cls`` or ``super()``."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        name = node.attr
        if not name.startswith("_") or (name.startswith("__") and name.endswith("__")):
            continue
        owner = node.value
        if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
            continue
        if isinstance(owner, ast.Call) and ast.unparse(owner.func) == "super":
            continue  # a base class's own template method (MDAnalysis's _single_frame)
        if ast.unparse(node) == "os._exit":
            continue  # the standard library's documented exit without clean-up
        found.append((node.lineno, ast.unparse(node)))
    return found


def imports(name, tree, known):
    """The package modules ``name`` imports, anywhere in its code."""
    package = name if known[name].name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                # ``from package import module`` depends on the module, not the package.
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base)
    return {module for module in found if module in known and module != name}


def test_no_module_reads_another_objects_private_attributes():
    offences = []
    for name, path in modules().items():
        for line, text in private_accesses(ast.parse(path.read_text())):
            offences.append(f"{name}:{line}: {text}")
    assert offences == [], "\n".join(offences)


def test_no_import_cycles():
    known = modules()
    graph = {name: imports(name, ast.parse(path.read_text()), known)
             for name, path in known.items()}
    cycles, state, stack = [], {}, []

    def visit(node):  # depth-first search; a back edge closes a cycle
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert cycles == [], "\n".join(" -> ".join(cycle) for cycle in cycles)


def test_the_checks_find_what_they_look_for():
    """The two checks above cannot pass vacuously."""
    tree = ast.parse("def f(dyn):\n    return dyn._ctx.model, self._own\n")
    assert private_accesses(tree) == [(2, "dyn._ctx")]
    known = {"rigidmd": SOURCE / "__init__.py", "rigidmd.a": SOURCE / "a.py",
             "rigidmd.b": SOURCE / "b.py"}
    lazy = ast.parse("def g():\n    from rigidmd import b\n")
    assert imports("rigidmd.a", lazy, known) == {"rigidmd.b"}
    assert len(modules()) > 20


def test_no_module_is_over_700_lines():
    long = {name: n for name, path in modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def class_lengths():
    """``{module.Class: lines}`` of every class of the package (nested ones too)."""
    found = {}
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                found[f"{name}.{node.name}"] = node.end_lineno - node.lineno + 1
    return found


def test_at_most_a_dozen_modules_at_the_top():
    top = sorted(path.name for path in SOURCE.glob("*.py") if path.name != "__init__.py")
    assert len(top) <= MAX_TOP_MODULES, top
    for package in ("core", "couplings", "run", "systems"):
        assert (SOURCE / package / "__init__.py").is_file(), package


def test_no_class_is_over_350_lines():
    lengths = class_lengths()
    assert lengths["rigidmd.core.dynamics.RigidDynamics"] <= MAX_CLASS_LINES
    long = {name: n for name, n in lengths.items() if n > MAX_CLASS_LINES}
    assert long == {}, "\n".join(f"{name}: {n} lines" for name, n in long.items())


def test_init_files_only_re_export():
    """A package's ``__init__`` holds imports, ``__all__``, ``__version__`` and a docstring."""
    offences = []
    for path in SOURCE.rglob("__init__.py"):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                continue  # the docstring
            if isinstance(node, ast.Assign) and all(
                    isinstance(t, ast.Name) and t.id in ("__all__", "__version__")
                    for t in node.targets):
                continue
            offences.append(f"{path.relative_to(SOURCE)}:{node.lineno}")
    assert offences == [], offences


#: What the core may import: itself only.  The coupling parts' interface, which the dynamics
#: composes, is the core's own (``rigidmd.core.coupling``); the parts, in
#: ``rigidmd.couplings``, sit a layer above it (issue 46: no cycle core <-> couplings).
CORE_MAY_IMPORT = ("rigidmd.core",)


def test_the_core_imports_nothing_above_it():
    """The core (state, model, step, dynamics, its checkpoint file and log) imports no
    package built on it: not the coupling parts, run (it imported run.checkpoint and
    run.logger), config, relax, the engines or the systems, eagerly or lazily."""
    known = modules()
    offences = []
    for name, path in known.items():
        if name == "rigidmd.core" or name.startswith("rigidmd.core."):
            for module in sorted(imports(name, ast.parse(path.read_text()), known)):
                if not any(module == allowed or module.startswith(allowed + ".")
                           for allowed in CORE_MAY_IMPORT):
                    offences.append(f"{name} imports {module}")
    assert offences == [], "\n".join(offences)


def test_old_paths_of_moved_modules_still_import():
    """rigidmd.run.checkpoint and rigidmd.run.logger moved into the core, the loader out
    of rigidmd.config's __init__: the old names are the same objects."""
    from rigidmd import config
    from rigidmd.config import loader
    from rigidmd.core import checkpoint, logger
    from rigidmd.run import checkpoint as old_checkpoint
    from rigidmd.run import logger as old_logger

    for name in old_checkpoint.__all__:
        assert getattr(old_checkpoint, name) is getattr(checkpoint, name), name
    for name in old_logger.__all__:
        assert getattr(old_logger, name) is getattr(logger, name), name
    for name in loader.__all__:
        assert getattr(config, name) is getattr(loader, name), name
