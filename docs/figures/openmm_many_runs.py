"""Where do rigidmd's and OpenMM's potential energy and diffusion meet?

⟨U⟩ per molecule and D (periodic box) of TIP4P-Ew under Langevin dynamics against the time
step, rigidmd (``RigidLangevin``) and OpenMM (``LangevinMiddleIntegrator``), many runs each,
from ``validation/water_openmm_long.json``.
"""

from _common import ROOT, figure, read_json, require, save


def draw(path):
    source = ROOT / "validation" / "water_openmm_long.json"
    groups = read_json(source, "groups")["groups"]
    fig, (ax, bx) = figure(ncols=2, width=7.2, height=3.2)
    for code, thermo, label, style in (("rigidmd", "langevin", "rigidmd, RigidLangevin", "o-"),
                                       ("openmm", "middle", "OpenMM, Langevin middle", "s--")):
        sel = sorted((g for g in groups if g["model"] == "tip4pew" and g["code"] == code
                      and g["thermo"] == thermo), key=lambda g: g["dt_fs"])
        require(sel, source, f"no tip4pew groups of {code} {thermo}")
        dt = [g["dt_fs"] for g in sel]
        ax.errorbar(dt, [g["U"][0] for g in sel], yerr=[g["U"][1] for g in sel], fmt=style,
                    capsize=2, label=label)
        bx.errorbar(dt, [g["D_pbc"][0] for g in sel], yerr=[g["D_pbc"][1] for g in sel],
                    fmt=style, capsize=2, label=label)
    for axis in (ax, bx):
        axis.set_xlabel("time step (fs)")
        axis.set_xticks([0.5, 1, 2])
    ax.set_ylabel("⟨U⟩ per molecule (kJ/mol)")
    bx.set_ylabel("D, this box (1e-5 cm²/s)")
    ax.legend(fontsize=7)
    fig.suptitle("TIP4P-Ew, 298 K: the gaps close as the step shrinks")
    save(fig, path)
