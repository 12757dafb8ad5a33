"""Does CHGNet on the slow level of r-RESPA allow a longer outer step?

The conserved energy's fluctuation against the outer step for CHGNet alone and for splits
with a fitted four-site water (or TIP4P/2005) on the fast level, 8 rigid waters in NVE
(``validation/respa_chgnet.json``, made by ``validation/respa_chgnet.py``).
"""

from _common import ROOT, figure, read_json, require, save

LABELS = {"fit": "fitted four-site", "fit_oh": "fitted, with O–H terms",
          "tip4p2005": "TIP4P/2005"}


def draw(path):
    source = ROOT / "validation" / "respa_chgnet.json"
    rows = read_json(source, "nve")["nve"]
    fig, ax = figure(width=6.4, height=3.6)
    groups = sorted({(r["fast"], r["k"]) for r in rows},
                    key=lambda g: (list(LABELS).index(g[0]), g[1]))
    for kind, k in groups:
        mine = sorted((r for r in rows if (r["fast"], r["k"]) == (kind, k)),
                      key=lambda r: r["dt_fs"])
        name = "CHGNet alone" if k == 1 else f"{LABELS[kind]}, k = {k}"
        style = {"color": "k", "lw": 2} if k == 1 else {
            "ls": "-" if kind == "fit" else "--" if kind == "fit_oh" else ":"}
        ax.loglog([r["dt_fs"] for r in mine], [r["std_eV"] for r in mine], marker="o",
                  ms=3, label=name, **style)
    target = require([r["std_eV"] for r in rows if r["k"] == 1 and r["dt_fs"] == 1.0],
                     source, "no run of CHGNet alone (k = 1) at 1 fs")[0]
    ax.axhline(target, color="0.5", lw=0.8)
    ax.text(0.52, target * 1.08, "CHGNet alone at 1 fs", fontsize=7, color="0.4")
    steps = sorted({r["dt_fs"] for r in rows})
    ax.set_xticks(steps, [f"{dt:g}" for dt in steps])
    ax.minorticks_off()
    ax.set_xlabel("outer step (fs): CHGNet is called once per outer step")
    ax.set_ylabel("std of the conserved energy (eV)")
    ax.set_title("8 rigid waters under CHGNet, NVE, 0.5 ps a point")
    ax.legend(fontsize=7)
    save(fig, path)
