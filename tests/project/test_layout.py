"""The package's layout, read with ``ast``: layers, no private access across objects, no cycles.

Checked over every module under ``src/rigidmd`` (lazy imports inside functions
count: a lazy import is still a dependency).  Modules are grouped in packages
by concern, and the packages in layers (:data:`LAYERS`, drawn in
``docs/developer/layout.md``): a package imports only the packages its row
names, so the lower layers build and test without the upper ones, and nothing
imports the top-level ``rigidmd`` (it only re-exports).
"""

import ast
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[2] / "src" / "rigidmd"
#: Most modules left flat in ``src/rigidmd`` (``__init__.py`` not counted).
MAX_TOP_MODULES = 12

#: The layers, lowest first: the step and its interfaces, the coupling parts, the user's
#: dynamics classes, the libraries built on them, LAMMPS, relaxation, the configuration,
#: the application.  A top-level module (``water.py``, ``openmm.py``) is a package here.
_BASE = ("core", "couplings", "md")
_LIBRARIES = ("water", "systems", "ipi", "openmm", "mdanalysis")
#: Package -> the packages it may import (itself always): the layer contract.  ``rigidmd``
#: is the top-level ``__init__``, which re-exports and which no module imports.
LAYERS = {
    "core": (),
    "couplings": ("core",),
    "md": ("core", "couplings"),
    "water": _BASE,
    "systems": _BASE + ("water",),
    "ipi": _BASE,
    "openmm": _BASE + ("water",),
    "mdanalysis": _BASE + ("water",),  # (a water model named for its corrections)
    "lammps": _BASE + _LIBRARIES,
    "relax": ("core",),  # a library: the relax: section and command are run's
    "config": _BASE + _LIBRARIES + ("lammps", "relax"),
    "run": _BASE + _LIBRARIES + ("lammps", "relax", "config"),
    "rigidmd": _BASE + _LIBRARIES + ("lammps", "relax", "config", "run"),
}
#: Basenames several packages may use: a package's ``__init__`` and its compiled kernels.
SHARED_BASENAMES = ("__init__", "_numba", "_numpy")  # per package: kernels, their references


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


def import_lines(name, tree, known):
    """``(line, module)`` of every package module ``name`` imports, anywhere in its code.

    A string that is a dotted module name (a lazy import table, ``import_module``) counts.
    """
    package = name if known[name].name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {(node.lineno, alias.name) for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                # ``from package import module`` depends on the module, not the package.
                full = f"{base}.{alias.name}"
                found.add((node.lineno, full if full in known else base))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "." in node.value:
            found.add((node.lineno, node.value))
    return sorted((line, module) for line, module in found
                  if module in known and module != name)


def imports(name, tree, known):
    """The package modules ``name`` imports, anywhere in its code."""
    return {module for _, module in import_lines(name, tree, known)}


def package_of(module):
    """``rigidmd.core.state`` -> ``core``; ``rigidmd.water`` -> ``water``; ``rigidmd`` itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "rigidmd"


def forbidden_imports(known, layers=None):
    """``module:line imports target (...)`` for each import its package's row does not allow."""
    layers = LAYERS if layers is None else layers
    offences = []
    for name, path in known.items():
        own = package_of(name)
        for line, target in import_lines(name, ast.parse(path.read_text()), known):
            other = package_of(target)
            if other == "rigidmd" or (other != own and other not in layers.get(own, ())):
                offences.append(f"{name}:{line} imports {target} ({own} may import "
                                f"{', '.join(layers.get(own, ())) or 'nothing else'})")
    return offences


def cycles_of(graph):
    """Every cycle a depth-first search of ``{node: successors}`` closes."""
    cycles, state, stack = [], {}, []

    def visit(node):  # a back edge closes a cycle
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)
    return cycles


def shared_basenames(paths):
    """``{basename: [modules]}`` of the basenames two modules share (allowed ones aside)."""
    found = {}
    for name, path in paths.items():
        found.setdefault(path.stem, []).append(name)
    return {base: names for base, names in sorted(found.items())
            if len(names) > 1 and base not in SHARED_BASENAMES}


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
    cycles = cycles_of(graph)
    assert cycles == [], "\n".join(" -> ".join(cycle) for cycle in cycles)


def test_every_import_obeys_the_layers():
    """Each import (eager or lazy) goes to the package's own modules or to a package its
    row of :data:`LAYERS` names; nothing imports the top-level ``rigidmd``."""
    offences = forbidden_imports(modules())
    assert offences == [], "\n".join(offences)


