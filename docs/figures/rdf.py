"""What does the O–O radial distribution function of rigid TIP3P look like?

g(r) of the oxygens of 216 rigid TIP3P waters over 2 ps of NVE with LAMMPS forces
(``examples/tip3p_water.py --quick``), from ``docs/figures/data/tip3p_rdf.csv``.
"""

import numpy as np
from _common import DATA, figure, read_csv, save


def draw(path):
    rows = read_csv(DATA / "tip3p_rdf.csv", "r_A", "g")
    r = np.array([row["r_A"] for row in rows])
    g = np.array([row["g"] for row in rows])
    fig, ax = figure(width=5.6, height=3.0)
    ax.plot(r, g)
    peak = np.argmax(g)
    ax.annotate(f"first peak {r[peak]:.2f} Å", (r[peak], g[peak]), xytext=(10, -5),
                textcoords="offset points", fontsize=8)
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xlim(2.0, r.max())
    ax.set_xlabel("r (Å)")
    ax.set_ylabel("g_OO(r)")
    ax.set_title("216 rigid TIP3P waters, 298 K, 2 ps NVE")
    save(fig, path)
