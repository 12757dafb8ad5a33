"""Do rigidmd and OpenMM sample the same temperatures at every time step?

Kinetic and configurational temperatures of translation and rotation in NVE, 216 TIP4P-Ew
waters, rigidmd and OpenMM from the same states, against the time step (means of the runs
at each step, with their standard errors), from ``validation/water_openmm_nve.json``.
"""

from collections import defaultdict

import numpy as np
from _common import ROOT, figure, read_json, require, save

KEYS = [("T_tr", "kinetic, translation"), ("T_rot", "kinetic, rotation"),
        ("Tconf_tr", "configurational, translation"),
        ("Tconf_rot", "configurational, rotation")]


def draw(path):
    source = ROOT / "validation" / "water_openmm_nve.json"
    runs = read_json(source, "runs")["runs"]
    fig, axes = figure(ncols=2, width=7.2, height=3.4, sharey=True)
    for ax, code in zip(axes, ("rigidmd", "openmm"), strict=True):
        for k, (key, label) in enumerate(KEYS):
            by_dt = defaultdict(list)
            for run in runs:
                if run["code"] == code and run["ensemble"] == "nve" and key in run:
                    by_dt[run["dt_fs"]].append(run[key])
            dts = sorted(require(by_dt, source, f"no {code} NVE runs with {key}"))
            mean = [np.mean([v[0] for v in by_dt[dt]]) for dt in dts]
            err = [np.sqrt(np.mean([v[1] ** 2 for v in by_dt[dt]]) / len(by_dt[dt]))
                   for dt in dts]
            ax.errorbar(dts, mean, yerr=err, fmt="o-", color=f"C{k}", capsize=2, label=label)
        ax.set_xlabel("time step (fs)")
        ax.set_title("rigidmd" if code == "rigidmd" else "OpenMM")
    axes[0].set_ylabel("temperature (K)")
    axes[0].legend(fontsize=7)
    fig.suptitle("216 TIP4P-Ew waters, NVE from the same states")
    save(fig, path)
