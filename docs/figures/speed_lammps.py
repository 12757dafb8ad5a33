"""How fast is a rigidmd run with LAMMPS forces against native LAMMPS?

Wall time per step over native LAMMPS's (``fix rigid/nve/small`` for NVE, ``fix
rigid/npt/small`` for the barostats), 216 and 1728 TIP3P waters on one core, from
``benchmarks/lammps_engine.txt``.
"""

import re

import numpy as np
from _common import ROOT, DataError, figure, name, read_text, save

ROW = re.compile(r"^\s*(.+?)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s*$")
RUNS = [("NVE LAMMPSCalculator", "NVE, in-process"), ("NVE LAMMPSEngine", "NVE, engine"),
        ("RigidNPT (MTK iso) LAMMPSCalculator", "MTK NPT, in-process"),
        ("RigidNPT (MTK iso) LAMMPSEngine", "MTK NPT, engine"),
        ("RigidCRescale every 1, LAMMPSCalculator", "C-rescale, in-process"),
        ("RigidCRescale every 1, LAMMPSEngine", "C-rescale, engine")]


def tables(text):
    """{title: {run: wall ratio to native}} of each table."""
    out, title = {}, None
    for line in text.splitlines():
        if line and not line.startswith(" "):
            title = line.split(" (")[0]
            out.setdefault(title, {})
            continue
        match = ROW.match(line)
        if match and title:
            out[title][match.group(1)] = float(match.group(3))
    return out


def draw(path):
    source = ROOT / "benchmarks" / "lammps_engine.txt"
    data = tables(read_text(source))
    fig, ax = figure(height=3.2)
    y = np.arange(len(RUNS))
    for k, (title, colour) in enumerate((("216 waters, one core", "C0"),
                                         ("1728 waters, one core", "C1"))):
        missing = [run for run, _ in RUNS if run not in data.get(title, {})]
        if missing:
            raise DataError(f"{name(source)}: no row {missing[0]!r} in a table {title!r}")
        ratios = [data[title][run] for run, _ in RUNS]
        ax.barh(y + (k - 0.5) * 0.38, ratios, height=0.38, color=colour,
                label=title.replace(", one core", ""))
    ax.axvline(1.0, color="k", lw=1)
    ax.set_yticks(y, [label for _, label in RUNS])
    ax.invert_yaxis()
    ax.set_xlim(0.8, 1.15)
    ax.set_xlabel("wall time per step / native LAMMPS (below 1: faster)")
    ax.set_title("rigidmd with LAMMPS forces against native LAMMPS, one core")
    ax.legend(loc="lower right")
    save(fig, path)
