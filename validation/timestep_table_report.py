r"""The time-step table from ``timestep_table.py``'s runs: each point against its dt → 0 limit.

Reads the run JSONs, pools the seeds of each point (model, waters, code, integrator, step:
the mean of the runs' means, its standard error over runs, or the one run's block error),
and fits :math:`a + b\,\delta t^2` over the steps up to ``--fit-max-fs`` (2 fs) per model
and quantity (⟨U⟩/N, the RDF's first peak position and height, D_PBC), weighted by the
points' errors:

- rigidmd: one limit :math:`a` shared by all its integrators, each with its own :math:`b`;
  each integrator is also fitted alone, and the table says whether those limits agree with
  the shared one (within ``--agree-sigma`` combined standard errors);
- LAMMPS and OpenMM: each its own limit (their long-range and dispersion treatments differ).

Writes ``<name>.md`` (the table, Markdown), ``<name>.json`` (points and fits) and
``<name>.csv`` (the points with their distance from the limit, for the docs' figure) into
``--outdir``.  T_tr and T_rot are as each code reports them (rigidmd's BAOAB: after its O
step; its end-of-step values are in the JSON and the CSV); T_conf shows "—" for runs that
carry none (LAMMPS, OpenMM, and rigidmd runs made with ``--tconf-frames 0``).

Run::

    python validation/timestep_table_report.py validation/timestep_runs/*.json \
        --name timestep_table
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (arguments.py, beside this script)
from arguments import positive  # noqa: E402

#: The quantities fitted against dt²; the temperatures are compared with the bath instead.
FITTED = ("U", "rdf_peak_r", "rdf_peak_g", "D_pbc")
#: Those of the configurations alone, the same under any thermostat (D_PBC is not: it
#: depends on the thermostat's friction), which a code may take from another's limit.
STATIC = ("U", "rdf_peak_r", "rdf_peak_g")
POOLED = ("U", "T_tr", "T_rot", "T_tr_end", "T_rot_end", "T_tr_gap", "T_rot_gap",
          "rdf_peak_r", "rdf_peak_g", "D_pbc", "T_conf_tr", "T_conf_rot")


def _value(entry):
    """(value, error) of a run's field: ``[mean, err]`` or a bare number; None stays None."""
    if entry is None:
        return None
    if isinstance(entry, list | tuple):
        return float(entry[0]), float(entry[1]) if entry[1] is not None else float("nan")
    return float(entry), float("nan")


def pool(runs, key):
    r"""[mean, standard error] of ``key`` over ``runs``; None when no run has it.

    One run: its own (block) error.  Several: the larger of the runs' scatter
    (:math:`s/\sqrt n`) and what their own errors give the mean
    (:math:`\sqrt{\sum_i \sigma_i^2}/n`, where every run has one).  The scatter of three
    runs estimates the error with two degrees of freedom: a tenth of the time it falls
    below a third of the true error (:math:`P(\chi^2_2/2 < 0.1) = 0.095`), and such a
    point then outweighs the rest of a fit and its verdicts (found in the 216-water table:
    two runs of Bussi at 1 fs agreeing to 0.02 kJ/mol in ⟨U⟩/N, each ± 0.07 and ± 0.12,
    pulled rigidmd's shared limit by 0.08).  Block errors can fall short too, so neither
    alone.
    """
    values = [_value(r.get(key)) for r in runs]
    values = [v for v in values if v is not None and np.isfinite(v[0])]
    if not values:
        return None
    x = np.array([v[0] for v in values])
    if len(x) == 1:
        return [float(x[0]), values[0][1]]
    error = x.std(ddof=1) / np.sqrt(len(x))
    own = np.array([v[1] for v in values])
    if np.isfinite(own).all():
        error = max(error, float(np.sqrt(np.sum(own ** 2))) / len(x))
    return [float(x.mean()), float(error)]


def _mean_of(runs, key):
    """The mean of a number the runs carry, over those that carry it (None when none)."""
    values = [float(r[key]) for r in runs if isinstance(r.get(key), int | float)]
    return float(np.mean(values)) if values else None


