r"""Rigid water in rigidmd and in OpenMM over long thermostatted runs: ⟨U⟩, T_conf and D.

Companion of ``water_openmm_nve.py`` (same state, same force field, the same
observables) for the statistics of issue 39: many independent runs, each
stopped by a wall-clock budget rather than a step count, so that a batch of
single-threaded runs fills a machine for a known time.

- ``run``: one run of one code, model, thermostat, step and seed, from the
  model's start state (TIP4P-Ew: ``water_openmm_nve.start6.1.npz``; TIP4P/2005
  and SPC/E: ``water_openmm_long.start_<model>.npz``, made by ``starts``).
  Both codes: 216 waters in the same cubic cell (0.9953 g/cm³), 9 Å, the
  long-range Lennard-Jones correction, PPPM (LAMMPS) or PME (OpenMM) at 1e-5.
  Thermostats: rigidmd ``langevin`` (:class:`rigidmd.RigidLangevin`,
  ``fixcm=True``: Ornstein–Uhlenbeck half steps around NO_SQUISH velocity
  Verlet, the O–BAB–O splitting) and ``bussi`` (:class:`rigidmd.RigidBussi`);
  OpenMM ``middle`` (``LangevinMiddleIntegrator``, the BAOAB splitting),
  ``leapfrog`` (``LangevinIntegrator``) and ``andersen`` (``VerletIntegrator``
  with an ``AndersenThermostat``).  ``--tau-ps`` is 1/friction, Bussi's τ or
  1/collision frequency.  TIP4P/2005 in OpenMM is OpenMM's TIP4P-Ew system
  with TIP4P/2005's charges, Lennard-Jones and M site.
  Recorded: kinetic energies of translation and rotation every 10 fs (from
  the bodies: rigidmd's own; OpenMM's from its atom velocities, which for the
  Langevin integrators are not on-step velocities), the code's own potential
  energy (rigidmd every 10 fs, with LAMMPS's constant intramolecular Coulomb
  energy in it; OpenMM every 50 fs) and frames of O, H, H every 1 ps, into
  one compressed ``.npz`` rewritten every minute and at the end (also on
  SIGTERM); an existing ``--out`` is refused unless ``--overwrite``.
- ``report``: reads any number of such files and gives, per model, code,
  thermostat and step (runs of several seeds pooled): ⟨U⟩/N (rigidmd's moved
  onto OpenMM's energy scale by the mean difference of the two energies on
  its own frames), T_tr (3N − 3 degrees of freedom where the total momentum
  is held, else 3N), T_rot (3N), the configurational temperatures of
  translation and rotation (``water_openmm_nve.configurational_sums`` on
  every frame, OpenMM's force field for both codes; kept in ``<file>.conf.npz``
  with the digest of the frames they are of), and D_PBC from the
  centres of mass (MSD slope over 3–10 ps lags in 20 ps segments, the
  system's own drift removed; runs of a few minutes are 20–30 ps long).
  The statistical unit is a run, or a 20 ps piece of a longer one (⟨U⟩
  stays correlated over tens of ps): means weighted by length with their
  standard errors; T_conf by jackknife over the pieces.
  Langevin friction slows diffusion: D here compares the codes under the
  same friction, it is not the NVE value.

Run (one thread each, ``nice``)::

    python validation/water_openmm_long.py run --code rigidmd --thermo langevin --dt-fs 2 \
        --seed 1 --budget-s 3600 --out validation/long/a.npz
    python validation/water_openmm_long.py report validation/long/*.npz --name water_openmm_long
    python validation/water_openmm_long.py starts --eq-ps 5     # TIP4P/2005 and SPC/E starts
    python validation/water_openmm_long.py --quick              # seconds: checks the pipeline
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

T0 = time.perf_counter()
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from arguments import existing_file  # noqa: E402
from water_openmm_nve import (  # noqa: E402
    CUTOFF,  # every model here (one box, one set-up for both codes)
    KB_KJ,
    TEMPERATURE_K,
    body_kinetic_energies,
    configurational_sums,
    openmm_context,
    state_at_rest,
    state_atoms,
    whole,
    write_results,
)
from water_openmm_nve import openmm_system as tip4p_openmm_system  # noqa: E402

KE_FS, U_OMM_FS, FRAME_FS = 10.0, 50.0, 1000.0
#: The statistical unit: a run, or pieces of at least this long of a longer one.  ⟨U⟩'s block
#: error was still growing at 15 ps blocks in one 75 ps run (1 ps: 0.044, 5 ps: 0.081, 15 ps:
#: 0.117 kJ/mol), so blocks of a few ps understate it; runs from different seeds are
#: independent.
PIECE_PS = 20.0
MSD_FIT_PS = (3.0, 10.0)  # ps of lag for D: runs of a few minutes are 13-30 ps long


# --------------------------------------------------------------------------- runs
def start_file(model_name):
    """The start state of ``model_name`` (see :func:`make_starts`)."""
    if model_name == "tip4pew":
        return HERE / "water_openmm_nve.start6.1.npz"
    return HERE / f"water_openmm_long.start_{model_name}.npz"


def load_state(model_name):
    with np.load(start_file(model_name)) as d:
        return {k: d[k] for k in ("positions", "momenta", "cell", "numbers")}


class Recorder:
    """The run's series and metadata, saved to ``args.out`` (compressed ``.npz``)."""

    def __init__(self, args, n, sites, masses, cell):
        self.args, self.n, self.sites, self.masses, self.cell = args, n, sites, masses, cell
        self.rec = {"K_tr": [], "K_rot": [], "U": [], "U_t_ps": [], "frames": []}
        self.last_save = time.perf_counter()
        self.meta = {}

    def frame(self, x_whole_A):
        mass = self.masses.reshape(-1, self.sites) > 0
        xs = x_whole_A.reshape(-1, self.sites, 3)[mass].reshape(self.n, -1, 3)
        self.rec["frames"].append(xs.astype(np.float32))

    def save(self, final=False):
        out = {k: np.asarray(v) for k, v in self.rec.items()}
        meta = dict(self.meta, final=final, wall_s=time.perf_counter() - T0)
        tmp = Path(str(self.args.out) + ".tmp.npz")
        np.savez_compressed(tmp, masses=self.masses, cell=self.cell,
                            meta=json.dumps(meta), **out)
        os.replace(tmp, self.args.out)
        self.last_save = time.perf_counter()

    def maybe_save(self):
        if time.perf_counter() - self.last_save > 60:
            self.save()


