"""Does a 4 fs step move the density of rigid TIP4P/2005?

The NPT density of 216 waters at 298 K and 1 atm under ``RigidLangevinBAOAB``'s part and the
Monte Carlo barostat: each run and each step's runs combined, with their standard errors,
beside the published value (``validation/npt_density_216.runs.json`` and ``.json``, made by
``validation/npt_density.py``).
"""

import numpy as np
from _common import ROOT, figure, read_json, save

PUBLISHED = 0.9979  # g/cm³, TIP4P/2005 at 298 K and 1 bar (Abascal & Vega 2005)


def draw(path):
    runs = read_json(ROOT / "validation" / "npt_density_216.runs.json")
    steps = read_json(ROOT / "validation" / "npt_density_216.json")
    fig, ax = figure(width=5.6, height=3.4)
    for r in runs:
        rho, err = r["density"]
        if np.isfinite(rho):
            ax.errorbar(r["point"]["dt_fs"] * (0.92 + 0.04 * r["point"]["seed"]), rho,
                        yerr=err, fmt="o", ms=3, color="0.6", capsize=2)
    for s in steps:
        rho, err = s["density"]
        ax.errorbar(s["dt_fs"] * 1.12, rho, yerr=2 * err, fmt="s", ms=6, color="C0", capsize=4,
                    label="runs combined, ±2σ" if s is steps[0] else None)
    ax.axhline(PUBLISHED, color="C3", lw=0.8, ls="--", label="published (0.9979)")
    ax.errorbar([], [], fmt="o", ms=3, color="0.6", label="each run, ±σ")
    ax.set_xscale("log")
    ticks = sorted({s["dt_fs"] for s in steps})
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.minorticks_off()
    ax.set_xlim(min(ticks) / 1.6, max(ticks) * 1.6)
    ax.set_xlabel("time step (fs)")
    ax.set_ylabel("density (g/cm³)")
    ax.set_title("216 TIP4P/2005, 298 K, 1 atm (BAOAB, Monte Carlo barostat)")
    ax.legend(fontsize=7)
    save(fig, path)
