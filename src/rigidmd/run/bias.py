r"""``rigidmd bias``: a time step's bias in ⟨U⟩, from two short runs at dt and dt/2.

One run cannot measure its own error: its ⟨U⟩ is all it has.  Two runs of
the same configuration from the same thermal start, at the time step ``dt``
and at ``dt/2``, can: for a second-order integrator the averages carry a
leading error :math:`c\,\Delta t^2`, so

.. math::
    \langle U\rangle(\Delta t) - \langle U\rangle(0) \approx
    \tfrac43\,\bigl(\langle U\rangle(\Delta t) - \langle U\rangle(\Delta t/2)\bigr),

with a statistical error from block averages of each run (independent runs:
the errors add in quadrature).  The same pair gives the kinetic temperatures
of translation and rotation and, every ``tconf_fs``, the configurational ones
(:mod:`rigidmd.core.configurational`), each of which the step biases in its
own way.  The bias is said in kJ/mol per body and in kelvin: the shift of
the bath temperature that would change ⟨U⟩ as much,
:math:`\Delta T = N\,\mathrm{bias}\;k_BT^2/\mathrm{Var}(U)`, with
:math:`\partial\langle U\rangle/\partial T = \mathrm{Var}(U)/k_BT^2` measured
from the half-step run's fluctuations; the kelvin error carries both the bias's error
and Var(U)'s (the spread of its blocks' variances).

Only a thermostatted run at constant volume is accepted: without a
thermostat the temperature itself moves with the step (the energy is what is
conserved), and under a barostat the density does, so ⟨U⟩ would mix the two
errors; estimate the bias at the barostat's mean density.

Progress goes to stderr (a bar on a terminal; otherwise a line each tenth of
a run, never two within a minute, and one at its end).  SIGINT, SIGTERM and
SIGUSR1 finish the current step, write the run's checkpoint and what was
sampled (``bias.json``), print the estimate so far and the command that
continues (``--resume``); the continued estimate is the one an uninterrupted
command gives, bit for bit, the configurational temperatures included (a
sample's probes depend on the seed, the run and the step alone).  A second
Ctrl-C stops at once: ``bias.json`` keeps the samples, and ``--resume``
continues from the run's last checkpoint (or its start).  A failure in a step
(exit 1) keeps them likewise.  Outputs in ``--outdir``, which one estimate
holds at a time (a lock): ``bias.json`` (every sample and number) and
``bias.txt`` (the table).  Times that are not a whole number of steps are
taken to the nearest step, and the command says so.
"""

import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np
from ase import units

from rigidmd.config import TIME_UNITS, ConfigError
from rigidmd.config.diagnostics import own_calculator
from rigidmd.core.configurational import ConfigurationalTemperature, block_mean, block_ratio
from rigidmd.core.observables import kinetic_dof
from rigidmd.run.fingerprint import fingerprint
from rigidmd.run.outputs import OutputLock, describe_os_error
from rigidmd.run.report import Progress
from rigidmd.run.runner import RunStopped
from rigidmd.run.signals import EXIT_STATUS, StopRequest, StopSignals

__all__ = ["estimate_bias", "BiasLeg", "check_bias_config", "add_bias_parser", "bias_command"]

KJ_MOL = units.kJ / units.mol
#: The flag (or field) that sets each argument of :func:`estimate_bias`, for the messages.
FLAGS = {"production_ps": "--ps", "equilibrate_ps": "--equilibrate-ps",
         "sample_fs": "--sample-fs", "tconf_fs": "--tconf-fs", "probes": "--probes",
         "seed": "seed", "dt_fs": "timestep"}
#: What a leg keeps per sample: step, potential energy (eV), kinetic energies (eV).
SAMPLE_FIELDS = ("step", "U", "K_tr", "K_rot")