def rigidmd_atoms(state, model):
    """``state``'s atoms (:func:`water_openmm_nve.state_atoms`: LAMMPS's ``lj/cut/coul/long``,
    PPPM 1e-5, the tail correction) with one tag per molecule (the bodies)."""
    atoms = state_atoms(state, model, CUTOFF)
    n = len(atoms) // model.sites
    atoms.set_tags(np.repeat(np.arange(1, n + 1), model.sites))  # one body per molecule
    return atoms


def drive(rec, args, deadline, advance, observe):
    """Make up to ``--skip-ps`` unrecorded, then record until ``deadline``.

    ``advance(n)`` makes n steps; ``observe(i, frame)`` records sample ``i`` (every
    :data:`KE_FS`) and, when ``frame``, returns the whole molecules' positions (Å).
    """
    ke = max(int(round(KE_FS / args.dt_fs)), 1)
    frame_every = int(round(FRAME_FS / KE_FS))
    skip_deadline = T0 + args.skip_frac * (deadline - T0)
    skip_steps = int(round(args.skip_ps * 1000 / args.dt_fs))
    t_start = time.perf_counter()
    done = 0
    while done < skip_steps and time.perf_counter() < skip_deadline:
        advance(10 * ke)
        done += 10 * ke
    rec.meta.update(skip_ps=done * args.dt_fs / 1000,
                    setup_s=t_start - T0, skip_s=time.perf_counter() - t_start)
    t_rec = time.perf_counter()
    i = 0
    try:
        while True:
            x = observe(i, i % frame_every == 0)
            if x is not None:
                rec.frame(x)
                rec.maybe_save()
            if time.perf_counter() > deadline:
                break
            advance(ke)
            i += 1
    finally:  # also when a signal stops the run: the samples recorded so far
        steps = i * ke
        rec.meta.update(steps=steps, ps=steps * args.dt_fs / 1000,
                        ms_per_step=1000 * (time.perf_counter() - t_rec) / max(steps, 1))


