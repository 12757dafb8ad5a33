r"""The time-step table's runs: rigid water's ⟨U⟩, temperatures, RDF peak and D against the step.

One run is one point: a code and integrator, a water model and size, a step, a seed and a
length, started from the model's shared thermal state.  It writes one JSON of results
(``<name>.json``) beside its series (``<name>.series.npz``) and its checkpoint
(``<name>.chk.npz``, rigidmd's own checkpoint; OpenMM's checkpoint in ``<name>.chk.omm``),
with the record of its arguments (``<name>.arguments``, checked by ``--resume``) and, while it
runs, its claim on the point (``<name>.claim``: a second run of the point into the same
``--outdir`` is refused):

- ⟨U⟩/N (kJ/mol) with a block-average error (``--blocks`` blocks of the recorded part);
- T_tr and T_rot as each code reports them (rigidmd: ``dyn.get_kinetic_temperatures()``,
  which for ``RigidLangevinBAOAB`` are the momenta right after its O step; the end-of-step
  values beside them as ``T_tr_end``, ``T_rot_end``); OpenMM's from its atom velocities
  (for ``LangevinMiddleIntegrator`` those after its O step); LAMMPS's from its frames'
  velocities;
- the O–O RDF's first peak (position, height) over the recorded frames;
- D_PBC from the centre-of-mass MSD (the box's drift removed, a straight line over the
  lags ``--msd-fit-ps``, or a tenth to a third of the run when shorter);
- ``T_conf_tr``, ``T_conf_rot``: the configurational temperatures of translation and
  rotation, every ``--tconf-frames``-th frame, ``2 * --tconf-probes`` force calls a sample
  (``--tconf-frames 0`` leaves them null): rigidmd's from its own state
  (:func:`configurational_sampler`), LAMMPS's and OpenMM's from their frames' positions
  with LAMMPS's forces of the same model (:class:`FrameConfigurational`).

Codes (``--code``): ``rigidmd`` with ``--integrator langevin`` (:class:`rigidmd.RigidLangevin`),
``baoab`` (:class:`rigidmd.RigidLangevinBAOAB`), ``bussi`` (:class:`rigidmd.RigidBussi`),
``nosehoover`` (:class:`rigidmd.RigidNoseHoover`), forces from LAMMPS in-process
(``lj/cut/coul/long``, PPPM 1e-5, the tail correction); ``lammps``: ``fix rigid/nvt/small``
(:func:`rigidmd.lammps.reference.run_rigid_reference`, in pieces of ``--piece-ps``: each
piece starts from the last frame, its Nosé–Hoover chain from rest); ``openmm``:
``LangevinMiddleIntegrator`` with SETTLE (TIP4P/2005 from its own file ``tip4p2005.xml``
beside this script, SPC/E from OpenMM's ``spce.xml``; PME 1e-5).  Friction 1/ps for the
Langevin schemes, τ = ``--tau-ps`` for Bussi and the Nosé–Hoover chains.  Every code uses
the cut-off ``min(9 Å, 0.49 L)``.

Start states: 216 waters are ``water_openmm_long.start_<model>.npz`` (committed); other
sizes are made by ``start`` (TIP4P-Ew quenched and equilibrated as
``water_openmm_nve.equilibrated_state``, rebuilt as the model, 5 ps of Bussi) into
``timestep_table.start_<model>_<n>.npz``, deterministic for a seed.

A run prints progress (a line on a terminal, a log line a minute otherwise), stops on
SIGTERM or SIGINT at the end of the sample interval it is in (at most ``--sample-fs``;
LAMMPS: of the piece it is in) and writes what it has (its JSON says
``"complete": false``), and ``--resume`` continues it from its checkpoint.  ``--jobs N``
runs the points of several values (``--dt-fs 1 2 4 --seed 1 2 3``) in N processes.

Run::

    python validation/timestep_table.py run --code rigidmd --integrator langevin baoab \
        bussi nosehoover --dt-fs 0.5 1 2 3 4 5 --seed 1 2 3 --ps 200 --jobs 16 \
        --outdir validation/timestep_runs
    python validation/timestep_table.py run --code lammps openmm --dt-fs 0.5 1 2 3 4 5 \
        --seed 1 2 3 --ps 200 --jobs 16 --outdir validation/timestep_runs
    python validation/timestep_table.py run ... --resume      # continue the stopped ones
    python validation/timestep_table_report.py validation/timestep_runs/*.json \
        --name timestep_table
    python validation/timestep_table.py cost --waters 216     # ms/step of every code here
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from arguments import at_least_zero, existing_file, positive, read_json, whole  # noqa: E402
from children import ends_with_parent  # noqa: E402

TEMPERATURE_K = 298.0
KB_KJ = 0.0083144626  # kJ/mol/K
CUTOFF = 9.0  # Å, or 0.49 of the box when smaller
FRICTION_PER_PS = 1.0
INTEGRATORS = ("langevin", "baoab", "bussi", "nosehoover")
CODES = ("rigidmd", "lammps", "openmm")
MODELS = ("tip4p2005", "spce")
#: Every result a run's JSON holds (the collector reads these).
RESULT_FIELDS = ("U", "T_tr", "T_rot", "T_tr_end", "T_rot_end", "T_tr_gap", "T_rot_gap",
                 "rdf_peak_r", "rdf_peak_g", "D_pbc", "T_conf_tr", "T_conf_rot")


# --------------------------------------------------------------------------- start states
def start_file(model_name, waters):
    if waters == 216:
        return HERE / f"water_openmm_long.start_{model_name}.npz"
    return HERE / f"timestep_table.start_{model_name}_{waters}.npz"


def make_start(model_name, waters, seed=1, eq_ps=5.0):
    """The start state of ``waters`` molecules of ``model_name`` (see the module docstring)."""
    from ase import units
    from water_openmm_long import rebuild
    from water_openmm_nve import equilibrated_state, state_at_rest

    from rigidmd import RigidBussi
    from rigidmd.water import water_model

    if waters == 216:  # the committed start every 216-water study shares
        raise SystemExit(f"--waters 216: the start is {start_file(model_name, 216).name}, made "
                         f"by 'water_openmm_long.py starts'; this makes other sizes")
    n_side = round(waters ** (1 / 3))
    if n_side ** 3 != waters:
        raise SystemExit(f"--waters {waters}: a start is made for a cube number of waters")
    model = water_model(model_name)
    state = rebuild(equilibrated_state(n_side, seed, eq_ps), water_model("tip4pew"), model)
    atoms = make_atoms(state, model)
    RigidBussi(atoms, 2 * units.fs, temperature_K=TEMPERATURE_K, taut=100 * units.fs,
               rng=np.random.default_rng(seed), fixcm=True).run(int(round(eq_ps * 500)))
    out = state_at_rest(atoms, model.sites)
    np.savez(start_file(model_name, waters), seed=seed, eq_ps=eq_ps, **out)
    if hasattr(atoms.calc, "close"):
        atoms.calc.close()
    return start_file(model_name, waters)


def load_start(model_name, waters):
    path = start_file(model_name, waters)
    if not path.exists():
        raise SystemExit(f"no start state {path.name}: make it with 'timestep_table.py start "
                         f"--model {model_name} --waters {waters}'")
    with np.load(path) as d:
        state = {k: d[k] for k in ("positions", "momenta", "cell", "numbers")}
    return state


#: Integrators whose runs draw no random numbers: their seeds differ by the start's momenta.
DETERMINISTIC = {("lammps", "nvt_small"), ("rigidmd", "nosehoover")}


def start_for(p):
    """The start of point ``p``: the model's shared state (:func:`load_start`); for an
    integrator that draws no random numbers (:data:`DETERMINISTIC`) and a seed other than 1,
    its momenta drawn again (rigid Maxwell–Boltzmann at 298 K from ``3000 + seed``, the
    centre of mass at rest), or its seeds would be one run repeated."""
    state = load_start(p["model"], p["waters"])
    if (p["code"], p["integrator"]) not in DETERMINISTIC or p["seed"] == 1:
        return state
    from water_openmm_nve import state_atoms

    from rigidmd import rigid_maxwell_boltzmann
    from rigidmd.water import water_model

    model = water_model(p["model"])
    atoms = state_atoms(state, model, cutoff_for(state["cell"]))
    atoms.set_tags(np.repeat(np.arange(1, len(atoms) // model.sites + 1), model.sites))
    rigid_maxwell_boltzmann(atoms, TEMPERATURE_K, bodies="tags",
                            rng=np.random.default_rng(3000 + p["seed"]))
    masses, momenta = atoms.get_masses(), atoms.get_momenta()
    momenta -= masses[:, None] * (momenta.sum(axis=0) / masses.sum())
    return dict(state, momenta=momenta)


def cutoff_for(cell):
    return min(CUTOFF, 0.49 * float(np.min(np.diag(cell))))


def make_atoms(state, model, skin=2.0):
    """``state``'s atoms with LAMMPS's forces for ``model`` (neighbour ``skin``, Å), one body
    per molecule."""
    from water_openmm_nve import lammps_calculator, state_atoms

    atoms = state_atoms(state, model, cutoff_for(state["cell"]))
    atoms.calc = lammps_calculator(model, cutoff_for(state["cell"]), skin)
    n = len(atoms) // model.sites
    atoms.set_tags(np.repeat(np.arange(1, n + 1), model.sites))
    return atoms


# --------------------------------------------------------------------------- one run
class Stop:
    """SIGTERM and SIGINT ask the run to stop at the end of its sample interval.

    The handlers stay for the process (a run's own); as a context manager (a run inside
    another program, as ``measure_ms``'s) it hands the previous ones back at the end.
    """

    def __init__(self):
        self.signal = None
        self.previous = {sig: signal.signal(sig, self._handle)
                         for sig in (signal.SIGTERM, signal.SIGINT)}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        return False

    def _handle(self, signum, frame):
        self.signal = signal.Signals(signum).name

    def __bool__(self):
        return self.signal is not None


class Progress:
    """A line on a terminal (rewritten), a log line every ``every_s`` otherwise (also on a
    terminal that several runs share: ``shared``)."""

    def __init__(self, name, total_ps, every_s=60.0, shared=False):
        self.name, self.total, self.every = name, total_ps, every_s
        self.tty = sys.stderr.isatty() and not shared
        self.last = time.perf_counter()
        self.t0, self.ps0 = self.last, None

    def begin(self, ps):
        """The run starts (or continues) at ``ps``: the rate counts from here."""
        self.t0, self.ps0 = time.perf_counter(), ps

    def __call__(self, ps, force=False):
        now = time.perf_counter()
        if self.ps0 is None:  # without begin(): from the first report
            self.t0, self.ps0 = now, ps
        if not force and now - self.last < (1.0 if self.tty else self.every):
            return
        self.last = now
        rate = (ps - self.ps0) / max(now - self.t0, 1e-9) * 86400 / 1000  # ns/day
        line = f"{self.name}: {ps:.2f} / {self.total:g} ps ({rate:.2f} ns/day)"
        if self.tty:
            print("\r" + line, end="\n" if force else "", file=sys.stderr, flush=True)
        else:
            print(time.strftime("%H:%M:%S ") + line, flush=True)


def run_name(p):
    split = (f"_k{p['substeps']}r{p['r_split']:g}" if p.get("substeps", 1) > 1 else "")
    return (f"{p['model']}_{p['waters']}_{p['code']}_{p['integrator']}_dt{p['dt_fs']:g}"
            f"{split}_s{p['seed']}")


class Series:
    """A run's samples: ``t_ps``, ``U`` (kJ/mol, whole system), ``T_tr``, ``T_rot``,
    ``T_tr_end``, ``T_rot_end`` (K) every ``sample_fs``; ``frame_t_ps``, ``O`` and ``com``
    (Å, unwrapped from frame to frame) and ``conf`` (:func:`configurational_temperatures`'
    four sums, nan where it gave none) every ``frame_fs``."""

    KEYS = ("t_ps", "U", "T_tr", "T_rot", "T_tr_end", "T_rot_end")

    def __init__(self, path):
        self.path = path
        self.rec = {k: [] for k in self.KEYS}
        self.frames = {"frame_t_ps": [], "O": [], "com": [], "conf": []}

    def load(self, samples, frames):
        """The series as saved, cut to what the checkpoint had recorded."""
        with np.load(self.path) as d:
            for k in self.KEYS:
                self.rec[k] = list(d[k][:samples])
            for k in self.frames:
                self.frames[k] = list(d[k][:frames]) if k in d.files else \
                    [np.full(4, np.nan)] * min(frames, len(d["frame_t_ps"]))

    def add(self, t_ps, U, T, T_end):
        for k, v in zip(self.KEYS, (t_ps, U, *T, *T_end), strict=True):
            self.rec[k].append(float(v))

    def frame(self, t_ps, O, com, cell, conf=None):
        box = np.diag(cell)
        if self.frames["com"]:  # unwrap from the previous frame (moves ≪ L/2 between frames)
            O = self.frames["O"][-1] + _minimage(O - self.frames["O"][-1], box)
            com = self.frames["com"][-1] + _minimage(com - self.frames["com"][-1], box)
        self.frames["frame_t_ps"].append(t_ps)
        self.frames["O"].append(np.asarray(O, dtype=float))
        self.frames["com"].append(np.asarray(com, dtype=float))
        self.frames["conf"].append(np.full(4, np.nan) if conf is None
                                   else np.asarray(conf, dtype=float))

    def counts(self):
        return len(self.rec["t_ps"]), len(self.frames["com"])

    def save(self):
        arrays = {k: np.asarray(v, dtype=float) for k, v in self.rec.items()}
        arrays.update({k: np.asarray(v, dtype=float) for k, v in self.frames.items()})
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        np.savez(tmp, **arrays)
        os.replace(tmp, self.path)


def _minimage(d, box):
    return d - box * np.round(d / box)


def molecule_centres(positions, masses, sites, cell):
    """O positions and centres of mass (whole molecules made around O), Å."""
    x = positions.reshape(-1, sites, 3)
    box = np.diag(cell)
    x = x[:, :1] + _minimage(x - x[:, :1], box)
    m = masses.reshape(-1, sites)[0]
    return x[:, 0].copy(), np.einsum("s,bsk->bk", m, x) / m.sum()


def intramolecular_energy(model, calc):
    """The constant in LAMMPS's energy of rigid molecules, kJ/mol per molecule.

    The pair style leaves a molecule's own pairs out but the k-space sum has them
    (:func:`rigidmd.mdanalysis.thermo.excluded_kspace_energy` at the calculator's pinned
    Ewald parameter); ⟨U⟩/N is given without it.
    """
    from ase import units

    from rigidmd.mdanalysis.thermo import ewald_parameter, excluded_kspace_energy

    return excluded_kspace_energy(model, ewald_parameter(calc)) / (units.kJ / units.mol)


def coulomb_energy(model):
    """A molecule's own Coulomb energy, kJ/mol: the constant in the energy of
    :func:`~rigidmd.lammps.reference.run_rigid_reference`'s runs, whose pair list keeps a
    molecule's own pairs (``erf(g r) → 1`` in :func:`intramolecular_energy`'s sum)."""
    from ase import units

    from rigidmd.mdanalysis.thermo import excluded_kspace_energy

    return excluded_kspace_energy(model, 1e6) / (units.kJ / units.mol)


def configurational_sampler(p, dyn, model, cell):
    """The run's configurational-temperature observer, or None with ``--tconf-frames 0``.

    A :class:`rigidmd.core.configurational.ConfigurationalTemperature` with a LAMMPS
    calculator of its own (the same interactions; so the trajectory is the unobserved one
    bit for bit) and its own random numbers (seed ``2000 + seed``: a sample's probes depend
    on that and its step alone, so a resumed run samples as an uninterrupted one), sampled
    at every ``tconf_frames``-th frame.  Cost: ``2 * tconf_probes`` force calls a sample (8 by
    default; at the default frame of 200 fs and every second frame, 8 calls per 400 fs:
    8 % more calls at 4 fs, 1 % at 0.5 fs).
    """
    if not p.get("tconf_frames", 0):
        return None
    from water_openmm_nve import lammps_calculator

    from rigidmd.core.configurational import ConfigurationalTemperature

    return ConfigurationalTemperature(dyn, probes=p.get("tconf_probes", 4),
                                      rng=2000 + p["seed"],
                                      calculator=lammps_calculator(model, cutoff_for(cell)))


class FrameConfigurational:
    """The configurational temperatures of another code's frames (LAMMPS, OpenMM).

    Each call takes a frame's positions (Å, every site, OpenMM's massless M site
    included; a molecule may be broken across the box), fits the rigid bodies (a
    :class:`rigidmd.RigidVerlet` that never steps) and takes one sample of
    :class:`rigidmd.core.configurational.ConfigurationalTemperature` with a LAMMPS calculator
    of the model (PPPM 1e-5 at the run's cut-off, the same as rigidmd's runs) and the
    probes' random numbers from ``2000 + seed``.  For an OpenMM run that measures how
    Boltzmann-distributed its configurations are under LAMMPS's forces of the same model:
    PME and PPPM at 1e-5 part by about 1e-5 of a force, and neither's truncated
    Lennard-Jones (with its tail correction, which adds no force) differs.  A sample's
    probes come from ``(2000 + seed, step)``, as rigidmd's own sampler draws them at that
    step, so a resumed run samples as an uninterrupted one.  The run's own
    trajectory is untouched: the frames are copies.  Cost: ``2 * tconf_probes + 1`` force
    calls and a body fit a sample.
    """

    def __init__(self, p, model, state):
        from water_openmm_nve import lammps_calculator

        self.p, self.model, self.state = p, model, state
        self.calc = lammps_calculator(model, cutoff_for(state["cell"]))

    def __call__(self, positions, step):
        """The sums ``(Σ|F|², Σ∇²U, Σ|τ|², Σ𝓛²U)`` at ``positions`` (shape (n_sites, 3), Å),
        the run's step ``step``."""
        from ase import Atoms, units

        from rigidmd import RigidVerlet
        from rigidmd.core.configurational import ConfigurationalTemperature

        sites, cell = self.model.sites, self.state["cell"]
        n = len(positions) // sites
        atoms = Atoms(numbers=self.state["numbers"], positions=positions, cell=cell, pbc=True,
                      masses=np.tile(self.model.masses(), n),
                      charges=self.model.charges(n), tags=np.repeat(np.arange(1, n + 1), sites))
        atoms.calc = self.calc
        dyn = RigidVerlet(atoms, units.fs)
        rng = np.random.default_rng((2000 + self.p["seed"], int(step)))
        sampler = ConfigurationalTemperature(dyn, probes=self.p.get("tconf_probes", 4),
                                             rng=rng, calculator=self.calc)
        return sampler.sample()[:4]

    def due(self, frame):
        """Whether frame number ``frame`` (from 0) is sampled (every ``tconf_frames``-th)."""
        every = self.p.get("tconf_frames", 0)
        return bool(every) and frame % every == 0

    def close(self):
        if hasattr(self.calc, "close"):
            self.calc.close()