def check_bias_config(config) -> None:
    """Refuse, with one line naming the field, what ``rigidmd bias`` cannot estimate."""
    coupling = config.coupling
    if getattr(coupling, "barostat", None) is not None:
        raise ConfigError("barostat: rigidmd bias runs at constant volume (a barostat moves the "
                          "density with the step too); remove it and give the structure at "
                          "the barostat's mean density")
    if getattr(coupling, "thermostat", None) is None:
        raise ConfigError("thermostat: rigidmd bias needs a thermostat (at constant energy the "
                          "temperature itself moves with the step); add one, e.g. "
                          "{kind: langevin, temperature: 300 K, friction: 1 1/ps}")
    bath = coupling.thermostat.kwargs.get("temperature_K")
    if bath is not None and not bath > 0:
        raise ConfigError(f"thermostat.temperature: {bath:g} K; rigidmd bias needs a bath above "
                          "0 K (the bias in kelvin divides by the fluctuations of U at it)")
    if coupling.thermostat.kwargs.get("friction", 1.0) == 0:
        raise ConfigError("thermostat.friction: 0 leaves the energy constant (no thermostat), "
                          "and rigidmd bias needs the temperature held; give a friction > 0, "
                          "e.g. 1 1/ps")
    if config.relax is not None:
        raise ConfigError("relax: rigidmd bias starts both runs from the structure as given; "
                          "relax it first (rigidmd relax) and give the relaxed structure")


class BiasLeg:
    """One of the two runs: its time step, its samples, its checkpoint.

    Parameters
    ----------
    name : str
        ``"dt"`` or ``"dt/2"``.
    dt : float
        ASE time units.
    equilibrate, production, every, tconf_every : int
        Steps: discarded, sampled after them, between samples of ⟨U⟩ and the
        kinetic energies, between configurational samples (0: none).
    """

    def __init__(self, name, dt, equilibrate, production, every, tconf_every):
        self.name, self.dt = name, dt
        self.equilibrate, self.production = equilibrate, production
        self.every, self.tconf_every = every, tconf_every
        self.samples = {key: [] for key in SAMPLE_FIELDS}
        self.tconf_sums = []
        self.done = False
        self.dof = None  # (translational, rotational) degrees of freedom, once it ran
        self.bodies = None  # bodies (and point particles) the energies are per

    @property
    def total(self):
        """Steps of the whole leg."""
        return self.equilibrate + self.production

    def todict(self):
        return {"name": self.name, "dt": self.dt, "equilibrate": self.equilibrate,
                "production": self.production, "every": self.every,
                "tconf_every": self.tconf_every, "samples": self.samples,
                "tconf_sums": self.tconf_sums, "done": self.done, "dof": self.dof,
                "bodies": self.bodies}

    def restore(self, saved):
        self.samples = {key: list(saved["samples"][key]) for key in SAMPLE_FIELDS}
        self.tconf_sums = [tuple(s) for s in saved["tconf_sums"]]
        self.done = bool(saved["done"])
        self.dof = None if saved["dof"] is None else tuple(saved["dof"])
        self.bodies = saved["bodies"]

    def trim(self, step):
        """Forget the samples after ``step`` (the run continues from its checkpoint there)."""
        keep = [i for i, s in enumerate(self.samples["step"]) if s <= step]
        self.samples = {key: [value[i] for i in keep] for key, value in self.samples.items()}
        self.tconf_sums = [t for t in self.tconf_sums if t[4] <= step]

    # ------------------------------------------------------------ the estimates
    def temperatures(self, dyn_dof, blocks):
        """⟨U⟩ (eV, total) and the temperatures (K) with block errors."""
        s = {key: np.asarray(value, dtype=float) for key, value in self.samples.items()}
        tr_dof, rot_dof = dyn_dof
        out = {"U": block_mean(s["U"], blocks),
               "T_tr": _scaled(block_mean(s["K_tr"], blocks), 2 / (tr_dof * units.kB)),
               "T_rot": _scaled(block_mean(s["K_rot"], blocks), 2 / (rot_dof * units.kB))
               if rot_dof else (np.nan, np.nan),
               "var_U": float(np.var(s["U"], ddof=1)) if len(s["U"]) > 1 else np.nan,
               "var_U_error": _variance_error(s["U"], blocks),
               "samples": len(s["U"])}
        sums = np.array([t[:4] for t in self.tconf_sums]).reshape(-1, 4)
        out["T_conf_tr"] = _scaled(block_ratio(sums[:, 0], sums[:, 1], blocks), 1 / units.kB)
        out["T_conf_rot"] = _scaled(block_ratio(sums[:, 2], sums[:, 3], blocks), 1 / units.kB)
        out["tconf_samples"] = len(sums)
        return out


def _scaled(pair, factor):
    return pair[0] * factor, pair[1] * factor