def run_rigidmd(args, state, model, deadline, rec):
    """Run rigidmd until ``deadline`` (perf_counter seconds), recording into ``rec``."""
    from ase import units

    from rigidmd import RigidBussi, RigidLangevin

    kj = units.kJ / units.mol
    atoms = rigidmd_atoms(state, model)
    dt = args.dt_fs * units.fs
    rng = np.random.default_rng(1000 + args.seed)
    if args.thermo == "langevin":
        dyn = RigidLangevin(atoms, dt, temperature_K=TEMPERATURE_K,
                            friction=1e-3 / args.tau_ps / units.fs, rng=rng, fixcm=True)
    elif args.thermo == "bussi":
        dyn = RigidBussi(atoms, dt, temperature_K=TEMPERATURE_K,
                         taut=args.tau_ps * 1000 * units.fs, rng=rng, fixcm=bool(args.fixcm))
    else:
        raise SystemExit(f"rigidmd has no thermostat {args.thermo!r} here")

    def observe(i, frame):
        rec.rec["K_tr"].append(dyn.get_translational_kinetic_energy() / kj)
        rec.rec["K_rot"].append(dyn.get_rotational_kinetic_energy() / kj)
        rec.rec["U"].append(atoms.get_potential_energy() / kj)
        rec.rec["U_t_ps"].append(i * KE_FS / 1000)
        return whole(atoms.positions, atoms.cell.array, model.sites) if frame else None

    drive(rec, args, deadline, dyn.run, observe)
    rec.meta.update(conserved_kj_per_mol=dyn.get_conserved_energy() / kj)


def openmm_system(state, model):
    """OpenMM's system of ``state`` (rigidmd's masses); TIP4P/2005 re-parametrised from
    OpenMM's TIP4P-Ew file (charges, Lennard-Jones, the M site's weights)."""
    import openmm

    from rigidmd.water import water_model

    n = len(state["numbers"]) // model.sites
    base = water_model("tip4pew") if model.name == "tip4p2005" else model
    positions = state["positions"].copy()
    if base is not model:  # build tip4pew's system (M where tip4pew has it), then re-parametrise
        x = positions.reshape(n, 4, 3)
        b = x[:, 1] + x[:, 2] - 2 * x[:, 0]
        x[:, 3] = x[:, 0] + base.d_om * b / np.linalg.norm(b, axis=1)[:, None]
    system = tip4p_openmm_system(dict(state, positions=positions), base, CUTOFF,
                                 parameters="rigidmd")
    masses = np.tile(model.masses(), n)
    for i, m in enumerate(masses):
        system.setParticleMass(i, float(m))
    if base is not model:
        nb = next(f for f in system.getForces() if isinstance(f, openmm.NonbondedForce))
        from ase import units
        kj = units.kJ / units.mol
        q = model.charges(n)
        for i in range(len(masses)):
            o = i % 4 == 0
            nb.setParticleParameters(i, float(q[i]), model.sigma / 10 if o else 1.0,
                                     model.epsilon / kj if o else 0.0)
        geom = model.molecule().positions  # O, H, H, M of the model
        h_sum = geom[1] + geom[2] - 2 * geom[0]
        a = float(np.linalg.norm(geom[3] - geom[0]) / np.linalg.norm(h_sum))
        for k in range(n):
            system.setVirtualSite(4 * k + 3, openmm.ThreeParticleAverageSite(
                4 * k, 4 * k + 1, 4 * k + 2, 1 - 2 * a, a, a))
    return system