def read_runs(paths):
    """``(path, run)`` of each run: a run's JSON, or a bundle of them (a list, as
    ``--bundle`` writes), in the order given."""
    for path in paths:
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError) as err:
            raise SystemExit(f"{path}: not a readable run or bundle ({err})") from None
        for run in data if isinstance(data, list) else [data]:
            if not isinstance(run, dict) or not isinstance(run.get("point"), dict):
                raise SystemExit(f"{path}: holds something that is not a table run (no "
                                 "point)")
            lacks = [k for k in POINT_KEYS if k not in run["point"]]
            if lacks:  # (an NPT run of npt_density.py has a point, without model or code)
                raise SystemExit(f"{path}: holds something that is not a table run (its "
                                 f"point has no {', '.join(lacks)})")
            yield path, run


#: What a table run's point names (its point's key in :func:`load_points`, and its seed).
POINT_KEYS = ("model", "waters", "code", "integrator", "dt_fs", "seed")


#: What the runs pooled into one point must share beyond the point's key (a run of other
#: length, equilibration, sampling or thermostat time, or D_PBC fitted over another window of
#: lags, is another measurement).  A field no run of the point holds (older runs) is alike.
SAME_IN_A_POINT = ("ps", "equil_ps", "sample_fs", "frame_fs", "tau_ps", "blocks",
                   "msd_fit_ps")
#: What a code's runs must share too: LAMMPS's pieces (each restarts its Nosé–Hoover chain
#: from rest; other codes' runs carry the option unused).
SAME_IN_A_POINT_OF = {"lammps": ("piece_ps",)}


def load_points(paths, include_incomplete=False):
    """Pooled points, one per (model, waters, code, integrator, dt); a run that was stopped
    before its length (``"complete": false``) is left out unless ``include_incomplete``."""
    groups, seen = {}, {}
    for path, run in read_runs(paths):
        p = run["point"]
        which = tuple(p.get(k) for k in ("model", "waters", "code", "integrator", "dt_fs",
                                         "seed", "substeps", "r_split"))
        if which in seen:  # a file given twice, or a bundle with its own inputs
            raise SystemExit(f"{path}: the run {run.get('name', which)} is also in "
                             f"{seen[which]}; give each run once (a bundle, and new runs "
                             "not in it)")
        seen[which] = path
        if not run.get("complete") and not include_incomplete:
            print(f"{Path(path).name}: stopped at {run.get('ps', 0):g} ps, left out "
                  f"(--include-incomplete takes it)")
            continue
        p = run["point"]
        integrator = p["integrator"] + (  # an r-RESPA split is a point of its own
            f" k={p['substeps']} r={p['r_split']:g}" if p.get("substeps", 1) > 1 else "")
        key = (p["model"], int(p["waters"]), p["code"], integrator, float(p["dt_fs"]))
        groups.setdefault(key, []).append(run)
    points = []
    for key in sorted(groups):
        runs = groups[key]
        for field in SAME_IN_A_POINT + SAME_IN_A_POINT_OF.get(key[2], ()):
            values = {json.dumps(r["point"].get(field)) for r in runs}
            if len(values) > 1:
                raise SystemExit(f"{' '.join(map(str, key))} fs: its runs differ in {field} "
                                 f"({', '.join(sorted(values))}); pool only runs made alike")
        row = dict(zip(("model", "waters", "code", "integrator", "dt_fs"), key, strict=True))
        first = runs[0]["point"]  # the split's levels as fields, not only in its name
        substeps = int(first.get("substeps", 1))
        row.update(scheme=first["integrator"], substeps=substeps,
                   r_split=float(first["r_split"]) if substeps > 1 else None)
        row.update(runs=len(runs), seeds=sorted(r["point"]["seed"] for r in runs),
                   ps=float(sum(r.get("recorded_ps", 0.0) for r in runs)),
                   complete=all(r.get("complete") for r in runs),
                   ms_per_step=_mean_of(runs, "ms_per_step"))
        row.update({k: pool(runs, k) for k in POOLED})
        # How many runs each quantity pools (T_conf: only the runs that sampled it, fewer
        # than the point's runs where earlier runs did not), for the tables and the plan.
        row["runs_of"] = {k: sum(1 for r in runs if (v := _value(r.get(k))) is not None
                                 and np.isfinite(v[0])) for k in POOLED}
        points.append(row)
    return points