#: The sampling intervals when none is given (fs): the whole number of steps nearest them.
SAMPLE_FS, TCONF_FS = 10.0, 100.0


def _steps(name, time_span, dt, notes, minimum=1):
    """Whole steps of ``dt`` nearest ``time_span`` (ASE time); a time that is not a whole
    number of them adds a line to ``notes`` (None: a default, said nothing of); fewer than
    ``minimum`` (or none for a time above zero) is refused naming ``name``."""
    fs = TIME_UNITS["fs"]
    unit = "ps" if name.endswith("-ps") else "fs"  # as the option is given
    steps = int(np.floor(time_span / dt + 0.5))
    if steps < minimum or (time_span > 0 and steps == 0):
        raise ConfigError(f"{name}: {time_span / TIME_UNITS[unit]:g} {unit} is less than "
                          f"{max(minimum, 1)} step(s) of {dt / fs:g} fs"
                          + (" (0: none)" if minimum == 0 else ""))
    if notes is not None and abs(steps * dt - time_span) > 1e-9 * max(time_span, dt):
        notes.append(f"{name}: {time_span / fs:g} fs is not a whole number of {dt / fs:g} fs "
                     f"steps; taken as {steps} steps ({steps * dt / fs:g} fs)")
    return steps


def _legs(config, production_ps, equilibrate_ps, sample_fs, tconf_fs, blocks, notes):
    """The two legs (dt, dt/2), sampled at the same times; refuses, naming the option, a
    leg that would have fewer samples than ``blocks`` (no error could be given)."""
    dt = config.run.timestep
    ps, fs = TIME_UNITS["ps"], TIME_UNITS["fs"]
    # On the coarser grid: both legs sample at the same times.
    every = max(_steps("--sample-fs", SAMPLE_FS * fs, dt, None, minimum=0), 1) \
        if sample_fs is None else _steps("--sample-fs", sample_fs * fs, dt, notes)
    tconf = max(_steps("--tconf-fs", TCONF_FS * fs, dt, None, minimum=0), 1) \
        if tconf_fs is None else 0 if not tconf_fs else \
        _steps("--tconf-fs", tconf_fs * fs, dt, notes)
    equilibrate = _steps("--equilibrate-ps", equilibrate_ps * ps, dt, notes, minimum=0)
    production = _steps("--ps", production_ps * ps, dt, notes, minimum=5)
    for option, interval in (("--sample-fs", every), ("--tconf-fs", tconf)):
        if not interval:
            continue
        taken = (equilibrate + production) // interval - equilibrate // interval
        if taken < blocks:
            advice = "raise --ps, or lower --sample-fs or --blocks" \
                if option == "--sample-fs" else \
                "raise --ps, or lower --tconf-fs (0: none) or --blocks"
            raise ConfigError(f"{option}: {production_ps:g} ps sampled every "
                              f"{interval * dt / fs:g} fs gives {taken} samples, fewer than "
                              f"the {blocks} blocks of the errors; {advice}")
    return [BiasLeg(name, dt / scale, equilibrate * scale, production * scale, every * scale,
                    tconf * scale) for name, scale in (("dt", 1), ("dt/2", 2))]


class _Sampler:
    """The leg's observer: ⟨U⟩ and the kinetic energies on sampled steps after equilibration."""

    modifies_atoms = False

    def __init__(self, dyn, leg):
        self.dyn, self.leg = dyn, leg

    def __call__(self):
        dyn, leg = self.dyn, self.leg
        if dyn.nsteps <= leg.equilibrate:
            return
        s = leg.samples
        s["step"].append(int(dyn.nsteps))
        s["U"].append(float(dyn.atoms.get_potential_energy()))
        K_tr, K_rot = dyn.get_kinetic_energies()  # as reported: BAOAB's after O
        s["K_tr"].append(float(K_tr))
        s["K_rot"].append(float(K_rot))


class _Conf:
    """The configurational temperature, after equilibration, its sums kept by the leg."""

    modifies_atoms = False
    wants_properties = False

    def __init__(self, dyn, leg, seed, probes, calculator):
        self.leg = leg
        # A sample's probes: (seed, leg, step), so a resumed leg draws those of an
        # uninterrupted one.
        self.tconf = ConfigurationalTemperature(dyn, probes=probes,
                                                rng=(seed, int(leg.name != "dt")),
                                                calculator=calculator)
        self.dyn = dyn

    def __call__(self):
        if self.dyn.nsteps > self.leg.equilibrate:
            self.leg.tconf_sums.append(self.tconf.sample())


