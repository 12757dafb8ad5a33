"""Run the fenced code blocks of a Markdown page as a reader following it would.

Used by ``tests/project/test_readme.py`` (README.md) and ``tests/project/test_docs.py`` (every page
under ``docs/``).  The blocks of one page run in order in one scratch directory:

* ``python`` blocks one after the other in one interpreter (a later block may
  use what an earlier one defined, as a reader following along would);
* ``yaml`` blocks whose first line is ``# file: NAME`` are written to NAME
  before the blocks after them run (other ``yaml`` blocks are fragments, not run);
  so are ``python`` blocks that start so (a module the page writes, which later
  blocks import and the ``rigidmd`` command may name: not run as a block);
* ``bash`` blocks line by line (comments after ``#`` are shell comments);
* an ``output`` block right after a ``python`` block is what that block prints: the
  test compares them line by line, token by token (:func:`outputs_match`); a number
  written ``A±T`` matches any printed number within ``T`` of ``A`` (for what varies
  from machine to machine or run to run), every other token must be printed as written;
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
    ("python -m venv .venv", ".ci/run makes a fresh virtual environment of its own"),
    ("sphinx", ".ci/run builds the documentation with -W"),
    ("examples/tip3p_water.py --outdir out", "tests/project/test_examples.py runs it with --quick"),
    ("examples/tip4p2005.py --outdir out4", "tests/project/test_examples.py runs it with --quick"),
    ("validation/water_models.py --jobs 2", "hours; tests/physics/test_water_properties.py "
     "runs its --quick form"),
    ("validation/water_lammps_check.py --models", "needs a finished water_models.py run; "
     "tests/physics/test_water_properties.py runs its --quick form"),
    ("validation/water_openmm_check.py --models", "minutes a model; "
     "tests/physics/test_water_openmm.py runs its --quick form"),
    ("validation/water_openmm_nve.py", "an hour and more on 2 cores; "
     "tests/physics/test_water_openmm.py runs its --quick form and a 27-water tracking check"),
    ("validation/water_openmm_long.py", "each run as long as its --budget-s; "
     "tests/physics/test_water_openmm.py runs its --quick form"),
    ("validation/timestep_table", "core-days for the full table; "
     "tests/physics/test_timestep_table.py runs each code for a few steps, a stop and "
     "--resume, and the collector"),
    ("examples/mace_water.py --quick", "tests/physics/test_ml_potential.py runs it where "
     "mace-torch is installed (the ml extra, not the test extra)"),
    ("validation/time_to_solution.py", "minutes on a quiet core; "
     "tests/physics/test_timestep_table.py runs it on the 64-water start for a few steps"),
    ("validation/respa_kspace_share.py", "minutes of native LAMMPS runs; "
     "tests/physics/test_respa_lammps.py runs its --quick form"),
    ("validation/respa_lammps_cost.py", "minutes; tests/physics/test_respa_lammps.py runs its "
     "--quick form"),
    ("validation/respa_lammps_native.py", "minutes of native LAMMPS runs; "
     "tests/physics/test_respa_lammps.py runs its --quick form, a stop and --resume"),
    ("validation/respa_lammps_nve.py", "minutes; tests/physics/test_respa_lammps.py runs its "
     "--quick form"),
    ("validation/respa_chgnet.py", "15 minutes, in CHGNet's own environment (PyTorch, not "
     "the test extra); tests/physics/test_respa_chgnet.py checks its fitted model and runs "
     "its --quick form where CHGNet is installed"),
    ("validation/npt_density.py", "hours for the table's runs; tests/physics/"
     "test_npt_density.py runs a few steps, a stop and --resume, and the report on the "
     "committed runs"),
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


#: The line a page's script prints after each ``python`` block, to cut its output apart.
BLOCK_END = "<<<end of a docs block>>>"
TOLERANCE = re.compile(r"^([-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?)±(\d+(?:\.\d*)?(?:e[-+]?\d+)?)$")


def outputs_match(expected, printed):
    """Whether ``printed`` is what an ``output`` block says, and if not, the first difference.

    Lines are compared one by one (trailing spaces and blank lines at either end aside),
    each split on whitespace; an expected token ``A±T`` matches a number within ``T`` of
    ``A``; any other token must be printed exactly.  Returns ``(ok, why)``.
    """
    want = expected.strip("\n").splitlines()
    got = printed.strip("\n").splitlines()
    if len(want) != len(got):
        return False, f"{len(got)} lines printed, {len(want)} stated:\n{printed}"
    for number, (w, g) in enumerate(zip(want, got, strict=True), 1):
        wt, gt = w.split(), g.split()
        if len(wt) != len(gt):
            return False, f"line {number}: printed {g!r}, stated {w!r}"
        for a, b in zip(wt, gt, strict=True):
            match = TOLERANCE.match(a)
            if match:
                try:
                    value = float(b)
                except ValueError:
                    return False, f"line {number}: printed {b!r} where a number {a} is stated"
                if abs(value - float(match.group(1))) > float(match.group(2)):
                    return False, f"line {number}: printed {b}, stated {a}"
            elif a != b:
                return False, f"line {number}: printed {g!r}, stated {w!r}"
    return True, ""


def run_page(text, cwd, timeout=900):
    """Run a page's blocks in ``cwd``; returns the commands and blocks that ran."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    python, outputs, ran = [], {}, []
    previous = None
    for lang, body in blocks(text):
        if lang == "output":
            assert previous == "python", "an output block follows no python block"
            outputs[len(python) - 1] = body
            previous = lang
            continue
        previous = lang
        if lang in ("yaml", "python") and body.startswith("# file: "):
            name = body.splitlines()[0].split()[2]
            (cwd / name).write_text(body)
            previous = f"{lang} file"  # no output block follows a file
        elif lang == "python":
            python.append(body)
            ran.append("python")
        elif lang == "bash":
            # Python blocks before a shell block run first (the shell may read their files).
            if python:
                run_python(python, cwd, env, timeout, outputs)
                python, outputs = [], {}
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
        run_python(python, cwd, env, timeout, outputs)
    return ran


def run_python(sources, cwd, env, timeout, outputs=None):
    """Run python blocks as one script; check each stated output (``{index: text}``)."""
    outputs = outputs or {}
    script = "".join(f"{source}\n\nprint({BLOCK_END!r}, flush=True)\n\n" for source in sources)
    (cwd / "page_blocks.py").write_text(script)
    result = subprocess.run([sys.executable, "page_blocks.py"], cwd=cwd, capture_output=True,
                            text=True, env=env, timeout=timeout)
    assert result.returncode == 0, result.stderr[-3000:]
    printed = result.stdout.split(BLOCK_END + "\n")
    for index, expected in outputs.items():
        ok, why = outputs_match(expected, printed[index])
        assert ok, f"python block {index + 1} of the page: {why}"