def test_the_layers_have_no_cycle_and_cover_every_package():
    assert cycles_of({package: set(allowed) for package, allowed in LAYERS.items()}) == []
    assert all(allowed in LAYERS for row in LAYERS.values() for allowed in row)
    assert not any("rigidmd" in row for row in LAYERS.values())
    packages = {package_of(name) for name in modules()}
    assert packages == set(LAYERS), packages ^ set(LAYERS)


def test_no_two_modules_share_a_basename():
    """``state`` meant rigidmd.core.state or a relaxation's state: each basename names one
    module (``__init__``, and each package's compiled kernels ``_numba`` and their NumPy
    references ``_numpy``, aside)."""
    assert shared_basenames(modules()) == {}


def test_the_checks_find_what_they_look_for(tmp_path):
    """The checks above cannot pass vacuously."""
    tree = ast.parse("def f(dyn):\n    return dyn._ctx.model, self._own\n")
    assert private_accesses(tree) == [(2, "dyn._ctx")]
    known = {"rigidmd": SOURCE / "__init__.py", "rigidmd.a": SOURCE / "a.py",
             "rigidmd.b": SOURCE / "b.py"}
    lazy = ast.parse("def g():\n    from rigidmd import b\n")
    assert imports("rigidmd.a", lazy, known) == {"rigidmd.b"}
    assert import_lines("rigidmd.a", ast.parse("x = 1\nTABLE = {'rigidmd.b': ()}\n"),
                        known) == [(2, "rigidmd.b")]
    assert len(modules()) > 20
    (tmp_path / "core.py").write_text("def f():\n    import rigidmd.run.x\n")
    (tmp_path / "x.py").write_text("from rigidmd import RigidVerlet\n")
    fake = {"rigidmd.core.y": tmp_path / "core.py", "rigidmd.run.x": tmp_path / "x.py",
            "rigidmd": tmp_path / "x.py"}
    assert forbidden_imports(fake, {"core": (), "run": ("core",)}) == [
        "rigidmd.core.y:2 imports rigidmd.run.x (core may import nothing else)",
        "rigidmd.run.x:1 imports rigidmd (run may import core)"]
    assert cycles_of({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]
    assert shared_basenames({"rigidmd.core.state": Path("core/state.py"),
                             "rigidmd.relax.state": Path("relax/state.py"),
                             "rigidmd.core._numba": Path("core/_numba.py"),
                             "rigidmd.relax._numba": Path("relax/_numba.py")}) == {
        "state": ["rigidmd.core.state", "rigidmd.relax.state"]}


def test_at_most_a_dozen_modules_at_the_top():
    top = sorted(path.name for path in SOURCE.glob("*.py") if path.name != "__init__.py")
    assert len(top) <= MAX_TOP_MODULES, top
    for package in ("core", "couplings", "run", "systems"):
        assert (SOURCE / package / "__init__.py").is_file(), package


def test_init_files_only_re_export():
    """A package's ``__init__`` holds imports, ``__all__``, ``__version__`` and a docstring.

    And a module ``__getattr__`` that re-exports a name on first use (PEP 562), where an
    import at the top would be circular (``rigidmd.couplings.Barostat``, whose module
    imports the dynamics, which imports the package).
    """
    offences = []
    for path in SOURCE.rglob("__init__.py"):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                continue  # the docstring
            if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
                continue  # a lazy re-export
            if isinstance(node, ast.Assign) and all(
                    isinstance(t, ast.Name) and t.id in ("__all__", "__version__")
                    for t in node.targets):
                continue
            offences.append(f"{path.relative_to(SOURCE)}:{node.lineno}")
    assert offences == [], offences


def test_the_removed_paths_are_gone():
    """No release was made with the old paths, so no shim keeps them: rigidmd.optimize
    (now rigidmd.relax), rigidmd.run.checkpoint and rigidmd.run.logger (rigidmd.core's),
    rigidmd.relax.Relaxation (rigidmd.relax.BodyRelaxation)."""
    import importlib.util

    import rigidmd.relax

    for name in ("rigidmd.optimize", "rigidmd.run.checkpoint", "rigidmd.run.logger"):
        assert importlib.util.find_spec(name) is None, name
    assert not hasattr(rigidmd.relax, "Relaxation")
