"""What do the energy and the temperature of a rigid NVE run look like?

Potential, kinetic and total energy, and the temperature, of 32 rigid TIP3P waters in NVE
at 1, 2 and 4 fs from one 300 K start, from ``docs/figures/data/nve_trace.csv``
(``docs/figures/data/make_data.py nve``).
"""

from _common import DATA, figure, read_csv, save


def draw(path):
    rows = read_csv(DATA / "nve_trace.csv")
    fig, (ax, bx) = figure(ncols=2, width=7.2, height=3.2)
    two = [r for r in rows if r["dt_fs"] == 2.0]
    t = [r["time_ps"] for r in two]
    e0 = two[0]["etot_eV"]
    ax.plot(t, [r["epot_eV"] - e0 for r in two], label="potential")
    ax.plot(t, [r["ekin_eV"] for r in two], label="kinetic")
    ax.plot(t, [r["etot_eV"] - e0 for r in two], "k", label="total")
    ax.set_xlabel("time (ps)")
    ax.set_ylabel("energy − E_total(0) (eV)")
    ax.set_title("2 fs: energies")
    ax.legend(fontsize=7)
    for k, dt in enumerate((1.0, 2.0, 4.0)):
        sel = [r for r in rows if r["dt_fs"] == dt]
        bx.plot([r["time_ps"] for r in sel], [1e3 * (r["etot_eV"] - sel[0]["etot_eV"])
                                             for r in sel], color=f"C{k + 2}",
                label=f"{dt:g} fs")
    bx.set_xlabel("time (ps)")
    bx.set_ylabel("E_total − E_total(0) (meV)")
    bx.set_title("total energy at three steps")
    bx.legend(fontsize=7)
    fig.suptitle("32 rigid TIP3P waters (ASE's TIP3P), NVE from 300 K")
    save(fig, path)
