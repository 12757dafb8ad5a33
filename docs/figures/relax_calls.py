"""How many force calls does a rigid relaxation take against ASE's route?

Force calls to fmax 0.05 and 0.01 eV/Å of ``relax()`` and of ASE's ``BFGS`` with
``FixBondLengths``, per water system that both finished, from
``benchmarks/relax_compare.jsonl``.
"""

from _common import ROOT, figure, read_jsonl, require, save


def draw(path):
    source = ROOT / "benchmarks" / "relax_compare.jsonl"
    records = read_jsonl(source)
    require(all(isinstance(rec, dict) and {"system", "route", "rows"} <= rec.keys()
                for rec in records), source, "a record without system, route or rows")
    routes = {}
    for rec in records:  # the last record of a system and route counts
        routes[(rec["system"], rec["route"])] = rec
    systems = sorted({s for s, _ in routes}, key=lambda s: (s.rstrip("0123456789s"), s))
    require({"relax", "ASE"} <= {route for _, route in routes}, source,
            "no records of both routes (relax and ASE)")
    fig, axes = figure(ncols=2, height=3.4)
    for ax, fmax in zip(axes, ("0.05", "0.01"), strict=True):
        for kind, marker in (("cluster", "o"), ("box", "s")):
            x, y = [], []
            for system in systems:
                ours, ase = routes.get((system, "relax")), routes.get((system, "ASE"))
                if not (system.startswith(kind) and ours and ase):
                    continue
                a, b = ours["rows"].get(fmax), ase["rows"].get(fmax)
                if a and b and a["converged"] and b["converged"]:
                    x.append(b["calls"])
                    y.append(a["calls"])
            name = "clusters" if kind == "cluster" else "64-water boxes"
            ax.scatter(x, y, marker=marker, label=f"{name} ({len(x)})")
        top = 600
        ax.plot([0, top], [0, top], "k-", lw=1, label="as many")
        ax.plot([0, top], [0, top / 4], "k:", lw=1, label="4× fewer")
        ax.set_xlim(0, top)
        ax.set_ylim(0, top / 2)
        ax.set_xlabel("ASE's BFGS + FixBondLengths: force calls")
        ax.set_title(f"to fmax {fmax} eV/Å")
    axes[0].set_ylabel("relax(): force calls")
    axes[0].legend(fontsize=7)
    save(fig, path)
