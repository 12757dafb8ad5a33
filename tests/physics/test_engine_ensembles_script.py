"""``validation/engine_ensembles.py``: arguments checked before any run, the table written to
``--out`` (default: the committed ``engine_ensembles.txt``) only when every run is complete,
and a stopped run (Ctrl-C, SIGTERM) says in one line that it wrote nothing.

``--ps 0.02`` (fewer samples than the 10 blocks) replaced the committed table by ``nan±nan``;
``--ps -1`` ended in a traceback after the equilibration; a Ctrl-C, in a traceback.  The
runs themselves (minutes of LAMMPS) are replaced here by stand-ins.
"""

import os
import signal

import numpy as np
import pytest
from helpers import benchmark_module

pytestmark = pytest.mark.lammps

COMMITTED = "the committed table\n"


def samples(kind, couple, ps, seed, equilibration_ps=5.0, n_side=4):
    """A run's stand-in: density and cell parameters of each sample."""
    n = int(ps * 500) // 5
    rng = np.random.default_rng(seed)
    return np.column_stack([1.0 + 0.01 * rng.standard_normal(n),
                            np.full((n, 3), 12.4), np.full((n, 3), 90.0)])


@pytest.mark.parametrize("args, option", [
    (["--ps", "0.02"], "--ps"), (["--ps", "-1"], "--ps"), (["--ps", "0"], "--ps"),
    (["--equilibration-ps", "-1"], "--equilibration-ps"), (["--n-side", "0"], "--n-side"),
])
def test_an_argument_that_would_fail_late_is_refused_first(tmp_path, monkeypatch, capsys,
                                                           args, option):
    bench = benchmark_module("engine_ensembles")
    monkeypatch.setattr(bench, "run", lambda *a, **k: pytest.fail("a run started"))
    out = tmp_path / "engine_ensembles.txt"
    out.write_text(COMMITTED)
    with pytest.raises(SystemExit) as stop:
        bench.main([*args, "--out", str(out)])
    assert stop.value.code == 2
    assert f"argument {option}" in capsys.readouterr().err.strip().splitlines()[-1]
    assert out.read_text() == COMMITTED


def test_the_table_goes_to_out_when_every_run_is_complete(tmp_path, monkeypatch, capsys):
    bench = benchmark_module("engine_ensembles")
    monkeypatch.setattr(bench, "run", samples)
    out = tmp_path / "table.txt"
    bench.main(["--ps", "0.1", "--runs", "LAMMPSCalculator iso", "LAMMPSEngine tri",
                "--out", str(out)])
    lines = out.read_text().splitlines()
    assert len(lines) == 4 and "nan" not in out.read_text()
    assert lines[2].split()[:2] == ["LAMMPSCalculator", "iso"]
    assert "[2/2] LAMMPSEngine tri" in capsys.readouterr().out  # progress
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.txt"]


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM"])
def test_a_stopped_run_writes_nothing_and_says_so(tmp_path, monkeypatch, how):
    bench = benchmark_module("engine_ensembles")
    calls = []

    def second_stopped(*args, **kwargs):
        calls.append(args)
        if len(calls) == 2:
            os.kill(os.getpid(), getattr(signal, how))
        return samples(*args, **kwargs)

    monkeypatch.setattr(bench, "run", second_stopped)
    out = tmp_path / "engine_ensembles.txt"
    out.write_text(COMMITTED)
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as stop:
        bench.main(["--ps", "0.1", "--out", str(out)])
    message = str(stop.value.code)
    assert f"stopped ({how}) after 1 of 5 runs: nothing written to {out}" in message
    assert out.read_text() == COMMITTED
    assert sorted(p.name for p in tmp_path.iterdir()) == ["engine_ensembles.txt"]
    assert signal.getsignal(signal.SIGTERM) is before  # the script's handler taken back


def test_a_run_with_non_finite_means_writes_nothing(tmp_path, monkeypatch):
    bench = benchmark_module("engine_ensembles")
    monkeypatch.setattr(bench, "run", lambda *args, **kwargs: samples(*args, **kwargs) * np.nan)
    out = tmp_path / "engine_ensembles.txt"
    out.write_text(COMMITTED)
    with pytest.raises(SystemExit, match="gave non-finite means: nothing written"):
        bench.main(["--ps", "0.1", "--runs", "LAMMPSCalculator iso", "--out", str(out)])
    assert out.read_text() == COMMITTED