def fit_limit(dt, y, err, groups):
    r"""Weighted least squares of :math:`y = a + b_g\,\delta t^2` (one :math:`b` per group).

    Parameters
    ----------
    dt, y, err : array_like, shape (n,)
        Steps (fs), values and their standard errors (non-finite: weight of the mean error;
        when none is finite, equal weights and ``a_err`` from the scatter about the fit, nan
        with no degree of freedom left).
    groups : sequence, shape (n,)
        The group of each point; each group gets its own slope.

    Returns
    -------
    dict
        ``a`` and ``a_err`` (the limit and its standard error), ``b`` (per group, per fs²),
        ``chi2`` and ``dof``; ``a`` is nan when the points cannot determine it.
    """
    dt, y, err = (np.asarray(v, dtype=float) for v in (dt, y, err))
    names = sorted(set(groups))
    ok = np.isfinite(err) & (err > 0)
    sigma = np.where(ok, err, err[ok].mean() if ok.any() else 1.0)
    A = np.zeros((len(y), 1 + len(names)))
    A[:, 0] = 1.0
    for i, g in enumerate(groups):
        A[i, 1 + names.index(g)] = dt[i] ** 2
    if len(y) < A.shape[1] or np.linalg.matrix_rank(A) < A.shape[1]:
        return {"a": float("nan"), "a_err": float("nan"), "b": {}, "chi2": float("nan"),
                "dof": 0, "points": len(y)}
    w = 1.0 / sigma
    coef, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
    cov = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
    resid = (y - A @ coef) * w
    dof = len(y) - A.shape[1]
    if not ok.any():  # no point has an error (single runs): the scatter's, if it has one
        cov = cov * (resid @ resid / dof) if dof > 0 else np.full_like(cov, np.nan)
    return {"a": float(coef[0]), "a_err": float(np.sqrt(cov[0, 0])),
            "b": {g: float(coef[1 + i]) for i, g in enumerate(names)},
            "chi2": float(resid @ resid), "dof": int(dof), "points": len(y)}


#: rigidmd's thermostats by what they do to diffusion, for D_PBC's limit: a Langevin friction
#: (1/ps here) slows it; a global thermostat (Bussi, Nosé–Hoover chains; τ = 1 ps) leaves it
#: close to NVE's.  Measured at 216 waters (dt → 0): 1.88 ± 0.03 against 1.78 ± 0.02
#: (1e-5 cm²/s), and at 4 fs Bussi's and Nosé–Hoover's 2.20 and 2.24.
DIFFUSION_KIND = {"langevin": "friction", "baoab": "friction", "bussi": "global",
                  "nosehoover": "global"}


def family(point, key="U"):
    """The set of runs that share a limit of ``key``: rigidmd's integrators together, each
    other code alone; for a quantity that depends on the thermostat (not :data:`STATIC`:
    D_PBC), rigidmd's by :data:`DIFFUSION_KIND` (code ``"rigidmd:friction"`` or
    ``"rigidmd:global"``)."""
    code = point["code"]
    if key not in STATIC and code == "rigidmd":
        scheme = point.get("scheme", point["integrator"]).split()[0]
        code = f"rigidmd:{DIFFUSION_KIND[scheme]}"
    return (point["model"], point["waters"], code)


