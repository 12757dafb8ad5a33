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

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_readme_is_a_front_door():
    """At most 150 lines; the two commands as CI runs them; a Python example."""
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    bash = [body for lang, body in blocks(text) if lang == "bash"]
    assert 'python -m pip install . && rigidmd demo\n' in bash
    assert 'python -m pip install -e ".[test]" && python -m pytest -n auto\n' in bash
    ci = (README.parent / ".ci" / "run").read_text()
    assert 'python -m pip install -e ".[test]" && python -m pytest -n auto' in ci
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
