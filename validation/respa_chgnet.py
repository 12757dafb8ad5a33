r"""CHGNet on the slow level of r-RESPA: a rigid four-site model fitted to CHGNet as the fast one.

The distillation route of multiple time steps for a machine-learned potential: the fast
level is a cheap model fitted to the ML model's own forces on its own trajectory, the slow
level is the ML model less it (:class:`rigidmd.MultipleTimeStep` with ``full=``: one call of
each per outer step, the cheap model also every inner step).  Here:

1. **Trajectory.** 8 waters in CHGNet's own geometry (``benchmarks/ml_potential.py``'s
   ``start_state``: O–H 0.9767 Å, H–O–H 103.42°, rigid 300 K velocities), rigid NVE under
   CHGNet 0.3.0 (float32, as it ships) at 1 fs for ``--fit-ps``; a frame every 10 fs.
2. **Fit.** A rigid four-site water (:class:`FourSite`: Lennard-Jones O–O with σ, ε;
   charges ``q_H`` on H and ``-2 q_H`` on M = O + a (H1 − O) + a (H2 − O); every pair of
   molecules, no cut-off) fitted by least squares to CHGNet's net forces (eV/Å) and torques
   about the centres of mass (eV) of every water on the even frames; the odd frames test
   it.  The forces inside a molecule do not enter: a rigid body never feels them.  The
   same residual for TIP4P/2005's own parameters in this geometry (an unrelated model)
   says what the fit buys.
3. **NVE scan.** From the trajectory's last state, ``RigidVerlet`` for ``--ps`` at outer
   steps 1–6 fs and k = 1 (CHGNet alone), 2, 4, 8 with the fitted model as the fast
   level, and k = 4 with TIP4P/2005 as the fast level: the standard deviation of the
   conserved energy about a straight line, and CHGNet's calls per simulated ps.  The target
   is CHGNet alone at 1 fs (NO_SQUISH's error under this model at its usual step; CHGNet's
   own roughness sets a floor under every step, see the ML potential page); per k, the
   largest outer step of the grid that meets it and CHGNet's calls per ps there, against
   1000 for the single step at 1 fs and 2000 for flexible MD at 0.5 fs.

A short look at energy conservation, not sampling accuracy (⟨U⟩ and the RDF with error bars
need ns under CHGNet, ~10⁶ calls: CPU days here).  Needs CHGNet and a CPU PyTorch in their
own environment (not the test extra; see ``benchmarks/ml_potential.py``)::

    OMP_NUM_THREADS=1 venv-chgnet/bin/python validation/respa_chgnet.py   # 15-20 min, one core
    OMP_NUM_THREADS=1 venv-chgnet/bin/python validation/respa_chgnet.py --quick   # ~1 min

Writes ``respa_chgnet.json`` and ``.txt`` beside this script (``--out`` to change).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
import numpy as np  # noqa: E402
from arguments import positive  # noqa: E402
from ase import units  # noqa: E402
from ase.calculators.calculator import Calculator, all_changes  # noqa: E402

from rigidmd import MultipleTimeStep, RigidVerlet  # noqa: E402

KE = units.Hartree * units.Bohr  # Coulomb constant, eV Å / e²
#: TIP4P/2005 (Abascal & Vega 2005): q_H (e), σ (Å), ε (eV), d_OM (Å).
TIP4P2005 = (0.5564, 3.1589, 93.2 * units.kB, 0.1546)
DT_FS = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
KS = (1, 2, 4, 8)


class FourSite(Calculator):
    r"""A rigid four-site water model on a cluster of waters (atoms O, H, H per molecule).

    .. math::

        E = \sum_{i<j} \Big[4\varepsilon\big((\sigma/r_{O_iO_j})^{12}
            - (\sigma/r_{O_iO_j})^6\big)
            + k_e \sum_{a \in i,\, b \in j} \frac{q_a q_b}{r_{ab}}\Big] + E_0

    over pairs of molecules, with charges :math:`q_H` on each H and :math:`-2q_H` on
    M = O + a (H1 − O) + a (H2 − O) (the force on M goes to O, H1, H2 with weights
    1 − 2a, a, a: exact, M being linear in them).  No cut-off, no periodic images.

    Parameters
    ----------
    q_h : float
        e.
    sigma : float
        Å.
    epsilon : float
        eV.
    a : float
        M's fraction of the H–O bisector sum (dimensionless).
    e0 : float, default 0
        A constant, eV (the fitted model's energy shift).
    c12_oh, c6_oh : float, default 0
        eV Å¹², eV Å⁶: an optional term :math:`c_{12}/r^{12} - c_6/r^6` between each O and
        the H atoms of the other molecules (the richer fit's two extra parameters).
    """

    implemented_properties = ["energy", "forces"]

    def __init__(self, q_h, sigma, epsilon, a, e0=0.0, c12_oh=0.0, c6_oh=0.0):
        super().__init__()
        self.q_h, self.sigma, self.epsilon, self.a, self.e0 = q_h, sigma, epsilon, a, e0
        self.c12_oh, self.c6_oh = c12_oh, c6_oh

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        x = self.atoms.positions.reshape(-1, 3, 3)
        n = len(x)
        o, h1, h2 = x[:, 0], x[:, 1], x[:, 2]
        m = o + self.a * (h1 - o) + self.a * (h2 - o)
        sites = np.stack([h1, h2, m], axis=1)  # (n, 3, 3): the charged sites
        q = np.array([self.q_h, self.q_h, -2 * self.q_h])
        i, j = np.triu_indices(n, 1)
        # Coulomb between the charged sites of molecules i < j
        d = sites[i][:, :, None, :] - sites[j][:, None, :, :]  # (pairs, 3, 3, 3)
        r = np.linalg.norm(d, axis=-1)
        qq = KE * q[:, None] * q[None, :]
        energy = float(np.sum(qq / r))
        f = (qq / r**3)[..., None] * d  # force on i's site a from j's site b
        fsite = np.zeros((n, 3, 3))
        np.add.at(fsite, i, f.sum(axis=2))
        np.add.at(fsite, j, -f.sum(axis=1))
        # Lennard-Jones between oxygens
        doo = o[i] - o[j]
        roo = np.linalg.norm(doo, axis=-1)
        sr6 = (self.sigma / roo) ** 6
        energy += float(np.sum(4 * self.epsilon * (sr6**2 - sr6)))
        flj = (24 * self.epsilon * (2 * sr6**2 - sr6) / roo**2)[:, None] * doo
        forces = np.zeros((n, 3, 3))
        np.add.at(forces[:, 0], i, flj)
        np.add.at(forces[:, 0], j, -flj)
        if self.c12_oh or self.c6_oh:  # O of one molecule, H of the other, both ways
            for first, second in ((i, j), (j, i)):
                d = o[first][:, None, :] - x[second][:, 1:, :]  # (pairs, 2, 3)
                r2 = np.sum(d * d, axis=-1)
                energy += float(np.sum(self.c12_oh / r2**6 - self.c6_oh / r2**3))
                f = ((12 * self.c12_oh / r2**7 - 6 * self.c6_oh / r2**4)[..., None] * d)
                np.add.at(forces[:, 0], first, f.sum(axis=1))
                np.add.at(forces[:, 1:], second, -f)
        forces[:, 1] += fsite[:, 0]
        forces[:, 2] += fsite[:, 1]
        forces[:, 0] += (1 - 2 * self.a) * fsite[:, 2]
        forces[:, 1] += self.a * fsite[:, 2]
        forces[:, 2] += self.a * fsite[:, 2]
        self.results = {"energy": energy + self.e0, "forces": forces.reshape(-1, 3)}


def tip4p2005_here(geometry):
    """TIP4P/2005's parameters in this geometry (its d_OM as the fraction a)."""
    q_h, sigma, epsilon, d_om = TIP4P2005
    oh, angle = geometry
    return q_h, sigma, epsilon, d_om / (2 * oh * np.cos(np.radians(angle) / 2))


def generalized(atoms, calc):
    """Net forces (eV/Å) and torques about the centres of mass (eV) of every water (atoms O,
    H, H) under ``calc``: the forces first, then the torques, flattened."""
    atoms = atoms.copy()
    atoms.calc = calc
    x = atoms.positions.reshape(-1, 3, 3)
    f = atoms.get_forces().reshape(-1, 3, 3)
    m = atoms.get_masses().reshape(-1, 3, 1)
    centre = (m * x).sum(axis=1, keepdims=True) / m.sum(axis=1, keepdims=True)
    return np.concatenate([f.sum(axis=1).ravel(), np.cross(x - centre, f).sum(axis=1).ravel()])


def four_site(params):
    """:class:`FourSite` from ``(q_h, sigma, epsilon, a)`` or, with the O–H terms,
    ``(q_h, sigma, epsilon, a, c12_oh, c6_oh)`` (no energy constant)."""
    return FourSite(*params[:4], 0.0, *params[4:])


def fit(frames, targets, start):
    """Least-squares fit from ``start`` (4 parameters, or 6 with the O–H terms: see
    :func:`four_site`); returns them and the RMS residual."""
    def residual(v):
        calc = four_site(v)
        return np.concatenate([generalized(a, calc) for a in frames]) - np.concatenate(targets)

    from scipy.optimize import least_squares

    scale, low, high = [0.05, 0.1, 0.002, 0.02], [0.2, 2.5, 1e-4, 0.0], [1.0, 4.0, 0.05, 0.4]
    if len(start) == 6:
        scale, low, high = scale + [100.0, 1.0], low + [0.0, -50.0], high + [1e4, 50.0]
    result = least_squares(residual, np.asarray(start, dtype=float), x_scale=scale,
                           bounds=(low, high))
    return tuple(result.x), float(np.sqrt(np.mean(result.fun**2)))


def residual_rms(frames, targets, params):
    calc = four_site(params)
    diff = np.concatenate([generalized(a, calc) for a in frames]) - np.concatenate(targets)
    return float(np.sqrt(np.mean(diff**2)))


def trajectory(start, model, ps, every_fs=10.0):
    """Rigid NVE under CHGNet at 1 fs; frames (copies) and the state at the end."""
    from ml_potential import CHGNetCluster

    atoms = start.copy()
    atoms.calc = CHGNetCluster(model)
    dyn = RigidVerlet(atoms, 1.0 * units.fs)
    frames = []
    dyn.attach(lambda: frames.append(atoms.copy()), interval=int(every_fs))
    dyn.run(int(round(ps * 1000)))
    return frames, dyn.atoms.copy()


def frequencies(start, model, fast, steps=200):
    """The characteristic frequency (cm⁻¹, ``force_frequency``) of the waters' net forces and
    torques along ``steps`` rigid NVE steps of 1 fs under CHGNet: CHGNet's, ``fast``'s on
    the same configurations, and their difference (the slow level's)."""
    from ml_potential import CHGNetCluster, force_frequency

    atoms = start.copy()
    atoms.calc = CHGNetCluster(model)
    dyn = RigidVerlet(atoms, 1.0 * units.fs)
    series = {"chgnet": [], "fast": [], "slow": []}
    for _ in dyn.irun(steps):
        g_ml = generalized(atoms, atoms.calc)  # the step's own CHGNet results, no new call
        g_fast = generalized(atoms, fast)
        for key, g in (("chgnet", g_ml), ("fast", g_fast), ("slow", g_ml - g_fast)):
            series[key].append(g)
    out = {}
    for key, g in series.items():
        g = np.asarray(g)
        half = g.shape[1] // 2  # forces first, then torques
        out[key] = {"nu_force_cm": force_frequency(g[:, :half], 1.0),
                    "nu_torque_cm": force_frequency(g[:, half:], 1.0),
                    "rms_force": float(np.sqrt(np.mean(g[:, :half] ** 2))),
                    "rms_torque": float(np.sqrt(np.mean(g[:, half:] ** 2)))}
    return out


def nve(start, model, fast, k, dt_fs, ps):
    """One NVE run; the conserved energy's std about a line (eV), CHGNet calls per ps."""
    from ml_potential import CHGNetCluster, counted

    atoms = start.copy()
    chgnet = counted(CHGNetCluster(model))
    atoms.calc = chgnet if k == 1 else MultipleTimeStep(fast, full=chgnet, substeps=k)
    dyn = RigidVerlet(atoms, dt_fs * units.fs)
    steps = max(int(round(ps * 1000 / dt_fs)), 2)
    energies = [dyn.get_conserved_energy()]
    begin = chgnet.calls
    for _ in dyn.irun(steps):
        energies.append(dyn.get_conserved_energy())
    energies = np.asarray(energies[1:])
    if not np.all(np.isfinite(energies)):
        return float("inf"), (chgnet.calls - begin) / ps
    t = np.arange(len(energies)) * dt_fs
    line = np.polyval(np.polyfit(t, energies, 1), t)
    return float(np.std(energies - line)), (chgnet.calls - begin) / (steps * dt_fs / 1000)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit-ps", type=float, default=1.0, help="CHGNet trajectory for the fit")
    ap.add_argument("--ps", type=positive, default=0.5, help="each NVE run, ps")
    ap.add_argument("--quick", action="store_true", help="a short look: k = 1, 4; 1, 4 fs")
    ap.add_argument("--out", type=Path, default=HERE / "respa_chgnet")
    args = ap.parse_args(argv)
    from ml_potential import CHGNetCluster, load_chgnet, start_state, warm_up

    dts, ks = (DT_FS, KS) if not args.quick else ((1.0, 4.0), (1, 4))
    if args.quick:
        args.fit_ps, args.ps = min(args.fit_ps, 0.06), min(args.ps, 0.02)
    t0 = time.perf_counter()
    model = load_chgnet("float32")
    start, template = start_state(8)
    warm_up(start)
    tp = template.positions  # O, H, H
    oh = float(np.linalg.norm(tp[1] - tp[0]))
    hoh = float(np.degrees(np.arccos(np.dot(tp[1] - tp[0], tp[2] - tp[0])
                                     / oh / np.linalg.norm(tp[2] - tp[0]))))
    frames, end = trajectory(start, model, args.fit_ps)
    targets = [generalized(a, CHGNetCluster(model)) for a in frames]
    train, test = frames[::2], frames[1::2]
    t_train, t_test = targets[::2], targets[1::2]
    unrelated = tip4p2005_here((oh, hoh))
    params, train_rms = fit(train, t_train, unrelated)
    # The richer fit: the four-site model's parameters and an O–H term, from no O–H term
    params_oh, train_rms_oh = fit(train, t_train, (*params, 0.0, 0.0))
    # The constant: the fitted model's mean energy offset from CHGNet's on the frames
    e_chg = [CHGNetCluster(model).get_potential_energy(a) for a in frames]
    e_fit = [four_site(params).get_potential_energy(a) for a in frames]
    e0 = float(np.mean(np.subtract(e_chg, e_fit)))
    fitted = (*params, e0)
    e0_oh = float(np.mean(np.subtract(e_chg, [four_site(params_oh).get_potential_energy(a)
                                              for a in frames])))
    fitted_oh = (*params_oh[:4], e0_oh, *params_oh[4:])
    scale = float(np.sqrt(np.mean(np.concatenate(t_test) ** 2)))
    rows = {"geometry": {"OH_A": oh, "HOH_deg": hoh},
            "fit": {"frames_train": len(train), "frames_test": len(test),
                    "q_h": params[0], "sigma_A": params[1], "epsilon_eV": params[2],
                    "a": params[3], "e0_eV": e0, "rms_train": train_rms,
                    "rms_test": residual_rms(test, t_test, params),
                    "rms_test_tip4p2005": residual_rms(test, t_test, unrelated),
                    "rms_chgnet": scale,
                    "energy_rms_eV": float(np.std(np.subtract(e_chg, e_fit)))},
            "fit_oh": {"q_h": params_oh[0], "sigma_A": params_oh[1],
                       "epsilon_eV": params_oh[2], "a": params_oh[3], "e0_eV": e0_oh,
                       "c12_oh": params_oh[4], "c6_oh": params_oh[5],
                       "rms_train": train_rms_oh,
                       "rms_test": residual_rms(test, t_test, params_oh)},
            "nve": []}
    steps = 50 if args.quick else 200
    rows["frequencies"] = frequencies(end, model, FourSite(*fitted), steps=steps)
    rows["frequencies_oh"] = frequencies(end, model, FourSite(*fitted_oh), steps=steps)
    fasts = {"fit": fitted, "fit_oh": fitted_oh, "tip4p2005": unrelated}
    runs = [(k, dt, "fit") for k in ks for dt in dts]
    runs += [(4, dt, kind) for kind in ("fit_oh", "tip4p2005") for dt in dts if 4 in ks]
    for k, dt, kind in runs:
        fast = FourSite(*fasts[kind])
        std, calls = nve(end, model, fast, k, dt, args.ps)
        rows["nve"].append({"k": k, "dt_fs": dt, "fast": kind, "std_eV": std,
                            "chgnet_calls_per_ps": calls})
        print(f"k = {k}  dt = {dt:g} fs  fast = {kind:9s}  std(E_cons) = {std:.3e} eV  "
              f"CHGNet calls/ps = {calls:.0f}", flush=True)
    rows["wall_s"] = time.perf_counter() - t0
    rows["ps"] = args.ps
    rows["fit_ps"] = args.fit_ps
    args.out.with_suffix(".json").write_text(json.dumps(rows, indent=1) + "\n")
    # (``report`` reads only the JSON's rows: the text can be made again from the JSON)
    args.out.with_suffix(".txt").write_text(report(rows))
    print(report(rows), end="")
    return 0


def label(kind, k):
    """A fast level's name in the report."""
    if k == 1:
        return "none (CHGNet alone)"
    return {"fit": "fitted", "fit_oh": "fitted, with O–H terms", "tip4p2005": "TIP4P/2005"}[kind]


def report(rows):
    f, g = rows["fit"], rows["fit_oh"]
    lines = [
        "CHGNet on the slow level of r-RESPA, a fitted rigid four-site model on the fast one; "
        "8 waters (a cluster), rigid NVE.", "",
        f"Fit on {f['frames_train']} frames, tested on {f['frames_test']} others (net forces "
        "and torques of every water; eV/Å and eV):", "",
        "| model | q_H (e) | σ (Å) | ε (meV) | a | RMS residual, test | CHGNet's RMS |",
        "|---|---|---|---|---|---|---|",
        f"| fitted | {f['q_h']:.4f} | {f['sigma_A']:.4f} | {1000 * f['epsilon_eV']:.3f} | "
        f"{f['a']:.4f} | {f['rms_test']:.4f} | {f['rms_chgnet']:.4f} |",
        f"| fitted, with O–H terms | {g['q_h']:.4f} | {g['sigma_A']:.4f} | "
        f"{1000 * g['epsilon_eV']:.3f} | {g['a']:.4f} | {g['rms_test']:.4f} | "
        f"{f['rms_chgnet']:.4f} |",
        f"| TIP4P/2005 (unrelated) | {TIP4P2005[0]} | {TIP4P2005[1]} | "
        f"{1000 * TIP4P2005[2]:.3f} | - | {f['rms_test_tip4p2005']:.4f} | "
        f"{f['rms_chgnet']:.4f} |", "",
        f"The O–H terms between each O and the other molecules' H: c₁₂ = {g['c12_oh']:.4g} "
        f"eV Å¹², c₆ = {g['c6_oh']:.4g} eV Å⁶.", "",
        f"Energy: the fitted model's offset from CHGNet's scatters by {f['energy_rms_eV']:.4f} eV "
        "over the frames.", "",
        "How slow is each level? The characteristic frequency of the waters' net forces and "
        "torques (√(⟨|Ġ|²⟩/⟨|G − Ḡ|²⟩)/2πc) along 1 fs steps under CHGNet, and their RMS:", "",
        "| forces | ν(net force) (cm⁻¹) | ν(torque) (cm⁻¹) | RMS net force (eV/Å) | "
        "RMS torque (eV) |", "|---|---|---|---|---|",
        *[f"| {name} | {q['nu_force_cm']:.0f} | {q['nu_torque_cm']:.0f} | "
          f"{q['rms_force']:.4f} | {q['rms_torque']:.4f} |"
          for name, q in (("CHGNet", rows["frequencies"]["chgnet"]),
                          ("fitted (fast level)", rows["frequencies"]["fast"]),
                          ("CHGNet − fitted (slow level)", rows["frequencies"]["slow"]),
                          ("fitted, with O–H terms", rows["frequencies_oh"]["fast"]),
                          ("CHGNet − fitted with O–H terms",
                           rows["frequencies_oh"]["slow"]))], "",
        f"NVE over {rows['ps']:g} ps from the trajectory's end: the conserved energy's std "
        "about a line (eV) and CHGNet's calls per ps:", "",
        "| fast level | k | " + " | ".join(f"{dt:g} fs" for dt in sorted({r['dt_fs'] for r in
                                                                         rows['nve']})) + " |"]
    dts = sorted({r["dt_fs"] for r in rows["nve"]})
    lines.append("|---|---|" + "---|" * len(dts))
    order = {"fit": 0, "fit_oh": 1, "tip4p2005": 2}
    groups = sorted({(r["fast"], r["k"]) for r in rows["nve"]},
                    key=lambda group: (order[group[0]], group[1]))
    for kind, k in groups:
        cells = []
        for dt in dts:
            r = next((r for r in rows["nve"] if (r["fast"], r["k"], r["dt_fs"]) ==
                      (kind, k, dt)), None)
            cells.append("" if r is None else f"{r['std_eV']:.2e} ({r['chgnet_calls_per_ps']:.0f})")
        name = label(kind, k)
        lines.append(f"| {name} | {k} | " + " | ".join(cells) + " |")
    target = next((r["std_eV"] for r in rows["nve"] if r["k"] == 1 and r["dt_fs"] == 1.0), None)
    if target is not None:
        lines += ["", f"Target: CHGNet alone at 1 fs, {target:.2e} eV (1000 CHGNet calls per "
                  "ps; flexible MD at 0.5 fs: 2000)."]
        for kind, k in groups:
            ok = [r for r in rows["nve"] if (r["fast"], r["k"]) == (kind, k)
                  and r["std_eV"] <= target]
            if ok:
                best = max(ok, key=lambda r: r["dt_fs"])
                calls = best["chgnet_calls_per_ps"]
                lines.append(f"- {label(kind, k)}, k = {k}: largest outer step meeting it "
                             f"{best['dt_fs']:g} fs, {calls:.0f} CHGNet calls per ps (the "
                             f"single step at 1 fs makes {1000 / calls:.1f}× as many, "
                             f"flexible MD at 0.5 fs {2000 / calls:.1f}×)")
            else:
                lines.append(f"- {label(kind, k)}, k = {k}: no outer step of the grid meets it")
    lines.append(f"\nWall time {rows['wall_s'] / 60:.1f} min.")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