def _dynamics(config, leg, checkpoint, engine):
    """The leg's dynamics: from its checkpoint, or from the configuration's start."""
    from rigidmd.core.dynamics import RigidDynamics
    from rigidmd.core.velocities import rigid_maxwell_boltzmann
    from rigidmd.run.restart import load_checkpoint

    if checkpoint.is_file():
        from rigidmd.core.checkpoint import read_checkpoint

        saved = read_checkpoint(checkpoint)
        dyn = load_checkpoint(saved, config.calculator.build(saved.atoms(), engine))
        if abs(dyn.dt - leg.dt) > 1e-9 * leg.dt:
            close = getattr(dyn.atoms.calc, "close", None)
            if callable(close):
                close()
            raise ConfigError(f"--resume: {checkpoint} is a run at "
                              f"{dyn.dt / TIME_UNITS['fs']:g} fs, not this estimate's {leg.name} "
                              f"run at {leg.dt / TIME_UNITS['fs']:g} fs; start again in another "
                              "directory")
        return dyn
    atoms = config.structure.build_atoms()
    bodies = config.structure.resolve_bodies(atoms)
    velocities = config.run.velocities
    if velocities is not None and config.structure.restart is None:
        rigid_maxwell_boltzmann(atoms, velocities["temperature_K"], bodies=bodies,
                                rng=np.random.default_rng(velocities["seed"]),
                                stationary=velocities.get("stationary", True))
    atoms.calc = config.calculator.build(atoms, engine)
    return RigidDynamics(atoms, leg.dt, bodies=bodies, couplings=config.coupling.parts(),
                         integrator=config.run.integrator,
                         integrator_options=config.run.integrator_options)


#: Wall seconds between a leg's saves (its samples in ``bias.json``, then its checkpoint):
#: what a kill that no handler sees (SIGKILL, the out-of-memory killer) can lose.
SAVE_EVERY_S = 300.0


class _Saver:
    """Every ``every_s`` wall seconds: the record (``save_record()``), then the checkpoint.
    In that order, so that a kill between the two leaves samples past the checkpoint, which
    a resumed leg drops and takes again (:meth:`BiasLeg.trim`), never a gap."""

    def __init__(self, dyn, checkpoint, save_record, every_s):
        self.dyn, self.checkpoint, self.save_record = dyn, checkpoint, save_record
        self.every_s, self.last = every_s, time.monotonic()

    def __call__(self):
        if time.monotonic() - self.last >= self.every_s:
            self.save_record()
            self.dyn.save_checkpoint(self.checkpoint)
            self.last = time.monotonic()


