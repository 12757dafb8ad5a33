"""How far is each step from dt → 0?

⟨U⟩/N against its dt → 0 limit, the reported T_tr and T_rot against the bath (and
``RigidLangevinBAOAB``'s end-of-step T_rot, dotted), and the configurational temperatures
where the runs carry them, for each code and integrator of the time-step table, from
``validation/timestep_table.json`` (``validation/timestep_table_report.py``); until the full
table is run, from the 216-water runs ``validation/timestep_table_216.json`` or the small
run ``validation/timestep_table_small.json``, whose titles say so.
"""

import json

from _common import ROOT, figure, save

STYLES = {("rigidmd", "langevin"): ("RigidLangevin", "o-"),
          ("rigidmd", "baoab"): ("RigidLangevinBAOAB", "s-"),
          ("rigidmd", "bussi"): ("RigidBussi", "^-"),
          ("rigidmd", "nosehoover"): ("RigidNoseHoover", "v-"),
          ("lammps", "nvt_small"): ("LAMMPS fix rigid/nvt/small", "D--"),
          ("openmm", "middle"): ("OpenMM LangevinMiddle", "x--")}


#: The tables drawn, the first found: (file, what the title adds).
SOURCES = (("timestep_table.json", ""),
           ("timestep_table_216.json", ": {runs} runs of 100 ps a point, not the full table"),
           ("timestep_table_small.json", ": the small run, not the table"))


def _data():
    for name, note in SOURCES:
        path = ROOT / "validation" / name
        if path.is_file():
            return json.loads(path.read_text()), note
    raise FileNotFoundError(f"none of {', '.join(n for n, _ in SOURCES)} in validation/")


def draw(path):
    data, note = _data()
    limits = {(f["model"], f["waters"], f["code"]): f["shared"]["a"]
              for f in data["fits"] if f["quantity"] == "U"}
    model = "tip4p2005"
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
