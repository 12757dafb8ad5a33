"""Why is the temperature of an NVE run not the temperature it started at?

The temperature of 32 rigid TIP3P waters in NVE at 2 fs after rigid Maxwell-Boltzmann
velocities at 300 K, from ``docs/figures/data/nve_trace.csv``: the cluster as
``water_cluster`` builds it is not at a minimum, so the potential energy it gives up in the
first tenth of a picosecond heats it, and the temperature then fluctuates about its new mean.
"""

import numpy as np
from _common import DATA, figure, read_csv, require, save


def draw(path):
    source = DATA / "nve_trace.csv"
    rows = require([r for r in read_csv(source, "dt_fs", "time_ps", "temperature_K")
                    if r["dt_fs"] == 2.0], source, "no rows at 2 fs")
    t = np.array([r["time_ps"] for r in rows])
    temp = np.array([r["temperature_K"] for r in rows])
    fig, ax = figure(width=5.6, height=3.0)
    ax.plot(t, temp, label="temperature")
    late = t >= 0.5
    require(late.any(), source, "no rows after 0.5 ps at 2 fs")
    ax.axhline(300, color="k", ls=":", label="velocities drawn at 300 K")
    ax.axhline(temp[late].mean(), color="C1", ls="--",
               label=f"mean after 0.5 ps: {temp[late].mean():.0f} K")
    ax.set_xlabel("time (ps)")
    ax.set_ylabel("T (K)")
    ax.set_title("32 rigid TIP3P waters, NVE at 2 fs")
    ax.legend(fontsize=7)
    save(fig, path)
