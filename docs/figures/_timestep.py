"""The drawing of a time-step table (``validation/timestep_table_report.py``'s JSON), shared by
``timestep_table.py`` (the table, or its 216-water runs) and ``timestep_table_small.py`` (the
small run of the time-step page)."""

from _common import figure, require, save

STYLES = {("rigidmd", "langevin"): ("RigidLangevin", "o-"),
          ("rigidmd", "baoab"): ("RigidLangevinBAOAB", "s-"),
          ("rigidmd", "bussi"): ("RigidBussi", "^-"),
          ("rigidmd", "nosehoover"): ("RigidNoseHoover", "v-"),
          ("lammps", "nvt_small"): ("LAMMPS fix rigid/nvt/small", "D--"),
          ("openmm", "middle"): ("OpenMM LangevinMiddle", "x--")}


def draw_table(data, note, source, path):
    """Draw a time-step table's points (``data``, read from ``source``) into ``path``;
    ``note`` is added to the title (``{runs}``: the runs per point)."""
    model = "tip4p2005"
    require([p for p in data["points"] if p["model"] == model], source, "no TIP4P/2005 points")
    limits = {(f["model"], f["waters"], f["code"]): f["shared"]["a"]
              for f in data["fits"] if f["quantity"] == "U"}
    conf = any(p.get("T_conf_tr") for p in data["points"])
    fig, axes = figure(ncols=3 if conf else 2, width=10.2 if conf else 7.2, height=3.4)
    ax, bx = axes[0], axes[1]
    for (code, integrator), (label, style) in STYLES.items():
        sel = sorted((p for p in data["points"] if p["model"] == model and p["code"] == code
                      and p["integrator"] == integrator), key=lambda p: p["dt_fs"])
        if not sel:
            continue
        dt = [p["dt_fs"] for p in sel]
        limit = limits.get((model, sel[0]["waters"], code), float("nan"))
        ax.errorbar(dt, [p["U"][0] - limit for p in sel], yerr=[p["U"][1] for p in sel],
                    fmt=style, capsize=2, label=label)
        line = bx.errorbar(dt, [p["T_tr"][0] for p in sel], yerr=[p["T_tr"][1] for p in sel],
                           fmt=style, capsize=2, label=f"{label}, T_tr")
        bx.errorbar(dt, [p["T_rot"][0] for p in sel], yerr=[p["T_rot"][1] for p in sel],
                    fmt=style, capsize=2, mfc="none", color=line[0].get_color(),
                    label=f"{label}, T_rot")
        if integrator == "baoab":  # its end-of-step momenta, which it does not report
            bx.plot(dt, [p["T_rot_end"][0] for p in sel], ":", color=line[0].get_color(),
                    label=f"{label}, T_rot at the end of the step")
        measured = [p for p in sel if p.get("T_conf_tr")]
        if conf and measured:
            cx = axes[2]
            dt_c = [p["dt_fs"] for p in measured]
            cx.errorbar(dt_c, [p["T_conf_tr"][0] for p in measured],
                        yerr=[p["T_conf_tr"][1] for p in measured], fmt=style, capsize=2,
                        color=line[0].get_color(), label=f"{label}, translation")
            cx.errorbar(dt_c, [p["T_conf_rot"][0] for p in measured],
                        yerr=[p["T_conf_rot"][1] for p in measured], fmt=style, capsize=2,
                        mfc="none", color=line[0].get_color(), label=f"{label}, rotation")
    ax.axhline(0.0, color="0.5", lw=0.8)
    bx.axhline(298.0, color="0.5", lw=0.8)
    ax.set_ylabel("⟨U⟩/N − its dt → 0 limit (kJ/mol)")
    bx.set_ylabel("reported temperature (K)")
    if conf:
        axes[2].axhline(298.0, color="0.5", lw=0.8)
        axes[2].set_ylabel("configurational temperature (K)")
        axes[2].legend(fontsize=6)
    for axis in axes:
        axis.set_xlabel("time step (fs)")
    ax.legend(fontsize=7)
    bx.legend(fontsize=6)
    n = data["points"][0]["waters"] if data["points"] else 0
    counts = sorted({p["runs"] for p in data["points"] if p["model"] == model})
    runs = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    fig.suptitle(f"TIP4P/2005, {n} waters, 298 K{note.format(runs=runs)}")
    save(fig, path)