def _run_leg(config, leg, directory, stop, progress, probes, seed, save_record=None):
    """Run (or continue) one leg; returns None when done, else the stop signal's number.
    ``save_record()`` writes ``bias.json`` (every :data:`SAVE_EVERY_S` and when the leg is
    done, before its checkpoint goes)."""
    checkpoint = _checkpoint_path(directory, leg)
    dyn = _dynamics(config, leg, checkpoint, directory / "engine")
    own = None  # the configurational temperature's calculator (as rigidmd run gives it)
    # Samples taken after the checkpoint (a failure, a second Ctrl-C) are taken again.
    leg.trim(dyn.nsteps)
    try:
        leg.dof = kinetic_dof(dyn.model, dyn.holds_momentum)
        leg.bodies = dyn.model.n_bodies or dyn.model.n_free
        remaining = leg.total - dyn.nsteps
        dyn.attach(_Sampler(dyn, leg), interval=leg.every)
        if leg.tconf_every:
            own = own_calculator(config.calculator, dyn.atoms, directory / "engine")
            dyn.attach(_Conf(dyn, leg, seed, probes, own), interval=leg.tconf_every)
        dyn.attach(Progress(dyn, remaining, stream=progress),
                   interval=max(1, remaining // 1000))
        if save_record is not None:  # after the step's samples
            dyn.attach(_Saver(dyn, checkpoint, save_record, SAVE_EVERY_S), interval=1)
        dyn.attach(stop.check, interval=1)  # last: after the step's samples
        try:
            dyn.run(remaining)
        except StopRequest as request:
            dyn.save_checkpoint(checkpoint)
            return request.signum
        leg.done = True
        if save_record is not None:
            save_record()  # the finished leg on record before its checkpoint goes
        checkpoint.unlink(missing_ok=True)
        return None
    finally:
        for calc in (dyn.atoms.calc, own):
            close = getattr(calc, "close", None)
            if callable(close):
                close()


def estimate_bias(config, directory, *, production_ps=10.0, equilibrate_ps=2.0,
                  sample_fs=None, tconf_fs=None, probes=4, seed=0, blocks=5, resume=False,
                  stream=None, progress=None, hint=None) -> dict:
    r"""Estimate the bias of ⟨U⟩/N at the configuration's time step from runs at dt and dt/2.

    Both runs start from the configuration's structure and velocities (its
    ``velocities:`` seed, its thermostat's seed), run ``equilibrate_ps``
    (discarded), then ``production_ps`` sampled every ``sample_fs`` (the same
    times in both) and, every ``tconf_fs``, the configurational temperatures
    (``2 * probes`` force calls each; 0 turns them off).

    Parameters
    ----------
    config : rigidmd.config.RunConfig
        Checked; a thermostat and no barostat (:func:`check_bias_config`).
    directory : path-like
        Where ``bias.json``, ``bias.txt`` and a stopped run's checkpoints go.
    production_ps, equilibrate_ps : float
    sample_fs, tconf_fs : float, optional
        Default: the whole number of steps nearest 10 and 100 fs; a time given that is
        not a whole number of steps is taken to the nearest, and said.
    probes, seed, blocks : int
        Configurational probes per sample, their seed, blocks of the errors.
    resume : bool
        Continue the stopped estimate in ``directory`` (the same configuration
        and arguments, or a ConfigError naming what differs).
    stream, progress : file, optional
        Messages (stdout) and the progress line (stderr).
    hint : str, optional
        The command that continues, printed after a stop.

    Returns
    -------
    dict
        ``"status"`` (0, or 130/143/138 after a signal), ``"legs"`` (each leg's
        ⟨U⟩/N in kJ/mol and temperatures in K, value and error), ``"bias_kJ_mol"``,
        ``"bias_K"`` (value and error), ``"complete"``.
    """
    stream = sys.stdout if stream is None else stream
    check_bias_config(config)
    directory = Path(directory)
    arguments = {"production_ps": production_ps, "equilibrate_ps": equilibrate_ps,
                 "sample_fs": sample_fs, "tconf_fs": tconf_fs, "probes": probes, "seed": seed,
                 "dt_fs": config.run.timestep / TIME_UNITS["fs"]}
    notes = []
    legs = _legs(config, production_ps, equilibrate_ps, sample_fs, tconf_fs, blocks, notes)
    record = directory / "bias.json"
    prints = fingerprint(config)
    if resume and not record.is_file():
        raise ConfigError(f"--resume: no estimate to continue ({record} does not exist)")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"--outdir: {describe_os_error(err)}") from None
    # One estimate at a time in the directory: a second would overwrite the first's files.
    with OutputLock(directory, field="--outdir"):
        _check_directory(directory, record, legs, arguments, prints, resume)
        for line in notes:
            print(line, file=stream)
        return _estimate_in(config, directory, legs, arguments, prints, blocks, probes, seed,
                            stream, progress, hint)


def _check_directory(directory, record, legs, arguments, prints, resume):
    """With ``resume``, the estimate in ``directory`` is this one (its legs restored from
    it); without, the directory holds none of an estimate's files."""
    if resume:
        saved = _read_record(record)
        for key, value in arguments.items():
            if saved["arguments"].get(key) != value:
                raise ConfigError(f"{FLAGS[key]}: {saved['arguments'].get(key)!r} in the "
                                  f"estimate in {record}, {value!r} now; give it as before to "
                                  "continue (or start again without --resume)")
        changed = [k for k in prints if saved["fingerprint"].get(k) != prints[k]]
        if changed:
            raise ConfigError(f"{changed[0]}: differs from the configuration of the estimate "
                              f"in {record}; give it as before to continue")
        try:
            for leg, kept in zip(legs, saved["legs"], strict=True):
                leg.restore(kept)
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"--resume: {record} is not an estimate rigidmd bias wrote (its "
                              "runs' records are incomplete); start again in another "
                              "directory") from None
        return
    held = [path.name for path in (record, directory / "bias.txt",
                                   *(_checkpoint_path(directory, leg) for leg in legs))
            if path.exists()]  # (a bias.txt alone: a table someone kept, not overwritten)
    if held:
        raise ConfigError(f"--outdir: {directory} already holds an estimate "
                          f"({', '.join(held)}); continue it with --resume or give another "
                          "directory")


