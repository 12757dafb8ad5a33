"""The tests mirror the package: where a module's tests are, and what a test file is for.

``src/rigidmd/<package>/<module>.py`` has its tests in ``tests/<package>/test_<module>.py``
(a private module ``_numba.py`` in ``test_numba.py``; a module at the top,
``src/rigidmd/water.py``, in ``tests/test_water.py``).  A module may have more files,
``test_<module>_<topic>.py`` (``tests/lammps/test_engine_faults.py``).  Two folders
are apart: ``tests/physics/`` (checks against peers and published or statistical
results: LAMMPS, OpenMM, water properties, tight binding and ML potentials, the
time-step table) and ``tests/project/`` (the repository as a whole: README, docs,
examples, layout, stored trajectories, benchmark scripts).  Builders shared by tests
live beside ``conftest.py`` (``tests/helpers.py`` and the few files named in
``SHARED``); reference data in ``tests/data/`` beside the script that wrote it.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "src" / "rigidmd"
TESTS = ROOT / "tests"
#: Folders of tests that do not mirror one module.
APART = ("physics", "project")
#: The shared files beside conftest.py (imported by name from every folder).
SHARED = {"conftest.py", "helpers.py", "free_top.py", "codeblocks.py", "hypothesis_or_skip.py"}


def mirrored(module: Path) -> Path:
    """The test file of ``module`` (a path under ``SOURCE``)."""
    relative = module.relative_to(SOURCE)
    return TESTS / relative.parent / f"test_{relative.stem.lstrip('_')}.py"


def modules(source: Path = SOURCE) -> list[Path]:
    """Every module of the package, ``__init__.py`` aside (a package's names are its modules')."""
    return sorted(p for p in source.rglob("*.py") if p.name != "__init__.py")


def unmirrored_tests(tests: Path = TESTS, source: Path = SOURCE) -> list[str]:
    """Test files outside ``APART`` that name no module of their folder's package, with why."""
    problems = []
    for path in sorted(tests.rglob("*.py")):
        relative = path.relative_to(tests)
        if relative.parts[0] in APART + ("data",) or "__pycache__" in relative.parts:
            continue
        if (len(relative.parts) == 1 and path.name in SHARED) or path.name == "conftest.py":
            continue  # (a folder's own conftest.py is pytest's, not a module's tests)
        if not path.name.startswith("test_"):
            problems.append(f"tests/{relative}: not a test file; shared builders go in "
                            "tests/helpers.py")
            continue
        package = source / relative.parent
        stems = {p.stem.lstrip("_") for p in package.glob("*.py") if p.name != "__init__.py"}
        name = path.stem.removeprefix("test_")
        if not any(name == stem or name.startswith(stem + "_") for stem in stems):
            problems.append(f"tests/{relative}: no module src/rigidmd/{relative.parent / name}.py"
                            " (nor one its name starts with); tests of the whole go in "
                            "tests/physics/ or tests/project/")
    return problems


def test_every_module_has_its_test_file():
    missing = [f"{m.relative_to(ROOT)} has no {mirrored(m).relative_to(ROOT)}"
               for m in modules() if not mirrored(m).is_file()]
    assert not missing, "\n".join(missing)


def test_every_test_file_mirrors_a_module():
    problems = unmirrored_tests()
    assert not problems, "\n".join(problems)


def test_the_rule_names_what_it_misses(tmp_path):
    """The rule on a made-up package: a module without tests, a test without a module."""
    source, tests = tmp_path / "src", tmp_path / "tests"
    for name in ("core/stepper.py", "core/_numba.py", "water.py", "core/__init__.py"):
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        (source / name).write_text("")
    for name in ("core/test_numba.py", "core/test_stepper_faults.py", "core/test_link.py",
                 "core/builders.py", "test_water.py", "helpers.py", "physics/test_any.py"):
        (tests / name).parent.mkdir(parents=True, exist_ok=True)
        (tests / name).write_text("")
    assert unmirrored_tests(tests, source) == [
        "tests/core/builders.py: not a test file; shared builders go in tests/helpers.py",
        "tests/core/test_link.py: no module src/rigidmd/core/link.py (nor one its name starts "
        "with); tests of the whole go in tests/physics/ or tests/project/",
    ]
    assert [p.relative_to(source).as_posix() for p in modules(source)] == [
        "core/_numba.py", "core/stepper.py", "water.py"]
    assert mirrored(SOURCE / "core" / "_numba.py") == TESTS / "core" / "test_numba.py"
    assert mirrored(SOURCE / "water.py") == TESTS / "test_water.py"
