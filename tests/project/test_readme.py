"""Every example and configuration shown in README.md runs as written.

The README's fenced blocks run in order in one scratch directory, with the
conventions of ``tests/codeblocks.py`` (python blocks in one interpreter,
``# file: NAME`` yaml blocks written to files, bash blocks line by line).
Lines checked elsewhere are listed in ``codeblocks.CHECKED_ELSEWHERE``: the
``pip install`` lines (``.ci/run`` runs the README's install and test command
on a clean checkout, then the documentation build).
"""

from pathlib import Path

import pytest
from codeblocks import CHECKED_ELSEWHERE, blocks, run_page, shell_lines

README = Path(__file__).resolve().parents[2] / "README.md"


def test_the_readme_is_a_front_door():
    """At most 150 lines; the two commands as CI runs them; a Python example."""
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    bash = [body for lang, body in blocks(text) if lang == "bash"]
    assert 'python -m pip install . && rigidmd demo\n' in bash
    # The test command as a user types it, in a fresh virtual environment of their own.
    assert ('python -m venv .venv && . .venv/bin/activate\n'
            'python -m pip install -e ".[test]" && python -m pytest -n auto\n') in bash
    ci = (README.parent / ".ci" / "run").read_text()
    # CI runs the README's test command exactly: its two lines, together and in order, as
    # the first commands in the scratch copy it makes (nothing a user would not run
    # before them: it once upgraded pip, which a new user's environment does not do).
    test_block = next(body for body in bash if "-m venv" in body)
    commands = [line for line in ci.splitlines() if line and not line.startswith("#")]
    entered = next(i for i, line in enumerate(commands) if line == 'cd "$work"')
    assert "\n".join(commands[entered + 1:entered + 3]) + "\n" == test_block, \
        commands[entered + 1:entered + 3]
    assert "trap 'rm -rf" in ci
    assert "python -m sphinx -W -b html docs docs/_build/html" in ci
    assert [lang for lang, _ in blocks(text)].count("python") >= 1


def test_readme_links_point_to_files():
    import re

    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README.read_text()):
        if not target.startswith("http"):
            assert (README.parent / target).is_file(), target


def test_every_readme_bash_line_runs_or_is_checked_elsewhere():
    for lang, body in blocks(README.read_text()):
        if lang == "bash":
            for command, skipped in shell_lines(body):
                assert skipped, f"{command}: README bash lines are all install/test commands"
    assert CHECKED_ELSEWHERE


@pytest.mark.slow
def test_every_readme_example_runs(tmp_path):
    ran = run_page(README.read_text(), tmp_path)
    assert "python" in ran
    assert (tmp_path / "md.traj").stat().st_size > 0
    assert len((tmp_path / "md.log").read_text().splitlines()) > 1


def _top_level_imports(tree):
    """(module, line) of each import a module runs when collected, in order, with the
    modules a top-level ``pytest.importorskip`` before it has already vouched for."""
    import ast

    vouched = set()
    for node in tree.body:
        if isinstance(node, ast.Try) and any(
                isinstance(h.type, ast.Name) and h.type.id in ("ImportError",
                                                               "ModuleNotFoundError")
                for h in node.handlers):
            continue  # an import with its own fall-back
        for sub in ast.walk(node) if not isinstance(node, (ast.FunctionDef,
                                                            ast.ClassDef)) else ():
            if (isinstance(sub, ast.Call) and isinstance(sub.func, ast.Attribute)
                    and sub.func.attr == "importorskip" and sub.args
                    and isinstance(sub.args[0], ast.Constant)):
                vouched.add(sub.args[0].value.split(".")[0])
            elif isinstance(sub, ast.Import):
                for alias in sub.names:
                    yield alias.name.split(".")[0], sub.lineno, frozenset(vouched)
            elif isinstance(sub, ast.ImportFrom) and sub.level == 0:
                yield sub.module.split(".")[0], sub.lineno, frozenset(vouched)


def test_the_tests_collect_on_a_bare_install():
    # The README: without the extras (pip install -e . pytest) the tests that need them
    # are skipped with the reason.  So every module a test file imports on collection is
    # the standard library's, a dependency of the bare install, pytest, or the suite's
    # own; any other is imported inside a test, after an importorskip, or with a fall-back.
    import ast
    import sys

    tests = README.parent / "tests"
    bare = set(sys.stdlib_module_names) | {"ase", "numpy", "numba", "yaml", "scipy",
                                           "matplotlib", "rigidmd", "pytest", "_pytest"}
    own = {p.stem for folder in (tests, tests / "data", README.parent / "docs" / "_ext")
           for p in folder.glob("*.py")}
    wrong = []
    for path in sorted(tests.glob("*.py")) + sorted((tests / "data").glob("*.py")):
        for module, line, vouched in _top_level_imports(ast.parse(path.read_text())):
            if module not in bare | own | vouched:
                wrong.append(f"{path.relative_to(README.parent)}:{line} imports {module}")
    assert not wrong, "\n".join(wrong)
