"""What do the energies of a rigid NVE run look like?

Potential, kinetic and total energy of 32 rigid TIP3P waters in NVE at 2 fs, each as its
change since t = 0 (the potential and kinetic energies trade, the total stays flat), and the
total at 1, 2 and 4 fs, all from one 300 K start, from ``docs/figures/data/nve_trace.csv``
(``docs/figures/data/make_data.py nve``).
"""

from _common import DATA, figure, read_csv, require, save


def draw(path):
    source = DATA / "nve_trace.csv"
    rows = read_csv(source, "dt_fs", "time_ps", "epot_eV", "ekin_eV", "etot_eV")
    steps = {dt: require([r for r in rows if r["dt_fs"] == dt], source, f"no rows at {dt:g} fs")
             for dt in (1.0, 2.0, 4.0)}
    fig, (ax, bx) = figure(ncols=2, width=7.2, height=3.2)
    two = steps[2.0]
    t = [r["time_ps"] for r in two]
    for column, label, style in (("epot_eV", "potential", "-"), ("ekin_eV", "kinetic", "-"),
                                 ("etot_eV", "total", "k-")):  # each from its own start
        ax.plot(t, [r[column] - two[0][column] for r in two], style, label=label)
    ax.set_xlabel("time (ps)")
    ax.set_ylabel("change since t = 0 (eV)")
    ax.set_title("2 fs: energies")
    ax.legend(fontsize=7)
    for k, (dt, sel) in enumerate(steps.items()):
        bx.plot([r["time_ps"] for r in sel], [1e3 * (r["etot_eV"] - sel[0]["etot_eV"])
                                             for r in sel], color=f"C{k + 2}",
                label=f"{dt:g} fs")
    bx.set_xlabel("time (ps)")
    bx.set_ylabel("E_total − E_total(0) (meV)")
    bx.set_title("total energy at three steps")
    bx.legend(fontsize=7)
    fig.suptitle("32 rigid TIP3P waters (ASE's TIP3P), NVE from 300 K")
    save(fig, path)