def frame_sampler(p, model, state):
    """:class:`FrameConfigurational` for ``p``, or None with ``--tconf-frames 0``."""
    return FrameConfigurational(p, model, state) if p.get("tconf_frames", 0) else None


def configurational_temperatures(sampler):
    """One sample's sums ``(Σ|F|², Σ∇²U, Σ|τ|², Σ𝓛²U)`` (eV²/Å², eV/Å², eV², eV) of the
    current state, or None without a sampler (the frame's T_conf columns then stay nan, and
    the run's JSON holds null: never an estimate made otherwise)."""
    if sampler is None:
        return None
    return sampler.sample()[:4]


def _rigidmd_dynamics(p, atoms):
    from ase import units

    import rigidmd

    dt = p["dt_fs"] * units.fs
    rng = np.random.default_rng(1000 + p["seed"])
    friction = FRICTION_PER_PS * 1e-3 / units.fs
    tau = p["tau_ps"] * 1000 * units.fs
    if p["integrator"] == "langevin":
        return rigidmd.RigidLangevin(atoms, dt, temperature_K=TEMPERATURE_K, friction=friction,
                                     rng=rng, fixcm=True)
    if p["integrator"] == "baoab":
        return rigidmd.RigidLangevinBAOAB(atoms, dt, temperature_K=TEMPERATURE_K,
                                          friction=friction, rng=rng, fixcm=True)
    if p["integrator"] == "bussi":
        return rigidmd.RigidBussi(atoms, dt, temperature_K=TEMPERATURE_K, taut=tau, rng=rng,
                                  fixcm=True)
    return rigidmd.RigidNoseHoover(atoms, dt, temperature_K=TEMPERATURE_K, tdamp=tau,
                                   fixcm=True)


