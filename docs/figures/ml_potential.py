"""Does rigid water need a shorter step under a machine-learned potential?

RMS fluctuation of the total energy against the time step, 8 waters under CHGNet: rigid
(rigidmd, and ASE's RATTLE route) and flexible, with TIP3P as the control, from
``benchmarks/ml_potential.txt``.
"""

from _common import ROOT, figure, markdown_rows, number, read_text, require, save

SERIES = [(("float64", "rigidmd"), "rigid, rigidmd (float64)", "o-"),
          (("float32", "RATTLE"), "rigid, ASE RATTLE (float32)", "s--"),
          (("float32", "flexible"), "flexible (float32)", "^-"),
          (("TIP3P (control)", "rigidmd"), "TIP3P control, rigidmd", "x:")]


def draw(path):
    source = ROOT / "benchmarks" / "ml_potential.txt"
    rows = markdown_rows(read_text(source))
    fig, ax = figure(width=5.6, height=3.4)
    for (model, route), label, style in SERIES:
        sel = require([r for r in rows if r[0] == model and r[1] == route], source,
                      f"no table rows '| {model} | {route} |'")
        ax.plot([number(r[2]) for r in sel], [number(r[4]) for r in sel], style, label=label)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks([0.25, 0.5, 1, 2], ["0.25", "0.5", "1", "2"])
    ax.set_xlabel("time step (fs)")
    ax.set_ylabel("RMS of the total energy (eV)")
    ax.set_title("8 waters under CHGNet, 0.2 ps NVE per run")
    ax.legend(fontsize=7)
    save(fig, path)
