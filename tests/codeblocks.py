"""Run the fenced code blocks of a Markdown page as a reader following it would.

Used by ``tests/test_readme.py`` (README.md) and ``tests/test_docs.py`` (every page
under ``docs/``).  The blocks of one page run in order in one scratch directory:

* ``python`` blocks one after the other in one interpreter (a later block may
  use what an earlier one defined, as a reader following along would);
* ``yaml`` blocks whose first line is ``# file: NAME`` are written to NAME
  before the blocks after them run (other ``yaml`` blocks are fragments, not run);
* ``bash`` blocks line by line (comments after ``#`` are shell comments);
* other blocks (``text``, MyST directives such as ``{eval-rst}``) are not run.

Some bash lines are not run here, and :data:`CHECKED_ELSEWHERE` says where they
are checked.
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OPENING = re.compile(r"^(`{3,})\s*([^`\s]*)")

#: Bash lines covered elsewhere: (marker in the line, where it is checked).
CHECKED_ELSEWHERE = (
    ("pip install", ".ci/run installs and tests a clean checkout"),
    ("sphinx", ".ci/run builds the documentation with -W"),
    ("examples/tip3p_water.py --outdir out", "tests/test_examples.py runs it with --quick"),
    ("examples/tip4p2005.py --outdir out4", "tests/test_examples.py runs it with --quick"),
    ("validation/water_models.py --jobs 2", "hours; tests/test_water_properties.py runs its "
     "--quick form"),
    ("validation/water_lammps_check.py --models", "needs a finished water_models.py run; "
     "tests/test_water_properties.py runs its --quick form"),
    ("validation/water_openmm_check.py --models", "minutes a model; tests/test_water_openmm.py "
     "runs its --quick form"),
    ("validation/water_openmm_nve.py", "an hour and more on 2 cores; "
     "tests/test_water_openmm.py runs its --quick form and a 27-water tracking check"),
    ("validation/water_openmm_long.py", "each run as long as its --budget-s; "
     "tests/test_water_openmm.py runs its --quick form"),
    ("validation/timestep_table", "core-days for the full table; tests/test_timestep_table.py "
     "runs each code for a few steps, a stop and --resume, and the collector"),
    ("examples/mace_water.py --quick", "tests/test_ml_potential.py runs it where mace-torch "
     "is installed (the ml extra, not the test extra)"),
    ("benchmarks/", "benchmarks measure speed or physics for minutes to hours; each is run "
     "in its --quick form by the tests of what it measures"),
    ("python -m pytest", "the test command itself"),
)


def blocks(text):
    """``(language, body)`` of every fenced block, nested fences kept inside their block."""
    out, fence, lang, body = [], None, None, []
    for line in text.splitlines(keepends=True):
        if fence is None:
            match = OPENING.match(line)
            if match:
                fence, lang, body = match.group(1), match.group(2), []
        elif line.strip() == fence:
            out.append((lang, "".join(body)))
            fence = None
        else:
            body.append(line)
    return out


def shell_lines(body):
    """``(command, reasons it is checked elsewhere)`` for each command line of a bash block."""
    for line in body.splitlines():
        command = line.split(" #")[0].strip()
        if not command or command.startswith("#"):
            continue
        skipped = [why for marker, why in CHECKED_ELSEWHERE if marker in line + "  "]
        yield command, skipped


def run_page(text, cwd, timeout=900):
    """Run a page's blocks in ``cwd``; returns the commands and blocks that ran."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    python, ran = [], []
    for lang, body in blocks(text):
        if lang == "yaml" and body.startswith("# file: "):
            name = body.splitlines()[0].split()[2]
            (cwd / name).write_text(body)
        elif lang == "python":
            python.append(body)
            ran.append("python")
        elif lang == "bash":
            # Python blocks before a shell block run first (the shell may read their files).
            if python:
                run_python(python, cwd, env, timeout)
                python = []
            for command, skipped in shell_lines(body):
                if skipped:
                    continue
                args = shlex.split(command)
                if args[0] == "rigidmd":
                    args = [sys.executable, "-m", "rigidmd.run.cli", *args[1:]]
                elif args[0] == "python":
                    args = [sys.executable, *args[1:]]
                    args = [str(ROOT / a) if a.startswith(("examples/", "benchmarks/",
                                                            "validation/")) else a
                            for a in args]
                result = subprocess.run(args, cwd=cwd, capture_output=True, text=True,
                                        env=env, timeout=timeout)
                assert result.returncode == 0, (command, result.stderr[-3000:])
                ran.append(command)
    if python:
        run_python(python, cwd, env, timeout)
    return ran


def run_python(sources, cwd, env, timeout):
    script = "\n\n".join(sources)
    (cwd / "page_blocks.py").write_text(script)
    result = subprocess.run([sys.executable, "page_blocks.py"], cwd=cwd, capture_output=True,
                            text=True, env=env, timeout=timeout)
    assert result.returncode == 0, result.stderr[-3000:]
