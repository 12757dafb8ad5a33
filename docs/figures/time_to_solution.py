"""What does a nanosecond of rigid water cost at the accuracy the step allows?

ns/day of each code and integrator at its largest step that meets the time-step table's goals
(and the steps given beside them), one thread, 216 TIP4P/2005 waters, measured side by side
in one run (``validation/time_to_solution.json``, made by ``validation/time_to_solution.py``).
"""

import numpy as np
from _common import ROOT, figure, read_json, save
from matplotlib.patches import Patch

NAMES = {("rigidmd", "baoab"): "rigidmd RigidLangevinBAOAB",
         ("rigidmd", "langevin"): "rigidmd RigidLangevin",
         ("rigidmd", "bussi"): "rigidmd RigidBussi",
         ("rigidmd", "nosehoover"): "rigidmd RigidNoseHoover",
         ("lammps", "nvt_small"): "LAMMPS fix rigid/nvt/small",
         ("openmm", "middle"): "OpenMM LangevinMiddle + SETTLE"}
COLOURS = {"not excluded": "C0", "shown": "C2", "given": "0.6"}


def label(row):
    """The row's code and integrator in words; an r-RESPA split named with its substeps and
    fast level (the row's ``substeps`` and ``r_split``)."""
    text = NAMES[(row["code"], row["scheme"])]
    if row["substeps"] > 1:
        text += f" r-RESPA k={row['substeps']}, {row['r_split']:g} Å fast"
    return f"{text}, {row['dt_fs']:g} fs"


def draw(path):
    data = read_json(ROOT / "validation" / "time_to_solution.json", "rows", "waters")
    rows = data["rows"]
    fig, ax = figure(width=7.6, height=0.45 * len(rows) + 1.4)
    y = np.arange(len(rows))
    ax.barh(y, [r["ns_per_day"] for r in rows],
            color=[COLOURS[r["basis"]] for r in rows])
    for k, r in enumerate(rows):
        ax.text(r["ns_per_day"], k, f" {r['ns_per_day']:.0f}", va="center", fontsize=8)
    ax.set_yticks(y, [label(r) for r in rows])
    ax.invert_yaxis()
    ax.set_xlabel("ns/day, one thread")
    words = {"not excluded": "largest step no goal excludes",
             "shown": "largest step every goal is shown to meet",
             "given": "a step chosen, not judged by the table"}
    ax.legend(handles=[Patch(color=colour, label=words[basis])
                       for basis, colour in COLOURS.items()
                       if any(r["basis"] == basis for r in rows)],
              loc="lower right", fontsize=7)
    ax.set_title(f"TIP4P/2005, {data['waters']} waters, one thread")
    save(fig, path)