def run_openmm(args, state, model, deadline, rec):
    """Run OpenMM until ``deadline`` (perf_counter seconds), recording into ``rec``."""
    import openmm
    from openmm import unit

    system = openmm_system(state, model)
    dt = args.dt_fs * 1e-3
    gamma = 1.0 / args.tau_ps
    if args.thermo == "middle":
        integrator = openmm.LangevinMiddleIntegrator(TEMPERATURE_K, gamma, dt)
        integrator.setRandomNumberSeed(1000 + args.seed)
    elif args.thermo == "leapfrog":
        integrator = openmm.LangevinIntegrator(TEMPERATURE_K, gamma, dt)
        integrator.setRandomNumberSeed(1000 + args.seed)
    elif args.thermo == "andersen":
        thermostat = openmm.AndersenThermostat(TEMPERATURE_K, gamma)
        thermostat.setRandomNumberSeed(1000 + args.seed)
        system.addForce(thermostat)
        integrator = openmm.VerletIntegrator(dt)
    else:
        raise SystemExit(f"OpenMM has no thermostat {args.thermo!r} here")
    context, masses, v = openmm_context(system, integrator, state)
    context.setVelocities(v)
    context.applyVelocityConstraints(1e-10)
    u_every = int(round(U_OMM_FS / KE_FS))
    cell = state["cell"] / 10

    def observe(i, frame):
        want_u = i % u_every == 0
        st = context.getState(getPositions=True, getVelocities=True, getEnergy=want_u)
        x = st.getPositions(asNumpy=True).value_in_unit(unit.nanometer)
        vel = st.getVelocities(asNumpy=True).value_in_unit(unit.nanometer / unit.picosecond)
        kt, kr = body_kinetic_energies(x, vel, masses, model.sites)
        rec.rec["K_tr"].append(kt)
        rec.rec["K_rot"].append(kr)
        if want_u:
            rec.rec["U"].append(st.getPotentialEnergy().value_in_unit(unit.kilojoule_per_mole))
            rec.rec["U_t_ps"].append(i * KE_FS / 1000)
        return whole(x, cell, model.sites) * 10 if frame else None

    drive(rec, args, deadline, integrator.step, observe)


# --------------------------------------------------------------------------- starts
def rebuild(state, old, new):
    """``new``'s molecules placed as ``old``'s: same O, plane, bisector, centre of mass,
    centre-of-mass and angular velocities; whole molecules, Å and ASE momenta."""
    n = len(state["numbers"]) // old.sites
    x = state["positions"].reshape(n, old.sites, 3)[:, :3]
    m_old = old.masses()[:3]
    v = state["momenta"].reshape(n, old.sites, 3)[:, :3] / m_old[None, :, None]
    M = m_old.sum()
    X = np.einsum("s,bsk->bk", m_old, x) / M
    V = np.einsum("s,bsk->bk", m_old, v) / M
    r, u = x - X[:, None], v - V[:, None]
    L = np.einsum("s,bsk->bk", m_old, np.cross(r, u))
    inertia = (np.einsum("s,bs->b", m_old, np.einsum("bsk,bsk->bs", r, r))[:, None, None]
               * np.eye(3) - np.einsum("s,bsi,bsj->bij", m_old, r, r))
    omega = np.linalg.solve(inertia, L[..., None])[..., 0]
    b = x[:, 1] + x[:, 2] - 2 * x[:, 0]
    b /= np.linalg.norm(b, axis=1)[:, None]
    e = x[:, 1] - x[:, 2]
    e -= np.einsum("bk,bk->b", e, b)[:, None] * b
    e /= np.linalg.norm(e, axis=1)[:, None]
    geom = new.molecule().positions  # O at the origin, bisector +y, H1 at +x
    sites = x[:, :1] + geom[None, :, 0:1] * e[:, None] + geom[None, :, 1:2] * b[:, None]
    m_new = new.masses()
    sites += (X - np.einsum("s,bsk->bk", m_new, sites) / m_new.sum())[:, None]
    momenta = m_new[None, :, None] * (V[:, None] + np.cross(omega[:, None], sites - X[:, None]))
    return {"positions": sites.reshape(-1, 3), "momenta": momenta.reshape(-1, 3),
            "cell": state["cell"], "numbers": np.tile([8, 1, 1, 0][:new.sites], n)}


