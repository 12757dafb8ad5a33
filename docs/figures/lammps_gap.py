"""How closely does rigidmd follow LAMMPS's ``fix rigid/nve``?

Position gap to LAMMPS over 500 steps of 1 fs for four systems, with ASE's and with LAMMPS's
physical constants, from ``examples/output/validate_against_lammps.txt``.
"""

import re

from _common import ROOT, figure, read_text, require, save


def draw(path):
    source = ROOT / "examples" / "output" / "validate_against_lammps.txt"
    lines = read_text(source).splitlines()
    header = next((line for line in lines if line.startswith("system")), "")
    steps = [int(s) for s in require(re.findall(r"step (\d+)", header), source,
                                     "no header line 'system ... step 0 step 100 ...'")]
    fig, ax = figure(width=6.0, height=3.4)
    k = 0
    for line in lines:
        match = re.match(r"^(.+?)\s{2,}(ASE|LAMMPS)\s+(.*)$", line)
        if not match:
            continue
        values = [float(v) for v in match.group(3).split()[:len(steps)]]
        name, constants = match.group(1).strip(), match.group(2)
        colour = f"C{k // 2}"
        ax.plot(steps, values, "o-" if constants == "ASE" else "s--", color=colour,
                label=f"{name}, {constants} constants")
        k += 1
    require(k, source, "no rows '<system>  ASE|LAMMPS  <gaps>'")
    ax.set_yscale("log")
    ax.set_xlabel("step (1 fs)")
    ax.set_ylabel("largest position gap to LAMMPS (Å)")
    ax.set_title("rigidmd against LAMMPS fix rigid/nve")
    ax.legend(fontsize=6, ncols=2)
    save(fig, path)