def _checkpoint_path(directory, leg):
    return directory / f"leg-{leg.name.replace('/', '-')}.npz"


def _estimate_in(config, directory, legs, arguments, prints, blocks, probes, seed, stream,
                 progress, hint):
    """Run the legs not done; the result (see :func:`estimate_bias`)."""
    record = directory / "bias.json"
    status = 0
    t0 = time.perf_counter()
    def record_now(status):
        """``bias.json`` and ``bias.txt`` now (``status`` None: running)."""
        result = _estimate(legs, blocks, config)
        result.update(status=status, arguments=arguments, fingerprint=prints,
                      legs_record=[leg.todict() for leg in legs],
                      elapsed_s=time.perf_counter() - t0)
        _write(directory, result)
        return result

    again = hint or "the same command with --resume"
    leg = legs[0]
    with StopSignals() as stop:
        try:
            for leg in legs:
                if leg.done:
                    continue
                print(f"run at {leg.name} = {leg.dt / TIME_UNITS['fs']:g} fs: {leg.total} "
                      f"steps ({leg.equilibrate} to equilibrate)", file=stream)
                if config.calculator.name == "ipi":
                    print(f"the run at {leg.name} waits for an engine at "
                          f"{config.calculator.address or 'the configured address'}; each run "
                          "connects anew, and an engine started by hand ends with the run it "
                          "served (EXIT): start it again for this one", file=stream)
                signum = _run_leg(config, leg, directory, stop, progress, probes, seed,
                                  save_record=lambda: record_now(None))
                if signum is not None:
                    status = EXIT_STATUS[signum]
                    break
        except KeyboardInterrupt:
            # A second Ctrl-C, anywhere in a step: what was sampled is kept, and a --resume
            # takes the run from its last checkpoint (or its start) and samples again after.
            stop.shielded = True
            result = record_now(130)
            print(result["text"], file=stream)
            print(f"\ninterrupted at once (second Ctrl-C) in the run at {leg.name}: {record} "
                  "keeps the samples so far, and the run continues from its last checkpoint "
                  f"(or its start); continue with: {again}", file=stream)
            return result
        except Exception as err:
            # A failed step: kept likewise; the command says so in one line (exit 1).  An
            # engine's set-up error (the input's fault) stays what it is.
            stop.shielded = True
            record_now(1)
            if getattr(err, "setup", False) or isinstance(err, ConfigError):
                raise
            reason = describe_os_error(err) if isinstance(err, OSError) else \
                " ".join(str(err).split()) or type(err).__name__
            raise RunStopped(f"{reason} (in the run at {leg.name}); {record} keeps the samples "
                             "so far, and the run continues from its last checkpoint (or its "
                             f"start): {again}") from err
        stop.shielded = True  # the record is written whole
        result = record_now(status)
    print(result["text"], file=stream)
    if status:
        print(f"stopped by a signal: {record} and the run's checkpoint hold what was done; "
              f"continue with: {again}", file=stream)
    return result


def _read_record(record):
    if not record.is_file():
        raise ConfigError(f"--resume: no estimate to continue ({record} does not exist)")
    try:
        saved = json.loads(record.read_text())
        saved["arguments"], saved["fingerprint"], saved["legs"] = (
            saved["arguments"], saved["fingerprint"], saved["legs_record"])
    except (ValueError, KeyError, TypeError):
        raise ConfigError(f"--resume: {record} is not an estimate rigidmd bias wrote") from None
    return saved