def rigidmd_calculator(p, model, cell):
    """The model's LAMMPS forces; with ``substeps`` above 1, r-RESPA's split of them: a fast
    level ``lammps_short_range_commands(r_split)`` and the slow level the model less it
    (``dt_fs`` is then the outer step).  Every level's neighbour skin is ``p["skin"]`` (Å;
    LAMMPS's metal default of 2 when absent: it changes the cost, not the forces)."""
    from water_openmm_nve import lammps_calculator

    skin = p.get("skin", 2.0)
    full = lammps_calculator(model, cutoff_for(cell), skin)
    if p.get("substeps", 1) <= 1:
        return full
    from rigidmd import MultipleTimeStep
    from rigidmd.lammps import LAMMPSCalculator

    fast = LAMMPSCalculator(model.lammps_short_range_commands(p["r_split"]),
                            atom_types=full.atom_types, skin=skin)
    return MultipleTimeStep(fast, full=full, substeps=p["substeps"])


def run_rigidmd(p, paths, stop, progress, resume):
    """Run (or continue) one rigidmd point; returns (series, steps done, ms/step)."""
    from ase import units

    from rigidmd import load_checkpoint
    from rigidmd.core.checkpoint import save_checkpoint
    from rigidmd.core.observables import kinetic_dof, kinetic_temperatures
    from rigidmd.water import water_model

    model = water_model(p["model"])
    state = start_for(p)
    series = Series(paths["series"])
    if resume and paths["chk"].exists():
        from rigidmd.core.checkpoint import read_checkpoint

        chk = read_checkpoint(paths["chk"])
        dyn = load_checkpoint(chk, rigidmd_calculator(p, model, state["cell"]))
        series.load(chk.extra["samples"], chk.extra["frames"])
    else:
        atoms = make_atoms(state, model, p.get("skin", 2.0))
        if p.get("substeps", 1) > 1:
            atoms.calc = rigidmd_calculator(p, model, state["cell"])
        dyn = _rigidmd_dynamics(p, atoms)
    atoms = dyn.atoms
    kj = units.kJ / units.mol
    sample = max(int(round(p["sample_fs"] / p["dt_fs"])), 1)
    frame_every = max(int(round(p["frame_fs"] / p["sample_fs"])), 1)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))
    dof = kinetic_dof(dyn.model, dyn.holds_momentum)
    masses = atoms.get_masses()
    conf = configurational_sampler(p, dyn, model, state["cell"])

    def observe():
        step = dyn.nsteps
        if series.counts()[0] and series.rec["t_ps"][-1] >= step * p["dt_fs"] / 1000:
            return  # a resumed run's first call: this step is recorded
        series.add(step * p["dt_fs"] / 1000, atoms.get_potential_energy() / kj,
                   dyn.get_kinetic_temperatures(),
                   kinetic_temperatures(dyn.get_translational_kinetic_energy(),
                                        dyn.get_rotational_kinetic_energy(), dof))
        if (step // sample) % frame_every == 0:
            frame = step // (sample * frame_every)
            due = conf is not None and frame % p.get("tconf_frames", 1) == 0
            series.frame(step * p["dt_fs"] / 1000,
                         *molecule_centres(atoms.positions, masses, model.sites,
                                           atoms.cell.array), atoms.cell.array,
                         configurational_temperatures(conf if due else None))

    def save():
        samples, frames = series.counts()
        series.save()
        save_checkpoint(dyn, paths["chk"], extra={"samples": samples, "frames": frames})

    # An observer due at a step gets the energy from the step's own force call.
    dyn.attach(observe, interval=sample)
    ms, s0 = run_in_pieces(dyn, total, sample, stop, progress, p, save)
    steps = dyn.nsteps
    atoms.get_potential_energy()
    offset = intramolecular_energy(model, getattr(atoms.calc, "full", None) or atoms.calc)
    for calc in (atoms.calc, getattr(conf, "calculator", None)):
        if hasattr(calc, "close"):
            calc.close()
    return series, steps, ms, offset, s0


def run_in_pieces(dyn, total, piece, stop, progress, p, save):
    """Run ``dyn`` to step ``total`` in pieces of ``piece`` steps until ``stop``: progress
    after each piece, ``save()`` every ``p["save_s"]`` seconds and at the end.  Returns the
    wall ms per step and the step it started from."""
    last_save = time.perf_counter()
    t0, s0 = time.perf_counter(), dyn.nsteps
    progress.begin(s0 * p["dt_fs"] / 1000)
    while dyn.nsteps < total and not stop:
        dyn.run(min(piece, total - dyn.nsteps))
        progress(dyn.nsteps * p["dt_fs"] / 1000)
        if time.perf_counter() - last_save > p["save_s"]:
            save()
            last_save = time.perf_counter()
    ms = 1000 * (time.perf_counter() - t0) / max(dyn.nsteps - s0, 1)
    save()
    return ms, s0


def run_openmm(p, paths, stop, progress, resume):
    """Run (or continue) OpenMM's ``LangevinMiddleIntegrator`` with SETTLE."""
    import openmm
    from openmm import unit
    from water_openmm_nve import body_kinetic_energies, openmm_context

    from rigidmd.water import water_model

    model = water_model(p["model"])
    state = load_start(p["model"], p["waters"])
    system = openmm_water_system(state, model, cutoff_for(state["cell"]))
    integrator = openmm.LangevinMiddleIntegrator(TEMPERATURE_K, FRICTION_PER_PS,
                                                 p["dt_fs"] * 1e-3)
    integrator.setRandomNumberSeed(1000 + p["seed"])
    context, masses, v = openmm_context(system, integrator, state)
    series = Series(paths["series"])
    meta_path = paths["chk"].with_name(paths["chk"].name + ".meta")
    if resume and paths["chk"].exists() and meta_path.exists():
        context.loadCheckpoint(paths["chk"].read_bytes())
        extra = json.loads(meta_path.read_text())
        held = context.getStepCount()
        if held != extra["steps"]:  # killed between the checkpoint and its record
            raise SystemExit(f"{paths['chk']}: holds step {held}, its record {meta_path.name} "
                             f"step {extra['steps']} (stopped between the two writes); remove "
                             "the run's files to start it again")
        series.load(extra["samples"], extra["frames"])
        steps = extra["steps"]
    else:
        context.setVelocities(v)
        context.applyVelocityConstraints(1e-10)
        steps = 0
    sample = max(int(round(p["sample_fs"] / p["dt_fs"])), 1)
    frame_every = max(int(round(p["frame_fs"] / p["sample_fs"])), 1)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))
    n = len(masses) // model.sites
    cell = state["cell"]
    conf = frame_sampler(p, model, state)

    def observe():
        st = context.getState(getPositions=True, getVelocities=True, getEnergy=True)
        x = st.getPositions(asNumpy=True).value_in_unit(unit.nanometer)
        vel = st.getVelocities(asNumpy=True).value_in_unit(unit.nanometer / unit.picosecond)
        kt, kr = body_kinetic_energies(x, vel, masses, model.sites)
        T = (2 * kt / ((3 * n - 3) * KB_KJ), 2 * kr / (3 * n * KB_KJ))
        series.add(steps * p["dt_fs"] / 1000,
                   st.getPotentialEnergy().value_in_unit(unit.kilojoule_per_mole), T,
                   (np.nan, np.nan))
        if (steps // sample) % frame_every == 0:
            x = np.asarray(x) * 10
            due = conf is not None and conf.due(steps // (sample * frame_every))
            series.frame(steps * p["dt_fs"] / 1000,
                         *molecule_centres(x, masses, model.sites, cell), cell,
                         conf(x, steps) if due else None)

    def save():
        samples, frames = series.counts()
        series.save()
        tmp = paths["chk"].with_name(paths["chk"].name + ".tmp")
        tmp.write_bytes(context.createCheckpoint())
        os.replace(tmp, paths["chk"])
        record = meta_path.with_name(meta_path.name + ".tmp")
        record.write_text(json.dumps({"samples": samples, "frames": frames, "steps": steps}))
        os.replace(record, meta_path)

    if steps == 0:
        observe()
    last_save = time.perf_counter()
    t0, s0 = time.perf_counter(), steps
    progress.begin(s0 * p["dt_fs"] / 1000)
    while steps < total and not stop:
        k = min(sample, total - steps)
        integrator.step(k)
        steps += k
        if steps % sample == 0:
            observe()
        progress(steps * p["dt_fs"] / 1000)
        if time.perf_counter() - last_save > p["save_s"]:
            save()
            last_save = time.perf_counter()
    ms = 1000 * (time.perf_counter() - t0) / max(steps - s0, 1)
    save()
    if conf is not None:
        conf.close()
    return series, steps, ms, 0.0, s0


def openmm_water_system(state, model, cutoff):
    """OpenMM's system for ``state`` at ``cutoff`` (Å): PME 1e-5, the dispersion correction,
    rigid water, rigidmd's masses.  TIP4P/2005 from its own file ``tip4p2005.xml`` (beside
    this script; OpenMM ships none), the others from OpenMM's
    (``water_openmm_nve.openmm_system``)."""
    import openmm
    from openmm import app, unit
    from water_openmm_nve import openmm_system

    if model.name != "tip4p2005":
        return openmm_system(state, model, cutoff)
    from rigidmd.openmm import water_topology

    n = len(state["numbers"]) // model.sites
    system = app.ForceField(str(HERE / "tip4p2005.xml")).createSystem(
        water_topology(model, n, state["cell"]), nonbondedMethod=app.PME,
        nonbondedCutoff=cutoff / 10 * unit.nanometer, rigidWater=True,
        ewaldErrorTolerance=1e-5)
    for force in system.getForces():
        if isinstance(force, openmm.NonbondedForce):
            force.setUseDispersionCorrection(True)
    for i, m in enumerate(np.tile(model.masses(), n)):
        system.setParticleMass(i, float(m))
    return system


def run_lammps(p, paths, stop, progress, resume):
    """LAMMPS ``fix rigid/nvt/small`` in pieces of ``piece_ps`` (each from the last frame)."""
    from ase import units
    from water_openmm_nve import body_kinetic_energies

    from rigidmd.lammps.reference import run_rigid_reference
    from rigidmd.water import water_model

    to_nm_ps = units.fs * 100.0  # Å per ASE time unit to nm/ps (amu nm²/ps² is kJ/mol)

    model = water_model(p["model"])
    state = start_for(p)
    cutoff = cutoff_for(state["cell"])
    series = Series(paths["series"])
    chk = paths["chk"].with_name(paths["chk"].name + ".meta")
    steps = 0
    if resume and chk.exists():
        saved = json.loads(chk.read_text())
        with np.load(paths["chk"]) as d:
            state = dict(state, positions=d["positions"], momenta=d["momenta"])
            if "steps" in d:  # the record inside the checkpoint: written with it, at once
                saved = {key: int(d[key]) for key in ("samples", "frames", "steps")}
        series.load(saved["samples"], saved["frames"])
        steps = saved["steps"]
    sample = max(int(round(p["sample_fs"] / p["dt_fs"])), 1)
    frame_every = max(int(round(p["frame_fs"] / p["sample_fs"])), 1)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))
    piece = max(int(round(p["piece_ps"] * 1000 / p["dt_fs"])) // sample, 1) * sample
    kj = units.kJ / units.mol
    n = len(state["numbers"]) // model.sites
    masses = np.tile(model.masses(), n)
    conf = frame_sampler(p, model, state)
    s0, loop_s = steps, 0.0
    progress.begin(s0 * p["dt_fs"] / 1000)  # (the first piece's report had 0.00 ns/day)
    while steps < total and not stop:
        atoms = make_atoms(state, model)
        k = min(piece, total - steps)
        skin = [f"neighbor {p['skin']:g} bin"] if "skin" in p else []  # else LAMMPS's 2 Å
        ref = run_rigid_reference(
            atoms, np.repeat(np.arange(n), model.sites), model.lammps_commands(
                cutoff, "pppm", 1e-5, tail=True) + skin, p["dt_fs"] * units.fs, k, every=sample,
            fix="rigid/nvt/small", temperature_K=TEMPERATURE_K,
            tdamp=p["tau_ps"] * 1000 * units.fs, seed=1000 + p["seed"] + steps)
        loop_s += ref.timing.get("loop_time", float("nan"))
        first = 1 if steps else 0
        for f in range(first, len(ref.step)):
            x, v = ref.positions[f], ref.velocities[f]
            kt, kr = body_kinetic_energies(x / 10, v * to_nm_ps, masses, model.sites)
            t = (steps + ref.step[f]) * p["dt_fs"] / 1000
            series.add(t, ref.potential_energy[f] / kj,
                       (2 * kt / ((3 * n - 3) * KB_KJ), 2 * kr / (3 * n * KB_KJ)),
                       (np.nan, np.nan))
            if ((steps + ref.step[f]) // sample) % frame_every == 0:
                due = conf is not None and conf.due((steps + ref.step[f])
                                                    // (sample * frame_every))
                series.frame(t, *molecule_centres(x, masses, model.sites, state["cell"]),
                             state["cell"], conf(x, steps + ref.step[f]) if due else None)
        steps += k
        state = dict(state, positions=ref.positions[-1], momenta=ref.velocities[-1]
                     * masses[:, None])
        samples, frames = series.counts()
        series.save()
        # The checkpoint carries its own record (a kill between two files left the record
        # of the step before: 0.4 ps skipped on --resume), written whole or not at all.
        tmp = paths["chk"].with_name(paths["chk"].name + ".tmp.npz")
        np.savez(tmp, positions=state["positions"], momenta=state["momenta"],
                 samples=samples, frames=frames, steps=steps)
        os.replace(tmp, paths["chk"])
        record = chk.with_name(chk.name + ".tmp")
        record.write_text(json.dumps({"samples": samples, "frames": frames, "steps": steps}))
        os.replace(record, chk)
        progress(steps * p["dt_fs"] / 1000)
    if conf is not None:
        conf.close()
    # LAMMPS's own loop (its start, the data file and the dump's parsing left out)
    ms = 1000 * loop_s / max(steps - s0, 1) if steps > s0 else float("nan")
    return series, steps, ms, coulomb_energy(model), s0


# --------------------------------------------------------------------------- analysis
def block_mean(x, blocks):
    """Mean and the standard error of ``blocks`` block means (nan with fewer than 2)."""
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return [float("nan"), float("nan")]
    parts = [b.mean() for b in np.array_split(x, min(blocks, len(x))) if len(b)]
    err = float(np.std(parts, ddof=1) / np.sqrt(len(parts))) if len(parts) > 1 else np.nan
    return [float(x.mean()), err]


def rdf_first_peak(O, cell, bin_A=0.02, r_max=None):
    """(r, g) of the O–O RDF's highest point below 3.5 Å over frames ``O`` (Å), a parabola
    through the highest bin and its neighbours."""
    box = np.diag(cell)
    r_max = r_max or min(0.5 * box.min(), 8.0)
    edges = np.arange(0.0, r_max + bin_A, bin_A)
    hist = np.zeros(len(edges) - 1)
    n = O.shape[1]
    iu = np.triu_indices(n, 1)
    for x in O:
        d = _minimage(x[:, None] - x[None], box)[iu]
        hist += np.histogram(np.linalg.norm(d, axis=1), edges)[0]
    r = 0.5 * (edges[1:] + edges[:-1])
    shell = 4 / 3 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    g = hist / (len(O) * n * (n - 1) / 2 / np.prod(box) * shell)
    i = int(np.argmax(np.where(r < 3.5, g, -1)))
    if 0 < i < len(g) - 1:
        a, b, c = g[i - 1], g[i], g[i + 1]
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den else 0.0
        return float(r[i] + shift * bin_A), float(b - 0.25 * (a - c) * shift)
    return float(r[i]), float(g[i])


def msd_diffusion(com, t_ps, fit):
    """D_PBC (1e-5 cm²/s): the MSD of unwrapped centres of mass, the box's drift removed, over
    every origin, a straight line over lags ``fit`` (ps) / 6."""
    if len(com) < 3:
        return float("nan")
    frame_ps = float(np.median(np.diff(t_ps)))
    lags = np.arange(max(int(round(fit[0] / frame_ps)), 1), int(round(fit[1] / frame_ps)) + 1)
    lags = lags[lags < len(com)]
    if len(lags) < 2:
        return float("nan")
    disp = com - com.mean(axis=1, keepdims=True)
    msd = [np.mean(np.sum((disp[lag:] - disp[:-lag]) ** 2, axis=2)) for lag in lags]
    return float(np.polyfit(lags * frame_ps, msd, 1)[0] / 6 * 10)


def analyse(series, p, n, offset=0.0):
    """The results of one run's series after ``equil_ps`` (see :data:`RESULT_FIELDS`);
    ``offset`` (kJ/mol per molecule) is taken off ⟨U⟩/N."""
    rec = {k: np.asarray(v, dtype=float) for k, v in series.rec.items()}
    rec["U"] = rec["U"] - n * offset
    fr = {k: np.asarray(v, dtype=float) for k, v in series.frames.items()}
    keep = rec["t_ps"] >= p["equil_ps"]
    keep_f = fr["frame_t_ps"] >= p["equil_ps"] if len(fr["frame_t_ps"]) else np.zeros(0, bool)
    out = {k: block_mean(rec[k][keep] / (n if k == "U" else 1), p["blocks"])
           for k in ("U", "T_tr", "T_rot", "T_tr_end", "T_rot_end")}
    # Reported less end-of-step, sample by sample (BAOAB's after-O against its end of step;
    # zero for the others): far less noisy than the difference of the two means.
    for k in ("T_tr", "T_rot"):
        out[f"{k}_gap"] = block_mean(rec[k][keep] - rec[f"{k}_end"][keep], p["blocks"])
    length = float(rec["t_ps"][keep][-1] - rec["t_ps"][keep][0]) if keep.sum() > 1 else 0.0
    fit = tuple(p["msd_fit_ps"]) if length >= 3 * p["msd_fit_ps"][1] else (length / 10,
                                                                             length / 3)
    cell = np.diag([p["box_A"]] * 3)
    if keep_f.sum() >= 1:
        # The peak of all frames, with the standard error of the blocks' peaks: a run's
        # scatter alone (three runs) gave limits that disagreed by 3 of their errors.
        O = fr["O"][keep_f]
        whole = rdf_first_peak(O, cell)
        parts = np.array([rdf_first_peak(b, cell)
                          for b in np.array_split(O, min(p["blocks"], len(O))) if len(b)])
        err = (np.std(parts, axis=0, ddof=1) / np.sqrt(len(parts)) if len(parts) > 1
               else [np.nan, np.nan])
        out["rdf_peak_r"], out["rdf_peak_g"] = ([float(v), float(e)]
                                                for v, e in zip(whole, err, strict=True))
    else:
        out["rdf_peak_r"] = out["rdf_peak_g"] = float("nan")
    out["D_pbc"] = msd_diffusion(fr["com"][keep_f], fr["frame_t_ps"][keep_f], fit) \
        if keep_f.sum() else float("nan")
    out["T_conf_tr"] = out["T_conf_rot"] = None
    conf = fr["conf"][keep_f] if len(fr.get("conf", [])) else np.zeros((0, 4))
    conf = conf[np.isfinite(conf).all(axis=1)]  # the frames sampled (every --tconf-frames)
    if len(conf):
        from ase import units

        for name, (num, den) in (("T_conf_tr", (0, 1)), ("T_conf_rot", (2, 3))):
            parts = [b[:, num].sum() / b[:, den].sum() / units.kB
                     for b in np.array_split(conf, min(p["blocks"], len(conf)))]
            value = conf[:, num].sum() / conf[:, den].sum() / units.kB
            err = np.std(parts, ddof=1) / np.sqrt(len(parts)) if len(parts) > 1 else np.nan
            out[name] = [float(value), float(err)]
    out.update(U_offset_per_molecule=offset, recorded_ps=length, msd_fit_ps=list(fit),
               samples=int(keep.sum()), frames=int(keep_f.sum()))
    return out


# --------------------------------------------------------------------------- command line
class Claim:
    """A point's claim on its files in ``--outdir``: ``<name>.claim``, locked (``flock``,
    exclusive) and holding the claiming process's id while the point runs, removed at the
    end.  A second run of the point into the same directory is refused (SystemExit, one
    line) before it writes anything, instead of both running and the later one's files
    replacing the earlier one's.  The lock ends with its process however it ends (SIGKILL
    too): a claim file left by a process that died is taken over, and said."""

    def __init__(self, path, name):
        self.path, self.name, self.fd = Path(path), name, None

    def _holder(self, fd):
        """The claim's ``pid host``, as it holds them (None when empty or unreadable)."""
        try:
            return os.pread(fd, 300, 0).decode().strip() or None
        except (OSError, UnicodeDecodeError):
            return None

    def __enter__(self):
        import fcntl

        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = self._holder(fd) or "?"
                os.close(fd)
                raise SystemExit(f"{self.name}: being run already (process {holder}, its claim "
                                 f"{self.path}); wait for it, stop it, or give another "
                                 "--outdir") from None
            try:  # (a claim its holder removed as this opened it: claim afresh)
                if os.fstat(fd).st_ino == os.stat(self.path).st_ino:
                    break
            except FileNotFoundError:
                pass
            os.close(fd)
        left = self._holder(fd)
        if left is not None:  # (its lock ended with its process: unheld, so not running)
            print(f"{self.name}: the claim of process {left}, which ended without removing "
                  f"it, taken over", flush=True)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)
        self.fd = fd
        return self

    def __exit__(self, *exc):
        try:
            self.path.unlink()  # (still locked: no run can claim the file being removed)
        except FileNotFoundError:
            pass
        os.close(self.fd)
        self.fd = None
        return False


def record_point(path, point):
    """Write the run's arguments ``point`` to ``path`` (``<name>.arguments``, JSON) before its
    first sample: a run killed outright leaves a checkpoint and a series but no JSON, and
    ``--resume`` checks its arguments against this record (:func:`complete_already`)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(point, indent=1) + "\n")
    os.replace(tmp, path)


def complete_already(path, name, resume, point=None, checkpoint=None, record=None):
    """Whether the run whose JSON is ``path`` is complete (said in a line).

    Refused (SystemExit, one line), never started over: without ``resume`` a run that is
    there (its JSON, or the checkpoint a killed run left); with ``resume`` a run made with
    other arguments than ``point`` (each but :data:`RESUME_MAY_CHANGE`; as its JSON says,
    and as its ``record`` of them says, :func:`record_point`, which a run killed outright
    before its JSON leaves), or one whose JSON says it stopped while its ``checkpoint`` is
    gone."""
    left = [p for p in (path, checkpoint) if p is not None and p.exists()]
    if left and not resume:
        raise SystemExit(f"{left[0]}: exists; give --resume to continue it or remove it")
    if not (resume and left):
        return False
    run = json.loads(path.read_text()) if path.exists() else {}
    stored = [run.get("point", {})]
    if record is not None and record.exists():
        stored.append(json.loads(record.read_text()))
    elif not path.exists():
        print(f"{name}: its arguments were not recorded (a run made before they were): "
              "--resume cannot check them", flush=True)
    for made in stored:
        for key, value in (point or {}).items():
            if key in made and key not in RESUME_MAY_CHANGE and made[key] != value:
                raise SystemExit(f"{name}: --resume with --{key.replace('_', '-')} {value!r}, "
                                 f"but the run was made with {made[key]!r}; give the run's "
                                 "arguments")
    if run.get("complete"):
        print(f"{name}: complete", flush=True)
        return True
    if checkpoint is not None and not checkpoint.exists() and run.get("steps", 0) > 0:
        raise SystemExit(f"{name}: stopped at {run.get('ps', 0):g} ps but {checkpoint} is "
                         "gone; remove its JSON to start it again")
    return False


def point_main(p, resume):
    """Run one point and write its JSON; exit status 0 when complete, 3 when stopped."""
    outdir = Path(p["outdir"])
    outdir.mkdir(parents=True, exist_ok=True)
    name = run_name(p)
    with Claim(outdir / f"{name}.claim", name):
        return _point_main(p, resume, outdir, name)


def _point_main(p, resume, outdir, name):
    """:func:`point_main` once the point is claimed."""
    paths = {"json": outdir / f"{name}.json", "series": outdir / f"{name}.series.npz",
             "chk": outdir / (f"{name}.chk.omm" if p["code"] == "openmm" else f"{name}.chk.npz"),
             "record": outdir / f"{name}.arguments"}
    arguments = {k: v for k, v in p.items() if k != "outdir"}
    if complete_already(paths["json"], name, resume, arguments, paths["chk"],
                        paths["record"]):
        return 0
    if p["code"] == "rigidmd" and p["integrator"] not in INTEGRATORS:
        raise SystemExit(f"--integrator {p['integrator']!r}: rigidmd has {', '.join(INTEGRATORS)}")
    state = load_start(p["model"], p["waters"])
    record_point(paths["record"], arguments)
    p = dict(p, box_A=float(state["cell"][0, 0]), cutoff_A=cutoff_for(state["cell"]))
    stop = Stop()
    progress = Progress(name, p["ps"], p["log_s"], shared=p.get("jobs", 1) > 1)
    runner = {"rigidmd": run_rigidmd, "openmm": run_openmm, "lammps": run_lammps}[p["code"]]
    wall = time.perf_counter()
    series, steps, ms, offset, first = runner(p, paths, stop, progress, resume)
    n = len(state["numbers"]) // (4 if p["model"].startswith("tip4p") else 3)
    total = int(round(p["ps"] * 1000 / p["dt_fs"]))
    results = analyse(series, p, n, offset)
    out = {"point": {k: v for k, v in p.items() if k != "outdir"}, "name": name,
           "complete": steps >= total, "steps": steps, "resumed_from_step": first,
           "ps": steps * p["dt_fs"] / 1000,
           "stopped_by": stop.signal, "ms_per_step": ms,
           "wall_s": time.perf_counter() - wall, "molecules": n,
           "temperature_K": TEMPERATURE_K, "friction_per_ps": FRICTION_PER_PS,
           "T_reported_as": {"rigidmd": "dyn.get_kinetic_temperatures()",
                             "openmm": "atom velocities from getState",
                             "lammps": "frame velocities"}[p["code"]],
           **results}
    tmp = paths["json"].with_name(paths["json"].name + ".tmp")
    tmp.write_text(json.dumps(out, indent=1, allow_nan=True) + "\n")
    os.replace(tmp, paths["json"])
    progress(steps * p["dt_fs"] / 1000, force=True)
    if stop:
        print(f"{name}: stopped by {stop.signal} at {out['ps']:.3f} ps; written, continue "
              f"with --resume", flush=True)
        return 3
    return 0


def reanalyse(paths, equil_ps=None):
    """Analyse runs again from their series (another ``--equil-ps``, or a newer analysis);
    each JSON keeps its run's record and gets the new results.  Every file is checked
    before any is rewritten (SystemExit, one line): a run's JSON with its series beside it,
    and ``equil_ps`` a finite number >= 0 that leaves part of each run (as ``run
    --equil-ps`` against ``--ps``: past the run, every result was NaN in a JSON still
    ``"complete": true``)."""
    if equil_ps is not None and not 0 <= equil_ps < float("inf"):
        raise SystemExit(f"--equil-ps {equil_ps}: expected a number >= 0")
    runs = []
    for path in paths:
        path = Path(path)
        out = read_json(path)
        if not (isinstance(out, dict) and isinstance(out.get("point"), dict)
                and "name" in out and "molecules" in out):
            raise SystemExit(f"{path}: not a run's JSON (no point, name or molecules)")
        if not path.with_name(out["name"] + ".series.npz").is_file():
            raise SystemExit(f"{path}: its series {out['name']}.series.npz is not beside it")
        length = out.get("ps", out["point"].get("ps"))  # (a stopped run: the part it ran)
        if equil_ps is not None and isinstance(length, int | float) and equil_ps >= length:
            raise SystemExit(f"--equil-ps {equil_ps:g}: leaves nothing of {path.name}'s "
                             f"{length:g} ps")
        runs.append((path, out))
    for path, out in runs:
        p = dict(out["point"])
        if equil_ps is not None:
            p["equil_ps"] = equil_ps
        series = Series(path.with_name(out["name"] + ".series.npz"))
        with np.load(series.path) as d:
            samples, frames = len(d["t_ps"]), len(d["frame_t_ps"])
        series.load(samples, frames)
        out.update(analyse(series, p, out["molecules"], out.get("U_offset_per_molecule", 0.0)))
        out["point"] = p
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(out, indent=1, allow_nan=True) + "\n")
        os.replace(tmp, path)
        print(f"{path.name}: analysed again", flush=True)


def points(args):
    integrators = args.integrator if args.integrator else list(INTEGRATORS)
    out = []
    for code, model, dt, seed, k in itertools.product(args.code, args.model, args.dt_fs,
                                                      args.seed, args.substeps):
        if k > 1 and code != "rigidmd":
            continue  # (a split is rigidmd's)
        for integ in (integrators if code == "rigidmd" else
                      ["nvt_small" if code == "lammps" else "middle"]):
            split = {"substeps": k, "r_split": args.r_split} if k > 1 else {}
            out.append({**split, "code": code, "integrator": integ, "model": model,
                        "waters": args.waters, "dt_fs": dt, "seed": seed, "ps": args.ps,
                        "equil_ps": args.equil_ps, "tau_ps": args.tau_ps,
                        "sample_fs": args.sample_fs, "frame_fs": args.frame_fs,
                        "blocks": args.blocks, "msd_fit_ps": args.msd_fit_ps,
                        "tconf_frames": args.tconf_frames,
                        "tconf_probes": args.tconf_probes,
                        "piece_ps": args.piece_ps, "save_s": args.save_s,
                        "log_s": args.log_s, "jobs": args.jobs,
                        "outdir": str(args.outdir)})
    return out


def run_many(args):
    """Run every point, ``--jobs`` at a time, each in its own process (:func:`run_points`)."""
    check_run_arguments(args)
    return run_points(points(args), __file__, run_name, point_main, args.jobs, args.resume)


def run_points(todo, script, name_of, one, jobs, resume):
    """Run the points ``todo``: with one point and one job here (``one(point, resume)``),
    else ``jobs`` at a time, each in its own process (``script _point JSON``); a signal is
    passed on to the running ones (each finishes its step and writes) and starts no more.
    Returns 0 when every run completed, 3 otherwise (named, by ``name_of(point)``)."""
    todo = list(todo)
    if len(todo) == 1 and jobs == 1:
        return one(todo[0], resume)
    stop = Stop()
    running, status = [], {}
    while (todo and not stop) or running:
        while todo and not stop and len(running) < jobs:
            p = todo.pop(0)
            cmd = [sys.executable, str(script), "_point", json.dumps(p)] + (
                ["--resume"] if resume else [])
            running.append((p, subprocess.Popen(cmd, preexec_fn=ends_with_parent)))
        for p, proc in list(running):
            if stop:
                try:
                    proc.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
            rc = proc.poll()
            if rc is not None:
                running.remove((p, proc))
                status[name_of(p)] = rc
        time.sleep(0.2)
    bad = {k: v for k, v in status.items() if v}
    if bad or stop:
        print(f"{len(bad)} of {len(status)} runs incomplete ({stop.signal or 'failed'}): "
              f"{', '.join(sorted(bad))}; not started: {len(todo)}", flush=True)
        return 3
    return 0


#: The full table's points: steps, runs and length per code (see the docs page).
TABLE_DT_FS = (0.5, 1.0, 2.0, 3.0, 4.0, 5.0)
TABLE_RUNS, TABLE_PS = 3, 200.0


def measure_ms(code, integrator, dt_fs, steps, model, waters, outdir, substeps=1,
               r_split=5.0, skin=None):
    """CPU and wall ms per step of one code at ``dt_fs`` from the model's start, one thread:
    a run of ``steps`` less a run of 20 (each with its own set-up), so that the set-up does
    not count.  The first call of a code in a process also pays its compiling: call it once
    with ``steps=40`` first.  No T_conf sampling.  ``substeps`` above 1: rigidmd's r-RESPA
    split (``dt_fs`` the outer step, the fast level cut at ``r_split``).  ``skin``: the
    neighbour skin (Å) of rigidmd's LAMMPS forces and of LAMMPS's own run (None: LAMMPS's
    metal default, 2 Å; OpenMM has none).  Returns ``(cpu_ms, wall_ms)``."""
    if steps <= 20:
        raise SystemExit(f"--steps {steps}: must be above 20 (a run of 20 steps is subtracted "
                         "from it)")
    spent = []
    split = {"substeps": substeps, "r_split": r_split} if substeps > 1 else {}
    if skin is not None:
        split["skin"] = float(skin)
    for n in (20, steps):
        p = {**split, "code": code, "integrator": integrator, "model": model, "waters": waters,
             "dt_fs": dt_fs, "seed": 1, "ps": n * dt_fs / 1000, "equil_ps": 0.0,
             "tau_ps": 1.0, "sample_fs": dt_fs * n, "frame_fs": dt_fs * n, "blocks": 1,
             "msd_fit_ps": [3, 10], "piece_ps": 1e9, "save_s": 1e9, "log_s": 1e9,
             "outdir": str(outdir)}
        name = run_name(p)
        paths = {"series": Path(outdir) / f"{name}.series.npz",
                 "chk": Path(outdir) / f"{name}.chk.{'omm' if code == 'openmm' else 'npz'}"}
        Path(outdir).mkdir(parents=True, exist_ok=True)
        runner = {"rigidmd": run_rigidmd, "openmm": run_openmm, "lammps": run_lammps}[code]
        cpu, wall = time.process_time(), time.perf_counter()
        with Stop() as stop:  # (the caller's handlers back after each run)
            runner(p, paths, stop, Progress(name, p["ps"], 1e9), False)
        if stop:  # a measurement cut short measures nothing: said, and nothing written
            raise SystemExit(f"stopped by {stop.signal} while measuring {code} {integrator} "
                             f"at {dt_fs:g} fs; nothing of this benchmark was written")
        spent.append((time.process_time() - cpu, time.perf_counter() - wall))
    return tuple(1000 * (spent[1][k] - spent[0][k]) / (steps - 20) for k in (0, 1))


def cost(args):
    """ms/step of each code at ``--waters``, one thread: the CPU time of this process (and
    the wall time) of a run of ``--steps`` less that of a run of 20, after a first run of 20
    that pays for compiling; then the core-hours of the TIP4P/2005 table at that speed.  The
    CPU time is what a machine of idle cores would take; the wall time also holds what
    other processes took from this one."""
    check_cost_arguments(args)
    rows = []
    steps_per_code = TABLE_RUNS * sum(TABLE_PS * 1000 / dt for dt in TABLE_DT_FS)
    for code, integ in ([("rigidmd", i) for i in INTEGRATORS]
                        + [("lammps", "nvt_small"), ("openmm", "middle")]):
        measure_ms(code, integ, 2.0, 40, args.model[0], args.waters, args.outdir)  # compiles
        cpu_ms, wall_ms = measure_ms(code, integ, 2.0, args.steps, args.model[0], args.waters,
                                     args.outdir)
        hours = steps_per_code * cpu_ms / 3.6e6
        rows.append({"code": code, "integrator": integ, "waters": args.waters,
                     "steps": args.steps, "cpu_ms_per_step": cpu_ms,
                     "wall_ms_per_step": wall_ms, "table_core_hours": hours})
        print(f"{code:8} {integ:10} {cpu_ms:7.2f} ms/step CPU ({wall_ms:6.2f} wall)  "
              f"{hours:6.1f} core-hours for {TABLE_RUNS} x {TABLE_PS:g} ps at "
              f"{', '.join(f'{d:g}' for d in TABLE_DT_FS)} fs", flush=True)
    print(f"total {sum(r['table_core_hours'] for r in rows):.1f} core-hours; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores while measuring", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return rows


def check_run_arguments(args):
    """What argparse cannot see alone: lengths against each other, points that would not run
    or would run twice (one line, SystemExit, before anything is written)."""
    if args.equil_ps >= args.ps:
        raise SystemExit(f"--equil-ps {args.equil_ps:g}: leaves nothing of --ps {args.ps:g}")
    low, high = args.msd_fit_ps
    if not low < high:
        raise SystemExit(f"--msd-fit-ps {low:g} {high:g}: the fit's window must rise")
    for option in ("seed", "dt_fs", "substeps", "code", "model", "integrator"):
        values = getattr(args, option) or []  # (--integrator: None, every one)
        if len(set(values)) != len(values):
            raise SystemExit(f"--{option.replace('_', '-')}: a value given twice ({values})")
    if max(args.substeps) > 1 and "rigidmd" not in args.code:
        raise SystemExit("--substeps: a force split is rigidmd's; with --code "
                         f"{' '.join(args.code)} nothing would run")
    if args.integrator and "rigidmd" not in args.code:
        raise SystemExit(f"--integrator: rigidmd's; --code {' '.join(args.code)} has its own")
    for model in args.model:  # (each point failed alone, after starting its process)
        check_start(model, args.waters)


def check_start(model, waters):
    """SystemExit in one line naming ``--waters`` when ``model`` has no start state of
    ``waters`` molecules, with how to make one."""
    if not start_file(model, waters).exists():
        side = max(round(waters ** (1 / 3)), 2)
        how = (f"make it with 'timestep_table.py start --model {model} --waters "
               f"{waters}'" if side ** 3 == waters else
               f"starts are made for cube numbers of waters ({side ** 3}, ...)")
        raise SystemExit(f"--waters {waters}: no start state "
                         f"{start_file(model, waters).name}; {how}")


def check_cost_arguments(args):
    """``cost``'s arguments, before its first run writes anything (SystemExit, one line): a
    start state of ``--waters``, ``--steps`` above the 20 subtracted, a folder for ``--json``."""
    if args.steps <= 20:
        raise SystemExit(f"--steps {args.steps}: must be above 20 (a run of 20 steps is "
                         "subtracted from it)")
    check_start(args.model[0], args.waters)
    if args.json is not None and not args.json.parent.is_dir():
        raise SystemExit(f"--json {args.json}: no folder {args.json.parent}")


#: The parts of a point a continued run may change (how often it saves and says so).
RESUME_MAY_CHANGE = ("save_s", "log_s", "jobs", "outdir", "box_A", "cutoff_A")


def add_run_options(sub, run, outdir):
    """The options a ``run`` command shares with every script that runs points in processes
    (:func:`run_points`), and the ``_point`` command those processes run."""
    run.add_argument("--save-s", type=at_least_zero, default=300.0, help="checkpoint every, s")
    run.add_argument("--log-s", type=at_least_zero, default=60.0,
                     help="log line every, s (no terminal)")
    run.add_argument("--jobs", type=whole(1), default=1)
    run.add_argument("--resume", action="store_true", help="continue stopped runs")
    run.add_argument("--outdir", type=Path, default=outdir)
    point = sub.add_parser("_point")
    point.add_argument("point")
    point.add_argument("--resume", action="store_true")


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run points (the product of the lists given)")
    r.add_argument("--code", nargs="+", choices=CODES, default=["rigidmd"])
    r.add_argument("--integrator", nargs="+", choices=INTEGRATORS,
                   help="rigidmd's integrators (default all)")
    r.add_argument("--model", nargs="+", choices=MODELS, default=["tip4p2005"])
    r.add_argument("--waters", type=whole(1), default=216)
    r.add_argument("--dt-fs", nargs="+", type=positive, required=True)
    r.add_argument("--seed", nargs="+", type=whole(0), default=[1])
    r.add_argument("--ps", type=positive, required=True, help="length of each run, ps")
    r.add_argument("--equil-ps", type=at_least_zero, default=0.0,
                   help="ps left out of the analysis at the start")
    r.add_argument("--tau-ps", type=positive, default=1.0,
                   help="Bussi's τ and the Nosé–Hoover chains' damping time, ps")
    r.add_argument("--sample-fs", type=positive, default=20.0, help="U and T every this, fs")
    r.add_argument("--frame-fs", type=positive, default=200.0, help="frames (RDF, MSD), fs")
    r.add_argument("--blocks", type=whole(2), default=10, help="blocks for the errors")
    r.add_argument("--tconf-frames", type=whole(0), default=2,
                   help="rigidmd: a T_conf sample every this many frames (0: none)")
    r.add_argument("--tconf-probes", type=whole(1), default=4,
                   help="rigidmd: Hutchinson probes per T_conf sample (2 force calls each)")
    r.add_argument("--msd-fit-ps", nargs=2, type=at_least_zero, default=[3.0, 10.0])
    r.add_argument("--piece-ps", type=positive, default=10.0, help="LAMMPS: ps per piece")
    r.add_argument("--substeps", nargs="+", type=whole(1), default=[1],
                   help="rigidmd: r-RESPA's inner steps per --dt-fs (the outer step); above 1 "
                   "the forces are split, the fast level lammps_short_range_commands(--r-split)")
    r.add_argument("--r-split", type=positive, default=5.0, help="the split's fast cut-off, Å")
    add_run_options(sub, r, HERE / "timestep_runs")
    s = sub.add_parser("start", help="make a start state")
    s.add_argument("--model", choices=MODELS, default="tip4p2005")
    s.add_argument("--waters", type=whole(8), default=64,
                   help="a cube number of waters, 8 or more (216: water_openmm_long.py's)")
    s.add_argument("--seed", type=whole(0), default=1)
    s.add_argument("--eq-ps", type=positive, default=5.0)
    s.add_argument("--overwrite", action="store_true",
                   help="replace the committed start of this size")
    a = sub.add_parser("analyse", help="analyse runs again from their series")
    a.add_argument("files", nargs="+", type=existing_file, help="the runs' JSONs")
    a.add_argument("--equil-ps", type=at_least_zero,
                   help="another length left out at the start (below each run's length)")
    c = sub.add_parser("cost", help="ms/step of every code")
    c.add_argument("--model", nargs=1, choices=MODELS, default=["tip4p2005"])
    c.add_argument("--waters", type=whole(1), default=216)
    c.add_argument("--steps", type=whole(21), default=200,
                   help="steps of the run measured, above the 20 subtracted")
    c.add_argument("--outdir", type=Path, default=Path("/tmp/timestep_cost"))
    c.add_argument("--json", type=Path, help="also write the rows here")
    return p.parse_args(argv)


def main(argv=None):
    args = parse(argv)
    if args.command == "_point":
        return point_main(json.loads(args.point), args.resume)
    if args.command == "start":
        existing = start_file(args.model, args.waters)
        if existing.exists() and not args.overwrite:  # every run of this size came from it
            raise SystemExit(f"{existing}: exists (the start of every {args.waters}-water run "
                             "made so far); give --overwrite to make it again")
        print(make_start(args.model, args.waters, args.seed, args.eq_ps))
        return 0
    if args.command == "analyse":
        reanalyse(args.files, args.equil_ps)
        return 0
    if args.command == "cost":
        cost(args)
        return 0
    return run_many(args)


if __name__ == "__main__":
    sys.exit(main())
