"""The package's layout, read with ``ast``: no private access across objects, no import cycles.

Checked over every module under ``src/rigidmd`` (lazy imports inside functions
count: a lazy import is still a dependency).
"""

import ast
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[1] / "src" / "rigidmd"
#: Longest module accepted (lines).
MAX_LINES = 700


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
