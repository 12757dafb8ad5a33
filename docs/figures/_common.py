"""What the figure scripts share: where the data is, how a figure looks and is saved.

Every script in ``docs/figures/`` (not starting with ``_``) defines ``draw(path)``, which
reads committed data (``docs/figures/data/``, ``benchmarks/``, ``validation/``,
``examples/output/``) and writes one PNG to ``path``.  The docs build calls them
(``docs/_ext/rigidmd_docs.py``, into ``docs/_generated/figures/``); no simulation runs.
"""

import csv
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parent / "data"

plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 100, "font.size": 9,
                     "axes.grid": True, "grid.alpha": 0.3, "legend.frameon": False,
                     "svg.hashsalt": "rigidmd"})


def figure(ncols=1, width=6.4, height=3.4, **kw):
    return plt.subplots(1, ncols, figsize=(width, height), layout="constrained", **kw)


def save(fig, path):
    """Write a PNG whose bytes depend on the data only (no date or version in it)."""
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)


def read_csv(path):
    """Rows of a CSV file whose ``#`` lines say how it was made; numbers as floats."""
    lines = [line for line in Path(path).read_text().splitlines() if not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    return [{k: _number(v) for k, v in row.items()} for row in rows]


def markdown_rows(text, first_cell=None):
    """The rows of the Markdown tables in ``text`` as lists of cells (header rows skipped)."""
    rows = []
    for line in text.splitlines():
        if not line.startswith("|") or set(line) <= set("|-: "):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if first_cell is None or cells[0] == first_cell:
            rows.append(cells)
    return rows


def number(text):
    """The first number in a cell (``-1.4e-03``, ``1.08 (1.08)``, ``> 600``)."""
    match = re.search(r"[-+−]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text.replace("−", "-"))
    return float(match.group(0)) if match else float("nan")


def _number(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return value
