"""What the figure scripts share: where the data is, how a figure looks and is saved.

Every script in ``docs/figures/`` (not starting with ``_``) defines ``draw(path)``, which
reads committed data (``docs/figures/data/``, ``benchmarks/``, ``validation/``,
``examples/output/``) and writes one PNG to ``path``.  The docs build calls them
(``docs/_ext/rigidmd_docs.py``, into ``docs/_generated/figures/``); no simulation runs.

A script reads its data with :func:`read_text`, :func:`read_json`, :func:`read_jsonl` or
:func:`read_csv` and checks what it parsed with :func:`require`: an empty, truncated or
malformed file stops it with a :class:`DataError` of one line naming the file, not with a
figure of nothing or a ``KeyError`` that names none.
"""

import csv
import json
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


class DataError(ValueError):
    """A figure's data file is empty or not what its script reads (one line, naming it)."""


def name(path):
    """``path`` as the message names it: relative to the repository where it is inside."""
    path = Path(path)
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


def require(found, path, what):
    """``found`` if it holds something; else a :class:`DataError` naming ``path`` and saying
    ``what`` is wrong (``"no rows"``, ``"no '216 TIP3P waters' table"``)."""
    if not found:
        raise DataError(f"{name(path)}: {what}")
    return found


def read_text(path):
    """The text of a data file; a :class:`DataError` naming it if it is empty."""
    text = Path(path).read_text(encoding="utf-8")
    return require(text.strip() and text, path, "empty file")


def read_json(path, *keys):
    """A JSON data file, checked to hold ``keys`` (each non-empty) if it is an object."""
    try:
        data = json.loads(read_text(path))
    except json.JSONDecodeError as err:
        raise DataError(f"{name(path)}: not JSON ({err})") from None
    for key in keys:
        require(isinstance(data, dict) and data.get(key), path, f"no {key!r}")
    return require(data, path, "no data")


def read_jsonl(path):
    """The records of a JSON Lines data file (one object a line; at least one)."""
    records = []
    for number_, line in enumerate(read_text(path).splitlines(), 1):
        if line.strip():
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError as err:
                raise DataError(f"{name(path)}:{number_}: not JSON ({err})") from None
    return require(records, path, "no records")


def read_csv(path, *columns):
    """Rows of a CSV file whose ``#`` lines say how it was made; numbers as floats.

    At least one row, with every column of ``columns``; a :class:`DataError` naming the file
    otherwise.
    """
    lines = [line for line in read_text(path).splitlines() if not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    require(rows, path, "no rows")
    missing = [c for c in columns if c not in rows[0]]
    require(not missing, path, f"no column {', '.join(missing)}")
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