def fits(points, fit_max_fs, agree_sigma, borrow=None):
    """Per family and fitted quantity: the shared fit, each integrator's own, and whether
    they agree.

    ``borrow`` (``{code: other code}``): a family whose own points cannot determine its
    limit (fewer than two steps at or below ``fit_max_fs``) takes the other code's limit of
    the same model and size, marked ``"borrowed_from"``, for the static quantities only
    (:data:`STATIC`; D_PBC depends on the thermostat); meant for LAMMPS's own integrator
    against rigidmd's, which use the same LAMMPS forces, never for OpenMM (its long-range
    and dispersion treatments differ)."""
    out = {}
    for key in FITTED:
        for fam in sorted({family(p, key) for p in points}):
            use = [p for p in points if family(p, key) == fam and
                   p["dt_fs"] <= fit_max_fs + 1e-9 and p[key] is not None]
            shared = fit_limit([p["dt_fs"] for p in use], [p[key][0] for p in use],
                               [p[key][1] for p in use], [p["integrator"] for p in use])
            alone, agree, compared = {}, True, 0
            for integ in sorted({p["integrator"] for p in use}):
                mine = [p for p in use if p["integrator"] == integ]
                f = fit_limit([p["dt_fs"] for p in mine], [p[key][0] for p in mine],
                              [p[key][1] for p in mine], [integ] * len(mine))
                alone[integ] = f
                if np.isfinite(f["a"]) and np.isfinite(shared["a"]):
                    gap = abs(f["a"] - shared["a"])
                    agree &= bool(gap <= agree_sigma * np.hypot(f["a_err"], shared["a_err"]))
                    compared += 1
            out[(*fam, key)] = {"shared": shared, "alone": alone,
                                "agree": agree if compared > 1 else None}
    for (model, waters, code, key), f in list(out.items()):
        if key not in STATIC:
            continue  # a dynamical quantity depends on the thermostat: never another's limit
        donor = out.get((model, waters, (borrow or {}).get(code), key))
        if not np.isfinite(f["shared"]["a"]) and donor is not None and \
                np.isfinite(donor["shared"]["a"]):
            out[(model, waters, code, key)] = dict(
                f, shared=dict(donor["shared"], b={}), borrowed_from=borrow[code])
    return out


def _pm(v, digits):
    if v is None:
        return "—"
    if not np.isfinite(v[1]):
        return f"{v[0]:.{digits}f}"
    return f"{v[0]:.{digits}f} ± {v[1]:.{digits}f}"


def _gap_pm(v):
    """A reported − end-of-step gap: "—" where the integrator reports its end of step
    (exactly zero: the NO_SQUISH thermostats), else as :func:`_pm`."""
    if v is not None and v[0] == 0 and (v[1] == 0 or not np.isfinite(v[1])):
        return "—"
    return _pm(v, 2)


def _gap(point, key, fit_table, digits):
    f = fit_table.get((*family(point, key), key))
    if f is None or point[key] is None or not np.isfinite(f["shared"]["a"]):
        return "—"
    return f"{point[key][0] - f['shared']['a']:+.{digits}f}"