def _estimate(legs, blocks, config):
    """The numbers and the table from the legs' samples (what there is of them)."""
    n = _bodies(config, legs)
    per = {}
    for leg in legs:
        if leg.dof is None or not leg.samples["U"]:
            per[leg.name] = None
            continue
        per[leg.name] = leg.temperatures(leg.dof, blocks)
    complete = all(leg.done for leg in legs)
    bias = bias_k = (np.nan, np.nan)
    a, b = per.get("dt"), per.get("dt/2")
    if a is not None and b is not None:
        value = 4 / 3 * (a["U"][0] - b["U"][0]) / n / KJ_MOL
        error = 4 / 3 * np.hypot(a["U"][1], b["U"][1]) / n / KJ_MOL
        bias = (value, error)
        kT2 = (config.coupling.thermostat.kwargs["temperature_K"] * units.kB) ** 2
        slope = b["var_U"] / kT2 * units.kB if kT2 > 0 else 0.0  # d<U>/dT (eV/K), all
        if slope > 0:
            # ΔT = bias / slope: the error of each, the slope's from its blocks' variances
            relative = b.get("var_U_error", np.nan) / b["var_U"]
            shift = value * n * KJ_MOL / slope
            bias_k = (shift, float(np.hypot(error * n * KJ_MOL / slope,
                                             shift * np.nan_to_num(relative))))
    text = _table(legs, per, n, bias, bias_k, complete, config)
    legs_out = {}
    for name, values in per.items():
        if values is not None:
            values = dict(values, U_per_body_kJ_mol=(values["U"][0] / n / KJ_MOL,
                                                     values["U"][1] / n / KJ_MOL))
        legs_out[name] = values
    return {"legs": legs_out, "bias_kJ_mol": bias, "bias_K": bias_k, "complete": complete,
            "bodies": n, "text": text}


def _variance_error(values, blocks):
    """Standard error of Var(``values``) from the variances of ``blocks`` consecutive blocks
    about the whole series' mean (NaN with too few values).  Blocks long against the
    correlation time make these nearly independent; shorter ones understate the error, as
    for the means."""
    values = np.asarray(values, dtype=float)
    if len(values) < 2 * blocks or blocks < 2:
        return np.nan
    mean = values.mean()
    spreads = np.array([np.mean((part - mean) ** 2) for part in np.array_split(values, blocks)])
    return float(spreads.std(ddof=1) / np.sqrt(blocks))


def _bodies(config, legs):
    """Bodies (molecules; point particles when there are none) the energies are per."""
    for leg in legs:
        if leg.bodies:
            return leg.bodies
    return 1


def _table(legs, per, n, bias, bias_k, complete, config):
    def pm(pair, digits):
        value, error = pair
        if np.isnan(value):
            return "-"
        return f"{value:.{digits}f}" + ("" if np.isnan(error) else f" ± {error:.{digits}f}")

    fs = TIME_UNITS["fs"]
    head = [f"{leg.name} = {leg.dt / fs:g} fs" for leg in legs]
    rows = [("samples", lambda v: f"{v['samples']} (T_conf {v['tconf_samples']})"),
            ("<U>/N (kJ/mol)", lambda v: pm((v["U"][0] / n / KJ_MOL, v["U"][1] / n / KJ_MOL),
                                            4)),
            ("T_tr (K)", lambda v: pm(v["T_tr"], 1)),
            ("T_rot (K)", lambda v: pm(v["T_rot"], 1)),
            ("T_conf,tr (K)", lambda v: pm(v["T_conf_tr"], 1)),
            ("T_conf,rot (K)", lambda v: pm(v["T_conf_rot"], 1))]
    bath = config.coupling.thermostat.kwargs["temperature_K"]
    lines = [f"step bias of {n} bodies at {legs[0].dt / fs:g} fs, bath {bath:g} K "
             f"({'complete' if complete else 'so far: the runs stopped early'})",
             f"{'':<16}" + "".join(f"{h:>24}" for h in head)]
    for label, cell in rows:
        cells = [cell(per[leg.name]) if per[leg.name] is not None else "-" for leg in legs]
        lines.append(f"{label:<16}" + "".join(f"{c:>24}" for c in cells))
    if np.isnan(bias[0]):
        lines.append("bias: needs samples of both runs")
    else:
        lines.append(f"bias of <U>/N at {legs[0].dt / fs:g} fs: {pm(bias, 4)} kJ/mol "
                     "(4/3 of the difference: the leading dt^2 term); as a temperature: "
                     f"{pm(bias_k, 2)} K (d<U>/dT from the fluctuations of U at "
                     f"{legs[1].dt / fs:g} fs)")
    return "\n".join(lines)


