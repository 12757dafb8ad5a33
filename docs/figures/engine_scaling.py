"""Does the engine keep up with native LAMMPS on many cores?

Time per step of native LAMMPS and of ``LAMMPSEngine`` on 1-16 MPI ranks (16-core machine),
from ``docs/figures/data/engine_scaling.csv`` (the table of the engine-scaling page).
"""

from _common import DATA, figure, read_csv, require, save


def draw(path):
    source = DATA / "engine_scaling.csv"
    rows = read_csv(source, "waters", "ranks", "native_ms", "engine_over_native")
    fig, (ax, bx) = figure(ncols=2, height=3.2)
    for k, waters in enumerate((216, 1728, 13824)):
        sel = require([r for r in rows if r["waters"] == waters], source,
                      f"no rows of {waters} waters")
        ranks = [r["ranks"] for r in sel]
        native = [r["native_ms"] for r in sel]
        engine = [r["native_ms"] * r["engine_over_native"] for r in sel]
        ax.plot(ranks, native, "o-", color=f"C{k}", label="native LAMMPS" if k == 0 else None)
        ax.plot(ranks, engine, "s--", color=f"C{k}", mfc="none",
                label="LAMMPSEngine" if k == 0 else None)
        bx.plot(ranks, [r["engine_over_native"] for r in sel], "o-", color=f"C{k}",
                label=f"{waters:,} waters")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks([1, 2, 4, 8, 16], ["1", "2", "4", "8", "16"])
    ax.set_xlabel("MPI ranks")
    ax.set_ylabel("ms per step")
    ax.legend(fontsize=7, loc="lower left")
    bx.axhline(1.0, color="k", lw=1)
    bx.set_xscale("log", base=2)
    bx.set_xticks([1, 2, 4, 8, 16], ["1", "2", "4", "8", "16"])
    bx.set_ylim(0.6, 1.5)
    bx.set_xlabel("MPI ranks")
    bx.set_ylabel("engine / native (wall time)")
    bx.legend(fontsize=7)
    fig.suptitle("LAMMPSEngine against native LAMMPS, TIP3P NVE, 16-core machine")
    save(fig, path)
