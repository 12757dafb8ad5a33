"""The benchmarks refuse a bad argument in one line before any run, and never write over
the recorded results they do not name (``benchmarks/*.py``)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def run(script, *args, cwd):
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


@pytest.mark.parametrize("script, args, message", [
    ("relax.py", ["boxx"], "relax.py: 'boxx' is not a command (compare, compare-table, "),
    ("relax.py", ["large", "abc"], "relax.py: large's first argument must be a whole number "
                                   ">= 1, got 'abc'"),
    ("relax.py", ["totals"], "relax.py totals: give the rows file(s) to read"),
    ("relax.py", ["compare", "bogus"], "argument systems: 'bogus' is not clusterNsS or boxNsS"),
    ("relax.py", ["compare", "cluster8s0", "--routes", "relax,bogus"],
     "argument --routes: 'bogus' is not relax or ASE"),
    ("integrator_overhead.py", ["--ratio", "--rounds", "0"],
     "argument --rounds: must be at least 1, got 0"),
    ("barostat_step.py", ["--waters", "100"], "argument --waters: 100 is not 27 r^3"),
    ("barostat_step.py", ["--steps", "0"], "argument --steps: must be at least 1, got 0"),
])
def test_a_bad_argument_is_one_line_before_any_run(tmp_path, script, args, message):
    """Each was a KeyError, ValueError, IndexError or ZeroDivisionError traceback, some after
    minutes of runs: ``compare ... --routes relax,bogus`` ran and recorded the relax route
    first; ``barostat_step.py --waters 100`` timed 216 waters and printed "100 waters"."""
    done = run(script, *args, cwd=tmp_path)
    assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
    assert message in done.stderr.strip().splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


def copied_module(name, folder):
    """``benchmarks/<name>.py`` copied into ``folder`` with its recorded ``.txt``, loaded from
    there (a fault writes over the copy, never over the repository's results)."""
    import importlib.util
    import shutil

    for suffix in (".py", ".txt"):
        shutil.copy(ROOT / "benchmarks" / f"{name}{suffix}", folder / f"{name}{suffix}")
    spec = importlib.util.spec_from_file_location(name, folder / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.tblite
def test_no_run_writes_over_the_recorded_results_unasked(monkeypatch, tmp_path, capsys):
    """``relax.py`` with no arguments replaced the recorded ``relax.txt`` (556 lines of every
    study) by its one table, and ``tight_binding.py`` replaced ``tight_binding.txt`` (a docs
    figure's data) whatever its arguments: they print, and write only to an ``--output``
    named.  (The measurements are stood in for: this checks where the results go.)"""
    recorded = {name: (ROOT / "benchmarks" / name).read_bytes()
                for name in ("relax.txt", "tight_binding.txt")}
    relax = copied_module("relax", tmp_path)
    monkeypatch.setattr(relax, "rows", lambda key, **kwargs: [f"| {key} | stood in |"])
    monkeypatch.setattr(sys, "argv", ["relax.py"])
    relax.main()
    assert "| box | stood in |" in capsys.readouterr().out
    pytest.importorskip("tblite", reason="needs tblite (rigidmd[tb])")
    binding = copied_module("tight_binding", tmp_path)
    monkeypatch.setattr(binding, "payoff", lambda n, ps, lines: lines.append("stood in"))
    monkeypatch.setattr(binding, "overhead", lambda *args, **kwargs: None)
    monkeypatch.setattr(sys, "argv", ["tight_binding.py", "--molecules", "2"])
    binding.main()
    assert "stood in" in capsys.readouterr().out
    monkeypatch.setattr(sys, "argv", ["tight_binding.py", "--output", str(tmp_path / "o.txt")])
    binding.main()
    assert "stood in" in (tmp_path / "o.txt").read_text()
    for name, content in recorded.items():
        assert (tmp_path / name).read_bytes() == content, name
