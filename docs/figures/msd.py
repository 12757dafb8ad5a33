"""How is the diffusion coefficient read from a trajectory?

Mean squared displacement of the centres of mass of 216 rigid TIP3P waters over 2 ps of NVE
(``examples/tip3p_water.py --quick``), and the slope 6D of its fit window, from
``docs/figures/data/tip3p_msd.csv``.
"""

import re

import numpy as np
from _common import DATA, figure, read_csv, read_text, require, save


def draw(path):
    source = DATA / "tip3p_msd.csv"
    rows = read_csv(source, "lag_ps", "msd_A2")
    t = np.array([row["lag_ps"] for row in rows])
    msd = np.array([row["msd_A2"] for row in rows])
    head = read_text(source).splitlines()[0]
    found = require(re.search(r"D = ([\d.e+-]+) cm2/s", head), source,
                    "no 'D = ... cm2/s' in its first line")
    d_cm2_s = float(found.group(1))
    slope = 6 * d_cm2_s * 1e4  # Å²/ps
    window = (t >= 0.2) & (t <= 0.8)
    offset = np.mean(msd[window] - slope * t[window])
    fig, ax = figure(width=5.6, height=3.0)
    ax.plot(t, msd, label="MSD of the centres of mass")
    ax.plot(t[window], offset + slope * t[window], "k--",
            label=f"6 D t, D = {d_cm2_s * 1e5:.2f}e-5 cm²/s (fit 0.2–0.8 ps)")
    ax.set_xlabel("lag time (ps)")
    ax.set_ylabel("MSD (Å²)")
    ax.set_title("216 rigid TIP3P waters, 298 K, 2 ps NVE")
    ax.legend(fontsize=7)
    save(fig, path)
