"""Do iso, aniso and triclinic NPT sample the same density, in-process and in an engine?

Mean density ± standard error of 216 TIP3P waters under ``RigidNPT`` (MTK) with LAMMPS
forces, each cell coupling, in-process and through ``LAMMPSEngine``, from the 216-water
table of ``validation/engine_ensembles.txt``.
"""

import re

import matplotlib.ticker
from _common import ROOT, figure, read_text, require, save


def draw(path):
    source = ROOT / "validation" / "engine_ensembles.txt"
    text = read_text(source)
    require("216 TIP3P waters" in text, source, "no '216 TIP3P waters' table")
    block = text[text.index("216 TIP3P waters"):]
    rows = require(re.findall(r"^\s+(LAMMPS\w+ \w+)\s+([\d.]+)±([\d.]+)", block,
                              re.MULTILINE), source, "no density rows in its 216-water table")
    fig, ax = figure(width=5.6, height=3.0)
    for k, (_run, density, error) in enumerate(rows):
        ax.errorbar(float(density), k, xerr=float(error), fmt="o", capsize=3)
    ax.set_yticks(range(len(rows)), [run for run, _, _ in rows])
    ax.invert_yaxis()
    ax.set_xlabel("density (g/cm³)")
    ax.set_title("216 TIP3P waters, MTK NPT, 298 K, 1 atm, 60 ps")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
    save(fig, path)
