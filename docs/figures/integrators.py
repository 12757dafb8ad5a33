"""Which integrator conserves the energy best at a given time step?

RMS fluctuation and drift of the total energy, 32 rigid TIP3P waters, 10 ps NVE per run,
every integrator and LAMMPS's ``fix rigid/nve`` and ``fix rigid``, from
``validation/integrators.txt``.
"""

import re

from _common import ROOT, figure, read_text, require, save

ROW = re.compile(r"^(\S[\w /]*?)\s+(\d+\.\d+)\s+(\d+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\w+)\s*$")
UNSTABLE = re.compile(r"^(\w+)\s+\d+\.\d+\s+\d+\s+.*unstable at")


def draw(path):
    source = ROOT / "validation" / "integrators.txt"
    rows, unstable = {}, set()
    for line in read_text(source).splitlines():
        if UNSTABLE.match(line):
            unstable.add(UNSTABLE.match(line).group(1))
        match = ROW.match(line)
        if match and match.group(7) == "stable":
            rows.setdefault(match.group(1).strip(), []).append(
                (float(match.group(2)), abs(float(match.group(4))), float(match.group(5))))
    require(rows, source, "no stable rows (integrator, dt, steps, drift, RMS, ..., stable)")
    fig, (ax, bx) = figure(ncols=2, height=3.4)
    for k, (name, points) in enumerate(rows.items()):
        dt, drift, rms = zip(*points, strict=True)
        style = "--" if name.startswith("LAMMPS") else "-"
        ax.plot(dt, rms, "o" + style, color=f"C{k}", label=name)
        bx.plot(dt, drift, "o" + style, color=f"C{k}", label=name)
    for axis in (ax, bx):
        axis.set_xscale("log", base=2)
        axis.set_yscale("log")
        axis.set_xticks([0.5, 1, 2, 4], ["0.5", "1", "2", "4"])
        axis.set_xlabel("time step (fs)")
    ax.set_ylabel("RMS fluctuation of the total energy (eV)")
    bx.set_ylabel("|drift| (eV/ps)")
    ax.legend(fontsize=7)
    never = sorted(unstable - set(rows))
    note = f"\n{', '.join(never)}: unstable at every step, not drawn" if never else ""
    fig.suptitle("32 rigid TIP3P waters, 10 ps NVE per run" + note)
    save(fig, path)