def table(points, fit_table, fit_max_fs):
    lines = ["| model | N | code | integrator | dt (fs) | runs | ps | ⟨U⟩/N (kJ/mol) | "
             "Δ⟨U⟩/N | T_tr (K) | T_rot (K) | reported − end of step, tr / rot (K) | "
             "T_conf tr/rot (K) | RDF r₁ (Å) | g(r₁) | D_PBC (1e-5 cm²/s) | ΔD |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for p in points:
        conf = "—" if p["T_conf_tr"] is None else \
            f"{_pm(p['T_conf_tr'], 1)} / {_pm(p['T_conf_rot'], 1)}"
        sampled = p.get("runs_of", {}).get("T_conf_tr", p["runs"])
        if p["T_conf_tr"] is not None and sampled < p["runs"]:
            conf += f" ({sampled} of {p['runs']} runs)"
        lines.append(
            f"| {p['model']} | {p['waters']} | {p['code']} | {p['integrator']} | "
            f"{p['dt_fs']:g} | {p['runs']} | {p['ps']:.0f} | {_pm(p['U'], 3)} | "
            f"{_gap(p, 'U', fit_table, 3)} | {_pm(p['T_tr'], 1)} | {_pm(p['T_rot'], 1)} | "
            f"{_gap_pm(p.get('T_tr_gap'))} / {_gap_pm(p.get('T_rot_gap'))} | {conf} | "
            f"{_pm(p['rdf_peak_r'], 3)} | {_pm(p['rdf_peak_g'], 2)} | "
            f"{_pm(p['D_pbc'], 2)} | {_gap(p, 'D_pbc', fit_table, 2)} |")
    lines += ["", f"dt → 0 limits (a + b·dt² over dt ≤ {fit_max_fs:g} fs; rigidmd's "
                  "integrators share a (for D_PBC those of one kind of thermostat: "
                  "friction, Langevin; global, Bussi and Nosé–Hoover); 'agree': each "
                  "integrator's own limit is within the stated combined standard errors of "
                  "the shared one)", "",
              "| model | N | code | quantity | limit | χ²/dof | own limits | agree |",
              "|---|---|---|---|---|---|---|---|"]
    for (model, waters, code, key), f in sorted(fit_table.items()):
        s = f["shared"]
        own = ", ".join(f"{k} {v['a']:.4g} ± {v['a_err']:.2g}" for k, v in f["alone"].items()
                        if np.isfinite(v["a"])) or "—"
        chi = f"{s['chi2']:.2f}/{s['dof']}" if s["dof"] else "—"
        agree = {None: "—", True: "yes", False: "NO"}[f["agree"]]
        limit = f"{s['a']:.4g} ± {s['a_err']:.2g}" if np.isfinite(s["a"]) else "—"
        lines.append(f"| {model} | {waters} | {code} | {key} | {limit} | {chi} | {own} | "
                     f"{agree} |")
    return "\n".join(lines) + "\n"


#: The goals of a step (the issue's, for TIP4P/2005 at 4 fs), each ``(tolerance, unit)``:
#: ⟨U⟩/N from its dt → 0 limit (kJ/mol); T_tr and T_rot as reported from the bath and from
#: each other (K); T_conf of translation and rotation from the bath (K); the RDF's first
#: peak height from its limit (relative); D_PBC from its limit (relative).
GOALS = {"U": 0.05, "T_tr": 1.0, "T_rot": 1.0, "T_tr_rot": 1.0, "T_conf_tr": 2.0,
         "T_conf_rot": 2.0, "rdf_peak_g": 0.01, "D_pbc": 0.03}


def deviations(point, fit_table, bath_K):
    """Each goal's deviation of ``point``, its standard error and the point's own part of
    that error, ``{goal: (dev, err, point_err)}`` (absent where the point or its limit lacks
    the quantity).  Relative goals are divided by the limit; the limit's own error is
    combined with the point's."""
    out = {}

    def limit(key):
        f = fit_table.get((*family(point, key), key))
        return None if f is None or not np.isfinite(f["shared"]["a"]) else f["shared"]

    for key in ("U", "rdf_peak_g", "D_pbc"):
        lim = limit(key)
        if point.get(key) is None or lim is None:
            continue
        err = np.hypot(point[key][1], lim["a_err"])
        dev = point[key][0] - lim["a"]
        scale = 1.0 if key == "U" else abs(lim["a"])
        out[key] = (dev / scale, err / scale, point[key][1] / scale)
    for key in ("T_tr", "T_rot", "T_conf_tr", "T_conf_rot"):
        if point.get(key) is not None:
            out[key] = (point[key][0] - bath_K, point[key][1], point[key][1])
    if point.get("T_tr") is not None and point.get("T_rot") is not None:
        err = float(np.hypot(point["T_tr"][1], point["T_rot"][1]))
        out["T_tr_rot"] = (point["T_tr"][0] - point["T_rot"][0], err, err)
    return out


def verdict(dev, err, tolerance, sigmas=2.0):
    """``"meets"`` when the deviation and ``sigmas`` errors lie within the tolerance,
    ``"fails"`` when the deviation less ``sigmas`` errors lies beyond it, else
    ``"unresolved"`` (the errors are too large to tell, or unknown: a value without an
    error, one run's RDF peak or D, is never judged)."""
    if not np.isfinite(err):
        return "unresolved"
    if abs(dev) + sigmas * err <= tolerance:
        return "meets"
    if abs(dev) - sigmas * err > tolerance:
        return "fails"
    return "unresolved"


def runs_to_decide(dev, err, point_err, runs, tolerance, sigmas=2.0):
    """The runs of a point, in all, that would decide an unresolved goal if its deviation
    stayed where it is: the point's own error falls as one over the square root of its
    runs, its limit's (the rest of ``err``) does not.

    The smallest ``m > runs`` with ``sigmas * hypot(point_err * sqrt(runs / m), limit_err)
    <= | |dev| - tolerance |``; None when no number of runs would do (the deviation sits
    on the tolerance, or the limit's own error is too large: the limit needs runs, not the
    point) or the errors are unknown.  A plan, not a promise: the deviation moves with the
    runs (by about its error).
    """
    if not (np.isfinite(err) and np.isfinite(point_err) and point_err > 0):
        return None
    limit_var = max(err * err - point_err * point_err, 0.0)
    half = abs(abs(dev) - tolerance) / sigmas
    if half * half <= limit_var:
        return None
    m = max(int(np.floor(point_err * point_err * runs / (half * half - limit_var))), runs + 1)
    # The bound decides to roundoff; the verdict itself settles the last run (it is strict
    # on the side of failing).
    while verdict(dev, float(np.hypot(point_err * np.sqrt(runs / m), np.sqrt(limit_var))),
                  tolerance, sigmas) == "unresolved":
        m += 1
    return m


#: Steps from this one (fs) are judged against twice the tolerances: the issue's goal for a
#: step past the accurate one is stability with every quantity within twice them.
RELAXED_FROM_FS = 6.0


def assess(points, fit_table, bath_K=298.0, goals=GOALS, relaxed_from_fs=RELAXED_FROM_FS):
    """Per point, each goal's deviation, error and verdict (the tolerances doubled from
    ``relaxed_from_fs``); per code and integrator, the largest step no goal fails
    (``"not_excluded_fs"``) and the largest step every goal is shown to meet (``"shown_fs"``,
    None when none), both among the steps judged at the goals' own tolerances and below
    the first step a goal fails (``"first_failing_fs"``): a larger step whose errors are
    too large to fail it is no accurate step when a smaller one failed."""
    rows, best = [], {}
    order = ("model", "waters", "code", "integrator", "dt_fs")
    for p in sorted(points, key=lambda p: tuple(p[k] for k in order)):
        devs = deviations(p, fit_table, bath_K)
        # An r-RESPA split is judged at the goals' own tolerances whatever its outer step:
        # it competes with the accurate single step.
        split = p.get("substeps", 1) > 1
        factor = 2.0 if p["dt_fs"] >= relaxed_from_fs - 1e-9 and not split else 1.0
        checks = {g: {"dev": d, "err": e, "tolerance": goals[g] * factor,
                      "verdict": verdict(d, e, goals[g] * factor)}
                  for g, (d, e, _) in devs.items() if g in goals}
        for g, c in checks.items():  # (a value without an error of its own: no plan)
            if c["verdict"] == "unresolved" and np.isfinite(c["err"]) and devs[g][2] > 0:
                # (in all: the point's runs that did not sample the quantity count too)
                sampled = p.get("runs_of", {}).get("T_tr" if g == "T_tr_rot" else g,
                                                   p["runs"])
                need = runs_to_decide(c["dev"], c["err"], devs[g][2], sampled,
                                      c["tolerance"])
                c["runs_to_decide"] = None if need is None else need + p["runs"] - sampled
        rows.append({**{k: p[k] for k in ("model", "waters", "code", "integrator", "dt_fs",
                                          "runs")},
                     "tolerance_factor": factor, "checks": checks})
        if factor != 1.0:
            continue  # a stability step, not a candidate for the accurate one
        key = (p["model"], p["waters"], p["code"], p["integrator"])
        entry = best.setdefault(key, {"scheme": p.get("scheme", p["integrator"]),
                                      "substeps": p.get("substeps", 1),
                                      "r_split": p.get("r_split"), "not_excluded_fs": None,
                                      "shown_fs": None, "first_failing_fs": None,
                                      "missing": set()})
        entry["missing"] |= set(goals) - set(checks)
        if not checks or entry["first_failing_fs"] is not None:
            continue  # (the points come in order of the step)
        if any(c["verdict"] == "fails" for c in checks.values()):
            entry["first_failing_fs"] = p["dt_fs"]
            continue
        entry["not_excluded_fs"] = max(entry["not_excluded_fs"] or 0.0, p["dt_fs"])
        if set(checks) == set(goals) and all(c["verdict"] == "meets" for c in checks.values()):
            entry["shown_fs"] = max(entry["shown_fs"] or 0.0, p["dt_fs"])
    for entry in best.values():
        entry["missing"] = sorted(entry["missing"])
    return rows, best


def goals_table(rows, best):
    """The goals' verdicts per point, and per code and integrator the largest steps."""
    names = list(GOALS)
    marks = {"meets": "✓", "fails": "✗", "unresolved": "?"}
    lines = ["| code | integrator | dt (fs) | " + " | ".join(
        f"{g} (±{GOALS[g]:g})" for g in names) + " |",
        "|---|---|---|" + "---|" * len(names)]
    for r in rows:
        cells = []
        for g in names:
            c = r["checks"].get(g)
            if c is None:
                cells.append("—")
                continue
            pct = g in ("rdf_peak_g", "D_pbc")
            dev, err = (100 * c["dev"], 100 * c["err"]) if pct else (c["dev"], c["err"])
            digits = 3 if g == "U" else 1
            cells.append(f"{marks[c['verdict']]} {dev:+.{digits}f} ± {err:.{digits}f}"
                         + ("%" if pct else ""))
        doubled = " (2× tolerances)" if r.get("tolerance_factor", 1.0) != 1.0 else ""
        lines.append(f"| {r['code']} | {r['integrator']} | {r['dt_fs']:g}{doubled} | "
                     + " | ".join(cells) + " |")
    lines += ["", "Runs that would decide the unresolved goals, in all (now: runs), if the "
              "deviations stayed as they are (each point's own error falls as 1/√runs, its "
              "limit's does not; ∞: the deviation sits on the tolerance or the limit's error "
              "is too large)", "",
              "| code | integrator | dt (fs) | runs | " + " | ".join(names) + " |",
              "|---|---|---|---|" + "---|" * len(names)]
    for r in rows:
        wanted = {g: c["runs_to_decide"] for g, c in r["checks"].items()
                  if c["verdict"] == "unresolved" and "runs_to_decide" in c}
        if wanted:
            lines.append(f"| {r['code']} | {r['integrator']} | {r['dt_fs']:g} | {r['runs']} | "
                         + " | ".join("" if g not in wanted else "∞" if wanted[g] is None
                                      else str(wanted[g]) for g in names) + " |")
    lines += ["", "| code | integrator | largest step no goal fails (fs) | largest step every "
              "goal is shown to meet (fs) | goals not measured |", "|---|---|---|---|---|"]
    for (_model, _waters, code, integ), b in sorted(best.items()):
        lines.append(f"| {code} | {integ} | {b['not_excluded_fs'] or '—'} | "
                     f"{b['shown_fs'] or '—'} | {', '.join(b['missing']) or '—'} |")
    return "\n".join(lines) + "\n"


def write_csv(points, fit_table, path):
    keys = ("U", "T_tr", "T_rot", "T_tr_end", "T_rot_end", "T_tr_gap", "T_rot_gap",
            "rdf_peak_r", "rdf_peak_g", "D_pbc")
    with open(path, "w", newline="") as fh:
        fh.write("# timestep_table_report.py: pooled points; <q>_limit is the family's "
                 "dt -> 0 fit (nan where none)\n")
        w = csv.writer(fh)
        w.writerow(["model", "waters", "code", "integrator", "dt_fs", "runs", "ps"]
                   + [f"{k}{s}" for k in keys for s in ("", "_err")]
                   + [f"{k}_limit" for k in FITTED])
        for p in points:
            vals = []
            for k in keys:
                vals += list(p[k]) if p.get(k) is not None else ["nan", "nan"]
            lim = [fit_table[(*family(p, k), k)]["shared"]["a"] for k in FITTED]
            w.writerow([p["model"], p["waters"], p["code"], p["integrator"], p["dt_fs"],
                        p["runs"], f"{p['ps']:.3f}"] + vals + lim)


def report(paths, outdir, name, fit_max_fs=2.0, agree_sigma=2.0, header="",
           include_incomplete=False, borrow=None):
    """Read the runs, write ``<name>.md``, ``.json`` and ``.csv``; return (points, fits).

    The Markdown and the JSON also hold each point's goals (:func:`assess`: deviation, error,
    verdict) and per code and integrator the largest steps that meet them."""
    points = load_points(paths, include_incomplete)
    fit_table = fits(points, fit_max_fs, agree_sigma, borrow)
    rows, best = assess(points, fit_table)
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    borrowed = sorted({(k[2], f["borrowed_from"]) for k, f in fit_table.items()
                       if "borrowed_from" in f})
    note = "".join(f"\n{code}'s limits of ⟨U⟩ and the RDF peak are {donor}'s (the same "
                   f"forces; {code} has too few steps at or below {fit_max_fs:g} fs for its "
                   "own; D_PBC, which depends on the thermostat, has none)\n"
                   for code, donor in borrowed)
    text = ((header + "\n\n" if header else "") + table(points, fit_table, fit_max_fs) + note
            + "\nGoals (✓ shown to meet: deviation and two standard errors within the "
            "tolerance; ✗ fails: beyond it by more than two; ? unresolved)\n\n"
            + goals_table(rows, best))
    (outdir / f"{name}.md").write_text(text)
    (outdir / f"{name}.json").write_text(json.dumps(
        {"fit_max_fs": fit_max_fs, "agree_sigma": agree_sigma, "points": points,
         "fits": [{"model": k[0], "waters": k[1], "code": k[2], "quantity": k[3], **v}
                  for k, v in sorted(fit_table.items())],
         "goals": GOALS, "assessed": rows,
         "largest_steps": [{"model": k[0], "waters": k[1], "code": k[2], "integrator": k[3],
                            **v} for k, v in sorted(best.items())]}, indent=1) + "\n")
    write_csv(points, fit_table, outdir / f"{name}.csv")
    return points, fit_table


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("files", nargs="+", type=Path)
    p.add_argument("--name", default="timestep_table")
    p.add_argument("--outdir", type=Path, default=HERE)
    p.add_argument("--fit-max-fs", type=positive, default=2.0)
    p.add_argument("--agree-sigma", type=positive, default=2.0)
    p.add_argument("--header", default="", help="a line written above the table")
    p.add_argument("--include-incomplete", action="store_true",
                   help="also pool runs that were stopped before their length")
    p.add_argument("--bundle", action="store_true",
                   help="also write every run read into <name>.runs.json (read again as input)")
    p.add_argument("--borrow-limit", nargs="*", default=[], metavar="CODE=OTHER",
                   help="a code without its own dt → 0 limit takes another's (lammps=rigidmd: "
                        "the same LAMMPS forces)")
    args = p.parse_args(argv)
    borrow = {}
    for item in args.borrow_limit:
        code, sep, donor = item.partition("=")
        if not sep or code == donor or code not in ("lammps", "rigidmd", "openmm") or \
                donor not in ("lammps", "rigidmd", "openmm"):
            p.error(f"--borrow-limit {item!r}: give CODE=OTHER of lammps, rigidmd, openmm")
        if "openmm" in (code, donor):
            p.error(f"--borrow-limit {item!r}: OpenMM's long-range and dispersion treatments "
                    "differ from LAMMPS's, so neither's limit is the other's")
        borrow[code] = donor
    report(args.files, args.outdir, args.name, args.fit_max_fs, args.agree_sigma, args.header,
           args.include_incomplete, borrow)
    if args.bundle:  # every run read, in one file the collector reads again
        runs = sorted((run for _, run in read_runs(args.files)),
                      key=lambda r: json.dumps(r["point"], sort_keys=True))
        (args.outdir / f"{args.name}.runs.json").write_text(json.dumps(runs, indent=1) + "\n")
    print((args.outdir / f"{args.name}.md").read_text())


if __name__ == "__main__":
    main()
