"""``validation/mc_barostat.py``: arguments checked before the start's MD, and the results
file (default: the committed ``mc_barostat.txt``) replaced only by a complete run.

Every printed line rewrote ``--output`` from its start, so a failed or interrupted run left
a truncated file in place of the results; ``--rounds 0`` was found after the start's MD.
The runs themselves (minutes of LAMMPS) are replaced here by stand-ins.
"""

import pytest
from ase import Atoms
from helpers import benchmark_module

pytestmark = pytest.mark.lammps

COMMITTED = "the committed results\n"


def script(monkeypatch, cost=None):
    """The script with its MD replaced: ``start`` returns a stand-in; ``cost`` as given."""
    bench = benchmark_module("mc_barostat")
    monkeypatch.setattr(bench, "start", lambda seed=1: pytest.fail("the start's MD ran"))
    if cost is not None:
        monkeypatch.setattr(bench, "start", lambda seed=1: Atoms())
        monkeypatch.setattr(bench, "cost", cost)
    return bench


@pytest.mark.parametrize("args, option", [
    (["--rounds", "0"], "--rounds"), (["--cost-steps", "0"], "--cost-steps"),
    (["--production-ps", "-1"], "--production-ps"),
    (["--only", "mc", "--production-ps", "0.2"], "--production-ps"),  # 4 samples, 10 blocks
    (["--equilibration-ps", "-1"], "--equilibration-ps"),
])
def test_an_argument_that_would_fail_late_is_refused_first(tmp_path, monkeypatch, capsys,
                                                           args, option):
    output = tmp_path / "mc_barostat.txt"
    output.write_text(COMMITTED)
    bench = script(monkeypatch)
    with pytest.raises(SystemExit) as stop:
        bench.main([*args, "--output", str(output)])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert f"argument {option}" in err[-1], err
    assert output.read_text() == COMMITTED
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mc_barostat.txt"]


def test_a_run_that_fails_leaves_the_results_file_as_it_was(tmp_path, monkeypatch, capsys):
    def failing_cost(atoms, rounds, steps, out, engine=False):
        out("cost: first line")
        raise RuntimeError("LAMMPS failed")

    output = tmp_path / "mc_barostat.txt"
    output.write_text(COMMITTED)
    bench = script(monkeypatch, failing_cost)
    with pytest.raises(RuntimeError, match="LAMMPS failed"):
        bench.main(["--only", "cost", "--output", str(output)])
    assert output.read_text() == COMMITTED
    partial = tmp_path / "mc_barostat.txt.partial"
    assert partial.read_text().splitlines()[-1] == "cost: first line"
    assert f"{output} is left as it was" in capsys.readouterr().err


def test_a_complete_run_replaces_the_results_file(tmp_path, monkeypatch):
    def cost(atoms, rounds, steps, out, engine=False):
        out(f"cost: {rounds} rounds of {steps} steps")

    output = tmp_path / "mc_barostat.txt"
    output.write_text(COMMITTED)
    bench = script(monkeypatch, cost)
    bench.main(["--only", "cost", "--rounds", "2", "--cost-steps", "7", "--output", str(output)])
    lines = output.read_text().splitlines()
    assert lines[0].startswith("216 TIP4P/2005 waters") and lines[-1] == "cost: 2 rounds of 7 steps"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mc_barostat.txt"]


def test_a_density_that_is_not_finite_is_not_written(tmp_path, monkeypatch):
    bench = script(monkeypatch, cost=lambda *args, **kwargs: None)
    monkeypatch.setattr(bench, "density_run", lambda *args: (float("nan"), float("nan")))
    output = tmp_path / "mc_barostat.txt"
    output.write_text(COMMITTED)
    with pytest.raises(SystemExit, match="the mc run's density is not finite"):
        bench.main(["--only", "mc", "--output", str(output)])
    assert output.read_text() == COMMITTED
