"""The site's figures (``docs/figures/*.py``, drawn by ``docs/_ext/rigidmd_docs.py``): each
refuses a bad data file in one line naming it, the build names a script that fails, no text
falls off a canvas, and a figure shows the data its page says it does.

(``tests/project/test_docs.py`` checks that every figure is drawn, twice the same, and shown.)
"""

import importlib.util
import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.figure  # noqa: E402
import matplotlib.text  # noqa: E402
import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
FIGURES = DOCS / "figures"
sys.path.insert(0, str(DOCS / "_ext"))
import rigidmd_docs  # noqa: E402

SCRIPTS = rigidmd_docs.figure_scripts()
#: What a data file is made into to see whether its script notices: nothing (a write that
#: failed or was interrupted), and text that is no format a script reads.
BAD_CONTENTS = {"empty": b"", "not the data": b"this is not the data\n"}


def shared_modules(folder=FIGURES):
    """The modules the scripts share (``_common``, ...): what ``from _common import`` finds."""
    return [p.stem for p in Path(folder).glob("_*.py")]


def draw(script, path, monkeypatch, folder=FIGURES):
    """Run ``script``'s ``draw(path)`` with the shared modules of ``folder`` (fresh)."""
    monkeypatch.syspath_prepend(str(folder))
    for name in shared_modules(folder):
        monkeypatch.setitem(sys.modules, name, None)  # put back as it was afterwards
        del sys.modules[name]
    spec = importlib.util.spec_from_file_location(f"figure_under_test_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.draw(path)


def inputs_of(script, tmp_path, monkeypatch):
    """The files under the repository that ``script`` reads to draw its figure."""
    read = []
    real = Path.read_text

    def recording(self, *args, **kwargs):
        read.append(Path(self).resolve())
        return real(self, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(Path, "read_text", recording)
        draw(script, tmp_path / f"{script.stem}.png", patch)
    return sorted({p.relative_to(ROOT) for p in read if ROOT in p.parents
                   and p.suffix != ".py"})


def test_there_are_figure_scripts():
    assert len(SCRIPTS) >= 12


@pytest.mark.slow
@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_every_figure_script_refuses_a_bad_input_in_one_line_naming_it(script, tmp_path,
                                                                          monkeypatch):
    """Each data file a script reads, emptied or replaced by other text in a copy of the
    tree: the script stops (no figure of nothing) with one line that names the file."""
    inputs = inputs_of(script, tmp_path, monkeypatch)
    assert inputs, f"{script.name} reads no data file"
    copy = tmp_path / "repo"
    (copy / "docs" / "figures").mkdir(parents=True)
    for source in FIGURES.glob("*.py"):
        shutil.copy(source, copy / "docs" / "figures" / source.name)
    for rel in inputs:
        (copy / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, copy / rel)
    copied_script = copy / "docs" / "figures" / script.name
    for rel in inputs:
        original = (copy / rel).read_bytes()
        for what, content in BAD_CONTENTS.items():
            (copy / rel).write_bytes(content)
            with pytest.raises(Exception) as caught:  # noqa: B017 - any error, if it names the file
                draw(copied_script, tmp_path / "bad.png", monkeypatch, copy / "docs" / "figures")
            message = str(caught.value)
            assert rel.as_posix() in message and "\n" not in message.strip(), (
                f"{script.name} with {rel} {what}: {type(caught.value).__name__}: {message!r}")
        (copy / rel).write_bytes(original)


def test_the_build_names_the_figure_script_that_failed(tmp_path, monkeypatch):
    """A script that fails stops ``write_figures`` with its name, and leaves no PNG."""
    folder = tmp_path / "figures"
    folder.mkdir()
    for name in shared_modules():
        shutil.copy(FIGURES / f"{name}.py", folder / f"{name}.py")
    (folder / "broken.py").write_text("def draw(path):\n    open(path, 'wb').write(b'x')\n"
                                      "    raise KeyError('energy')\n")
    monkeypatch.setattr(rigidmd_docs, "FIGURES", folder)
    monkeypatch.setattr(sys, "path", list(sys.path))
    with pytest.raises(Exception, match=r"broken\.py.*KeyError.*energy"):
        rigidmd_docs.write_figures(tmp_path / "out")
    assert not (tmp_path / "out" / "broken.png").exists()


def texts_off_canvas(fig):
    """The texts of ``fig`` (tick labels aside) that reach past its edges."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    ticks = {id(t) for ax in fig.axes for minor in (False, True)
             for t in ax.get_xticklabels(minor=minor) + ax.get_yticklabels(minor=minor)}
    off = []
    for text in fig.findobj(matplotlib.text.Text):
        if not text.get_visible() or not text.get_text() or id(text) in ticks:
            continue
        box = text.get_window_extent(renderer)
        if box.x0 < -1 or box.y0 < -1 or box.x1 > width + 1 or box.y1 > height + 1:
            off.append(f"{text.get_text()!r} spans x {box.x0:.0f}..{box.x1:.0f} of {width:.0f}")
    return off


@pytest.mark.slow
def test_no_figure_text_falls_off_its_canvas(tmp_path, monkeypatch):
    clipped = {}
    real = matplotlib.figure.Figure.savefig

    def checked(fig, path, *args, **kwargs):
        off = texts_off_canvas(fig)
        if off:
            clipped[Path(path).name] = off
        return real(fig, path, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", checked)
    monkeypatch.setattr(sys, "path", list(sys.path))
    drawn = rigidmd_docs.write_figures(tmp_path)
    assert len(drawn) == len(SCRIPTS)
    assert not clipped, clipped


def section_figures(page, heading):
    """The figure scripts whose PNGs the section ``heading`` of ``page`` shows."""
    import re

    text = (DOCS / page).read_text()
    section = text[text.index(heading):]
    following = re.search(r"^#{1,2} ", section[len(heading):], re.MULTILINE)
    if following:
        section = section[:len(heading) + following.start()]
    return re.findall(r"/_generated/figures/(\w+)\.png", section)


@pytest.mark.parametrize(("page", "heading", "data"), [
    ("validation/timestep.md", "## The small run", "validation/timestep_table_small.json"),
    ("validation/timestep-216.md", "## The goals", "validation/timestep_table_216.json")])
def test_a_timestep_figure_shows_the_runs_its_page_describes(page, heading, data, tmp_path,
                                                            monkeypatch):
    """The time-step page's small run (64 waters) and the 216-water page each show a figure
    drawn from their own runs, not the other's."""
    names = section_figures(page, heading)
    tables = [n for n in names if n.startswith("timestep_table")]
    assert tables, f"{page} shows no time-step figure under {heading!r}"
    for name in tables:
        read = inputs_of(FIGURES / f"{name}.py", tmp_path, monkeypatch)
        tables_read = [p.as_posix() for p in read if p.name.startswith("timestep_table")]
        assert tables_read == [data], (page, name, tables_read)


def test_the_nve_energy_curves_are_what_their_axis_says(tmp_path, monkeypatch):
    """Left panel: every curve is its energy's change since t = 0, as the axis is labelled
    (the kinetic energy was drawn raw against an axis of E − E_total(0))."""
    import csv

    import numpy as np

    seen = {}
    real = matplotlib.figure.Figure.savefig

    def capture(fig, path, *args, **kwargs):
        ax = fig.axes[0]
        seen["label"] = ax.get_ylabel()
        seen["lines"] = {line.get_label(): np.asarray(line.get_ydata()) for line in
                         ax.get_lines() if not line.get_label().startswith("_")}
        return real(fig, path, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", capture)
    draw(FIGURES / "nve_energy.py", tmp_path / "nve_energy.png", monkeypatch)
    lines = (FIGURES / "data" / "nve_trace.csv").read_text().splitlines()
    rows = [{k: float(v) for k, v in r.items()}
            for r in csv.DictReader(line for line in lines if not line.startswith("#"))]
    rows = [r for r in rows if r["dt_fs"] == 2.0]
    assert "since t = 0" in seen["label"], seen["label"]
    for label, column in (("potential", "epot_eV"), ("kinetic", "ekin_eV"),
                          ("total", "etot_eV")):
        expected = np.array([r[column] - rows[0][column] for r in rows])
        np.testing.assert_allclose(seen["lines"][label], expected, err_msg=label)