def _write(directory, result):
    def plain(value):
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        if isinstance(value, (np.floating, float)):
            return None if np.isnan(value) else float(value)
        if isinstance(value, np.integer):
            return int(value)
        return value

    tmp = directory / "bias.json.tmp"
    tmp.write_text(json.dumps(plain(result), indent=1))
    tmp.replace(directory / "bias.json")
    (directory / "bias.txt").write_text(result["text"] + "\n")


# ------------------------------------------------------------ the command
def add_bias_parser(sub, trust_help):
    """Register ``rigidmd bias`` on the command's subparsers."""
    bias = sub.add_parser("bias", help="estimate the time step's bias of <U> from runs at dt "
                                       "and dt/2 (a thermostatted configuration)")
    bias.add_argument("config", help="YAML configuration with a thermostat (no barostat)")
    bias.add_argument("--timestep", help="dt with unit (default: the configuration's)")
    bias.add_argument("--ps", type=float, default=10.0,
                      help="sampled picoseconds of each run (default 10)")
    bias.add_argument("--equilibrate-ps", type=float, default=2.0,
                      help="picoseconds each run discards first (default 2)")
    bias.add_argument("--sample-fs", type=float,
                      help="femtoseconds between samples of U and the temperatures (default: "
                           "the whole number of steps nearest 10)")
    bias.add_argument("--tconf-fs", type=float,
                      help="femtoseconds between configurational temperatures (each 2 * probes "
                           "force calls; 0: none; default: the whole number of steps nearest "
                           "100)")
    bias.add_argument("--probes", type=int, default=4, help="Hutchinson probes (default 4)")
    bias.add_argument("--blocks", type=int, default=5, help="blocks of the errors (default 5)")
    bias.add_argument("--outdir", default="rigidmd-bias", help="output directory")
    bias.add_argument("--resume", action="store_true",
                      help="continue a stopped estimate in the output directory")
    bias.add_argument("--trust", action="store_true", help=trust_help)


def bias_command(args, stream=None):
    """``rigidmd bias``: the exit status (0, or 130/143/138 after a stop signal)."""
    from rigidmd.config import check_config, load_config, parse_quantity

    for name in ("ps", "equilibrate_ps", "sample_fs", "tconf_fs"):
        value = getattr(args, name)
        if value is None:
            continue  # a default
        if not (np.isfinite(value) and value >= 0) or (name in ("ps", "sample_fs")
                                                        and value == 0):
            raise ConfigError(f"--{name.replace('_', '-')}: expected a positive number of "
                              f"{name.split('_')[-1]}, got {value:g}")
    for name, least in (("probes", 1), ("blocks", 2)):
        if getattr(args, name) < least:
            raise ConfigError(f"--{name}: expected a whole number >= {least}, got "
                              f"{getattr(args, name)}")
    if not args.outdir.strip():
        raise ConfigError("--outdir: empty; give a directory (default rigidmd-bias)")
    raw = load_config(args.config)
    if isinstance(raw, dict) and raw.get("steps") is None:
        raw["steps"] = 1  # not read: the runs' lengths are --equilibrate-ps and --ps
    if args.timestep is not None:
        raw["timestep"] = args.timestep
        parse_quantity("--timestep", args.timestep, TIME_UNITS)
    config = check_config(raw, trust=args.trust)
    check_bias_config(config)
    words = ["rigidmd", "bias", str(Path(args.config).resolve())]  # from any folder
    for name in ("timestep", "ps", "equilibrate_ps", "sample_fs", "tconf_fs", "probes",
                 "blocks"):
        words += [f"--{name.replace('_', '-')}", str(getattr(args, name))] if getattr(
            args, name) is not None else []
    words += ["--outdir", str(Path(args.outdir).resolve())] + (["--trust"] if args.trust else [])
    hint = shlex.join(words + ["--resume"])
    result = estimate_bias(config, args.outdir, production_ps=args.ps,
                           equilibrate_ps=args.equilibrate_ps, sample_fs=args.sample_fs,
                           tconf_fs=args.tconf_fs, probes=args.probes, blocks=args.blocks,
                           resume=args.resume, stream=stream, hint=hint)
    print(f"wrote {Path(args.outdir) / 'bias.json'} and {Path(args.outdir) / 'bias.txt'}",
          file=stream or sys.stdout)
    return result["status"]