def make_starts(eq_ps):
    """TIP4P/2005 and SPC/E starts from TIP4P-Ew's (:func:`rebuild`), then ``eq_ps`` of
    rigidmd Bussi (τ 0.1 ps, 2 fs, ``fixcm``) and the total momentum set to zero."""
    from ase import units

    from rigidmd import RigidBussi
    from rigidmd.water import water_model

    ew = water_model("tip4pew")
    source = load_state("tip4pew")
    for name in ("tip4p2005", "spce"):
        model = water_model(name)
        atoms = rigidmd_atoms(rebuild(source, ew, model), model)
        RigidBussi(atoms, 2 * units.fs, temperature_K=TEMPERATURE_K, taut=100 * units.fs,
                   rng=np.random.default_rng(7), fixcm=True).run(int(round(eq_ps * 500)))
        np.savez(start_file(name), **state_at_rest(atoms, model.sites))
        print(f"{start_file(name).name}: {eq_ps:g} ps", flush=True)


# --------------------------------------------------------------------------- analysis
def _pieces(series, sample_ps):
    """``series`` (one sample every ``sample_ps``) in max(1, length // PIECE_PS) parts."""
    series = np.asarray(series, dtype=float)
    return np.array_split(series, max(1, int(len(series) * sample_ps // PIECE_PS)))


def _piece_means(series, sample_ps):
    """(mean, samples) of each piece, shape (pieces, 2)."""
    return np.array([(p.mean(), len(p)) for p in _pieces(series, sample_ps) if len(p)])


def msd_diffusion(com, frame_ps, fit=MSD_FIT_PS):
    """D (1e-5 cm²/s) from centres of mass every ``frame_ps``: unwrapped, the mean
    displacement of all molecules removed, MSD over all origins, slope of a straight line
    over lags ``fit`` (ps) / 6."""
    lags = np.arange(int(round(fit[0] / frame_ps)), int(round(fit[1] / frame_ps)) + 1)
    if len(com) <= lags[-1]:
        return float("nan")
    disp = com - com.mean(axis=1, keepdims=True)  # the system's drift out
    msd = [np.mean(np.sum((disp[lag:] - disp[:-lag]) ** 2, axis=2)) for lag in lags]
    return float(np.polyfit(lags * frame_ps, msd, 1)[0] / 6 * 10)  # Å²/ps = 10 × 1e-5 cm²/s


def _frames_digest(model_name, frames):
    """SHA-256 of a model's name and frames: what a cache of their sums is of."""
    import hashlib

    digest = hashlib.sha256(model_name.encode())
    digest.update(np.ascontiguousarray(frames).tobytes())
    return digest.hexdigest()


def _cached_sums(cache, model_name, frames):
    """The configurational sums in ``cache`` when they are of the first frames of
    ``frames``; else none (an unreadable cache, or one of another run's frames)."""
    try:
        with np.load(cache) as d:
            sums, digest = d["sums"], str(d["digest"])
    except (OSError, KeyError, ValueError):
        return np.zeros((0, 5))
    if len(sums) > len(frames) or digest != _frames_digest(model_name, frames[:len(sums)]):
        return np.zeros((0, 5))
    return sums


def analyse_run(path, contexts):
    """Per-piece values of one run (see the module docstring)."""
    import openmm

    from rigidmd.water import water_model

    with np.load(path) as d:
        data = {k: d[k] for k in d.files}
    meta = json.loads(str(data["meta"]))
    model = water_model(meta["model"])
    n, sites = meta["molecules"], model.sites
    masses = data["masses"]
    if model.name not in contexts:
        state = load_state(model.name)
        contexts[model.name] = openmm.Context(
            openmm_system(state, model), openmm.VerletIntegrator(1e-3),
            openmm.Platform.getPlatformByName("CPU"), {"Threads": "1"})
    frames = data["frames"].astype(float)  # (frames, n, 3, 3): O, H, H in Å
    full = np.zeros((len(frames), n, sites, 3))
    full[:, :, :3] = frames
    if sites == 4:
        full[:, :, 3] = frames[:, :, 0]  # M: placed by OpenMM
    # Nine force calls a frame: kept beside the run (``<file>.conf.npz``) with the digest of
    # the frames they are of, and extended when the run has grown; frames that are not those
    # (another run written to the same file) are computed afresh.
    cache = Path(str(path) + ".conf.npz")
    done = _cached_sums(cache, model.name, data["frames"])
    rng = np.random.default_rng(len(done))
    new = [configurational_sums(contexts[model.name], f.reshape(-1, 3) / 10, masses, rng,
                                sites) for f in full[len(done):]]
    sums = np.concatenate([done, np.array(new).reshape(-1, 5)])[:len(full)]
    if new:
        tmp = Path(str(cache) + ".tmp.npz")
        np.savez(tmp, sums=sums, digest=_frames_digest(model.name, data["frames"][:len(sums)]))
        os.replace(tmp, cache)
    held = meta["code"] == "rigidmd" and (meta["thermo"] == "langevin" or meta["fixcm"])
    ke_ps, u_ps, frame_ps = (meta[k] / 1000 for k in ("ke_fs", "u_fs", "frame_fs"))
    u = np.asarray(data["U"]) / n
    offset = offset_sd = 0.0
    if meta["code"] == "rigidmd":  # LAMMPS's energy holds the constant intramolecular part
        at = np.round(np.arange(len(frames)) * meta["frame_fs"] / meta["u_fs"]).astype(int)
        at = at[at < len(u)]
        gap = u[at] - sums[:len(at), 0] / n
        offset, offset_sd = float(np.mean(gap)), float(np.std(gap))
    m3 = masses.reshape(-1, sites)[0, :3]
    com = np.einsum("s,fbsk->fbk", m3, frames) / m3.sum()
    pieces = _pieces(np.arange(len(com)), frame_ps)
    d = [(msd_diffusion(com[int(p[0]):int(p[-1]) + 1], frame_ps), len(p)) for p in pieces
         if len(p)]
    return {"meta": meta, "ps": len(data["K_tr"]) * ke_ps,
            "T_tr": _piece_means(2 * data["K_tr"] / ((3 * n - (3 if held else 0)) * KB_KJ),
                                 ke_ps),
            "T_rot": _piece_means(2 * data["K_rot"] / (3 * n * KB_KJ), ke_ps),
            "U": _piece_means(u - offset, u_ps), "U_frames": _piece_means(sums[:, 0] / n,
                                                                         frame_ps),
            "conf": np.array([[p.sum() for p in _pieces(sums[:, k], frame_ps)]
                              for k in (1, 2, 3, 4)]),
            "D": np.array([x for x in d if np.isfinite(x[0])]).reshape(-1, 2),
            "D_run": msd_diffusion(com, frame_ps),
            "offset": offset, "offset_sd": offset_sd, "dof_tr": 3 * n - (3 if held else 0)}


def _mean(pieces):
    """Mean of piece means weighted by their samples, and its standard error."""
    pieces = np.asarray(pieces, dtype=float).reshape(-1, 2)
    if len(pieces) == 0:
        return [float("nan"), float("nan")]
    x, w = pieces[:, 0], pieces[:, 1]
    mean = float(np.sum(w * x) / w.sum())
    if len(x) < 2:
        return [mean, float("nan")]
    k = len(x)
    return [mean, float(np.sqrt(np.sum(w**2 * (x - mean) ** 2) * k / (k - 1)) / w.sum())]


def _ratio(num, den):
    """Σnum/Σden (K) with a jackknife error over pieces."""
    num, den = np.asarray(num), np.asarray(den)
    value = num.sum() / den.sum() / KB_KJ
    k = len(num)
    if k < 2:
        return [float(value), float("nan")]
    jack = (num.sum() - num) / (den.sum() - den) / KB_KJ
    return [float(value), float(np.sqrt((k - 1) / k * np.sum((jack - jack.mean()) ** 2)))]


def group_key(meta):
    return (meta["model"], meta["code"], meta["thermo"], float(meta["tau_ps"]),
            float(meta["dt_fs"]))


def report(paths, outdir, name):
    """Pool the runs of each (model, code, thermostat, τ, step); write ``<name>.json/.txt``."""
    contexts, groups = {}, {}
    for path in sorted(paths):
        r = analyse_run(path, contexts)
        groups.setdefault(group_key(r["meta"]), []).append(r)
        print(f"{Path(path).name}: {r['ps']:.0f} ps", flush=True)
    rows = []
    for key in sorted(groups, key=lambda k: (k[0], k[4], k[2], k[1])):
        runs = groups[key]
        cat = {k: np.concatenate([r[k] for r in runs]) for k in ("T_tr", "T_rot", "U",
                                                                  "U_frames", "D")}
        conf = np.concatenate([r["conf"] for r in runs], axis=1)
        d_runs = [r["D_run"] for r in runs]
        rows.append({"model": key[0], "code": key[1], "thermo": key[2], "tau_ps": key[3],
                     "dt_fs": key[4], "runs": len(runs), "seeds": [r["meta"]["seed"] for r in
                                                                   runs],
                     "ps": float(sum(r["ps"] for r in runs)),
                     "U": _mean(cat["U"]), "U_frames": _mean(cat["U_frames"]),
                     "T_tr": _mean(cat["T_tr"]), "T_rot": _mean(cat["T_rot"]),
                     "Tconf_tr": _ratio(conf[0], conf[1]),
                     "Tconf_rot": _ratio(conf[2], conf[3]),
                     "D_pbc": _mean(cat["D"]),
                     "D_runs": d_runs, "dof_tr": runs[0]["dof_tr"],
                     "ms_per_step": [r["meta"].get("ms_per_step") for r in runs],
                     "offsets": [r["offset"] for r in runs],
                     "offset_sd": [r["offset_sd"] for r in runs]})
    results = {"temperature_K": TEMPERATURE_K, "piece_ps": PIECE_PS, "msd_fit_ps": MSD_FIT_PS,
               "groups": rows}
    return write_results(results, Path(outdir) / name, table(results))


def table(results):
    def pm(v, digits=2):
        return f"{v[0]:.{digits}f} ± {v[1]:.{digits}f}"

    lines = [f"216 waters, one cell (0.9953 g/cm³ of TIP4P-Ew), 9 Å, LJ tail, PPPM/PME 1e-5, "
             f"{TEMPERATURE_K:g} K; mean ± standard error over runs and {PIECE_PS:g} ps "
             f"pieces of longer ones (D: MSD fit {MSD_FIT_PS[0]:g}-{MSD_FIT_PS[1]:g} ps)",
             "U: kJ/mol per molecule (rigidmd's LAMMPS energy moved onto OpenMM's scale); "
             "U_frames: OpenMM's energy of the 1 ps frames; T in K (T_tr: dof column); "
             "D_PBC in 1e-5 cm²/s under the thermostat's friction",
             "",
             f"{'model':9} {'code':7} {'thermostat':10} {'τ/ps':>4} {'dt':>3} {'runs':>4} "
             f"{'ps':>5} {'U':>17} {'U_frames':>17} {'T_tr':>14} {'dof':>4} {'T_rot':>14} "
             f"{'Tconf_tr':>14} {'Tconf_rot':>14} {'D_PBC':>12}"]
    for g in results["groups"]:
        lines.append(f"{g['model']:9} {g['code']:7} {g['thermo']:10} {g['tau_ps']:4g} "
                     f"{g['dt_fs']:3g} {g['runs']:4d} {g['ps']:5.0f} {pm(g['U'], 3):>17} "
                     f"{pm(g['U_frames'], 3):>17} {pm(g['T_tr']):>14} {g['dof_tr']:4d} "
                     f"{pm(g['T_rot']):>14} {pm(g['Tconf_tr']):>14} {pm(g['Tconf_rot']):>14} "
                     f"{pm(g['D_pbc']):>12}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- command line
def run_main(args):
    from rigidmd.water import water_model

    deadline = T0 + args.budget_s
    model = water_model(args.model)
    state = load_state(model.name)
    n = len(state["numbers"]) // model.sites
    masses = np.tile(model.masses(), n)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rec = Recorder(args, n, model.sites, masses, state["cell"])
    rec.meta.update({k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                     if k != "command"})
    rec.meta.update(model=model.name, molecules=n, sites=model.sites,
                    temperature_K=TEMPERATURE_K, ke_fs=KE_FS,
                    u_fs=KE_FS if args.code == "rigidmd" else U_OMM_FS, frame_fs=FRAME_FS)

    def stop(signum, frame):
        raise SystemExit(f"signal {signum}")

    signal.signal(signal.SIGTERM, stop)
    stopped = None
    try:
        (run_rigidmd if args.code == "rigidmd" else run_openmm)(args, state, model, deadline,
                                                                 rec)
    except (SystemExit, KeyboardInterrupt) as why:
        stopped = str(why) or "interrupted"
    finally:
        rec.save(final=True)
    m = rec.meta
    print(f"{args.out.name}: {m.get('ps', 0):.1f} ps recorded after {m.get('skip_ps', 0):.1f} "
          f"ps, {m.get('ms_per_step', 0):.2f} ms/step"
          + (f"; stopped ({stopped}), what it had is written" if stopped else ""), flush=True)
    if stopped:
        raise SystemExit(1)


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true",
                   help="two runs of a few seconds (rigidmd and OpenMM) and their report in "
                        "--outdir: checks the pipeline, no results")
    p.add_argument("--outdir", type=Path, default=HERE)
    sub = p.add_subparsers(dest="command")
    r = sub.add_parser("run", help="one run")
    r.add_argument("--code", choices=("rigidmd", "openmm"), required=True)
    r.add_argument("--thermo", choices=("langevin", "bussi", "middle", "leapfrog", "andersen"),
                   required=True, help="rigidmd: langevin, bussi; OpenMM: middle, leapfrog, "
                   "andersen")
    r.add_argument("--tau-ps", type=float, default=1.0,
                   help="1/friction (Langevin), Bussi's τ, 1/collision frequency (ps)")
    r.add_argument("--fixcm", type=int, default=1, help="rigidmd Bussi's fixcm (0 or 1)")
    r.add_argument("--dt-fs", type=float, required=True)
    r.add_argument("--seed", type=int, default=1)
    r.add_argument("--model", default="tip4pew", choices=("tip4pew", "tip4p2005", "spce"))
    r.add_argument("--budget-s", type=float, required=True,
                   help="wall seconds from the process's start to its last step")
    r.add_argument("--skip-ps", type=float, default=10.0, help="ps made before recording")
    r.add_argument("--skip-frac", type=float, default=0.25,
                   help="at most this fraction of the budget goes to --skip-ps")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out (else refused)")
    s = sub.add_parser("report", help="pool and analyse runs")
    s.add_argument("files", nargs="+", type=existing_file)
    s.add_argument("--name", default="water_openmm_long")
    st = sub.add_parser("starts", help="make the TIP4P/2005 and SPC/E start states")
    st.add_argument("--eq-ps", type=float, default=5.0)
    args = p.parse_args(argv)
    if args.command is None and not args.quick:
        p.error("give run, report or starts (or --quick)")
    if args.command == "run" and args.out.exists() and not args.overwrite:
        p.error(f"argument --out: {args.out} exists (another run's; --overwrite replaces it)")
    if args.command == "report":
        seen = {}
        for path in args.files:
            if path.resolve() in seen:
                p.error(f"argument files: {path} given twice (as {seen[path.resolve()]}): "
                        "a run pooled twice")
            seen[path.resolve()] = path
    return args


def main(argv=None):
    args = parse(argv)
    if args.quick:
        global FRAME_FS, PIECE_PS, MSD_FIT_PS
        FRAME_FS, PIECE_PS, MSD_FIT_PS = 100.0, 0.2, (0.2, 0.4)  # series of a few ps
        args.outdir.mkdir(parents=True, exist_ok=True)
        files = []
        for code, thermo in (("rigidmd", "langevin"), ("openmm", "middle")):
            out = args.outdir / f"water_openmm_long_quick_{code}.npz"
            global T0
            T0 = time.perf_counter()
            run_main(parse(["run", "--code", code, "--thermo", thermo, "--dt-fs", "2",
                            "--budget-s", "10", "--skip-ps", "0", "--out", str(out),
                            "--overwrite"]))
            files.append(out)
        return report(files, args.outdir, "water_openmm_long_quick")
    if args.command == "run":
        return run_main(args)
    if args.command == "report":
        return report(args.files, args.outdir, args.name)
    return make_starts(args.eq_ps)


if __name__ == "__main__":
    main()
