"""What does a rigid step buy under tight binding?

Energy spread of 2 ps of NVE against force calls per ps, rigid (``RigidVerlet``) and
flexible (ASE's ``VelocityVerlet``), 8 waters under GFN2-xTB, from
``benchmarks/tight_binding.txt``.
"""

from _common import ROOT, figure, markdown_rows, number, read_text, require, save


def draw(path):
    source = ROOT / "benchmarks" / "tight_binding.txt"
    rows = [r for r in markdown_rows(read_text(source)) if r[0] in ("rigid", "flexible")]
    fig, ax = figure(width=5.2, height=3.4)
    for route, marker in (("rigid", "o"), ("flexible", "s")):
        sel = require([r for r in rows if r[0] == route and len(r) >= 5], source,
                      f"no table rows '| {route} | dt | ... | calls per ps |'")
        calls = [number(r[4]) for r in sel]
        spread = [number(r[3]) for r in sel]
        ax.plot(calls, spread, marker + "-", label=route)
        for r, x, y in zip(sel, calls, spread, strict=True):
            ax.annotate(f"{r[1]} fs", (x, y), textcoords="offset points", xytext=(5, 4),
                        fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks([250, 500, 1000, 2000, 4000], ["250", "500", "1000", "2000", "4000"])
    ax.set_xticks([], minor=True)
    ax.set_yticks([3e-3, 1e-2, 2e-2], ["0.003", "0.01", "0.02"])
    ax.set_yticks([], minor=True)
    ax.set_xlabel("force calls per ps")
    ax.set_ylabel("total-energy spread (eV)")
    ax.set_title("8 waters, GFN2-xTB, 300 K: rigid against flexible")
    ax.legend()
    save(fig, path)
