r"""The coupling interface: what a thermostat or barostat is to the step, and its registry.

A :class:`~rigidmd.core.dynamics.RigidDynamics` holds an integrator scheme and a
list of coupling parts.  Each step of :math:`\Delta t` is the symmetric
splitting

.. code-block:: text

    part_1.first_half(Δt/2) ... part_n.first_half(Δt/2)
    the integrator's deterministic step (forces, drift, rotation)
    part_n.second_half(Δt/2) ... part_1.second_half(Δt/2)

A part may also act inside the deterministic step, between its two half drifts
(:meth:`Coupling.middle`, called by the scheme's ``middle`` operator: BAOAB's O).

A part acts on the body state (centre-of-mass velocities, NO_SQUISH
momenta, point particles; a barostat also on the cell), contributes a term to
the conserved energy, saves and restores its own variables (for the rollback
of a failed step and for checkpoints), and says what it is in a LAMMPS deck.
It never holds the dynamics: each call gets a :class:`CouplingView` (the
state, the body model, the per-step record of :mod:`rigidmd.core.record`, the force
evaluator and the step number).

This module is the interface the core's step needs (:class:`Coupling`,
:class:`CouplingView`, the registry :data:`COUPLINGS` with :func:`register`,
:func:`check_composition`, :func:`export_parts` and the random-number
generator helpers the checkpoints use); the parts themselves and what they
share (:class:`rigidmd.couplings.base.Thermostat`,
:class:`rigidmd.couplings.base.NoseHooverChain`, the parameter checks) live in
:mod:`rigidmd.couplings`, a layer above, which re-exports these names.

:data:`COUPLINGS` maps each kind's name (``"langevin"``, ``"bussi"``,
``"nose_hoover"``, ``"monte_carlo"``, ...) to its class; the class's
:attr:`Coupling.parameters` say which parameters it takes, with which units, so
that the configuration checker, the command line and the LAMMPS export all read
one registry.
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from ase import Atoms

from rigidmd.core.model import BodyModel
from rigidmd.core.stepcontext import StepContext

__all__ = ["Coupling", "CouplingView", "Parameter", "COUPLINGS", "register", "NotExportable",
           "LammpsFix", "check_rng", "rng_state", "set_rng_state", "rng_kind", "new_rng",
           "check_composition", "export_parts", "Target", "share_target"]

#: Registered coupling kinds, name -> class.
COUPLINGS = {}


class NotExportable(ValueError):
    """A coupling part has no LAMMPS equivalent.

    Raised by :meth:`Coupling.lammps_fix`; the message is the one line ``rigidmd
    export-lammps`` prints (exit status 2), so it names the configuration field
    (``"thermostat.kind: ..."``) and says what to use instead.
    """


@dataclass(frozen=True)
class Parameter:
    """One parameter of a coupling kind, as the configuration file spells it.

    Attributes
    ----------
    name : str
        Keyword of the class's constructor (``"temperature_K"``, ``"taut"``).
    field : str
        Key in the configuration section (``"temperature"``, ``"taut"``).
    quantity : str
        How the value is written and converted: ``"temperature"`` (``"300 K"``),
        ``"time"`` (``"100 fs"``, to ASE time), ``"rate"`` (``"0.01 1/fs"``, to
        1/ASE time), ``"pressure"`` (``"1 bar"``, to eV/Å³),
        ``"compressibility"`` (``"4.5e-5 1/bar"``, to Å³/eV), ``"integer"``,
        ``"seed"`` (an integer or absent, becomes ``rng``), ``"choice"``,
        ``"flag"`` (``true`` or ``false``).
    required : bool
    default : object
        Value used when the field is absent and not required.
    example : str
        Shown in the error message when the field is missing.
    choices : tuple of str
        Allowed values of a ``"choice"``.
    """

    name: str
    field: str
    quantity: str
    required: bool = True
    default: object = None
    example: str = ""
    choices: tuple = ()


@dataclass(frozen=True)
class LammpsFix:
    """What a coupling part is in a LAMMPS deck.

    Attributes
    ----------
    body_style : str
        Suffix of the rigid fix style (``"nve"``, ``"nvt"``, ``"npt"``) for
        ``fix ... rigid/<body_style>/small molecule``.
    body_keywords : str
        Keywords appended to that fix (``"temp 300 300 0.1"``, ``"langevin ..."``),
        in LAMMPS metal units.
    free_fixes : tuple of str
        Fix styles with arguments for the atoms in no body (``"nvt temp ..."``,
        ``"langevin ..."``), without ``fix ID group``.
    notes : tuple of str
        Where LAMMPS does something else than the part; written as comments.
    """

    body_style: str
    body_keywords: str = ""
    free_fixes: tuple = ()
    notes: tuple = ()


def register(cls):
    """Class decorator: add a coupling kind to :data:`COUPLINGS` under ``cls.kind``.

    Once registered (when the module defining the class is imported), the kind is
    what checkpoints store and rebuild (``cls(**part.todict())`` without ``kind``),
    what a configuration's ``thermostat:`` or ``barostat:`` section may name (the
    kind of a part of rigidmd's; a part of your own by its dotted path, with
    ``--trust``), and what the configuration reference lists.  A kind registered
    twice is refused.
    """
    if cls.kind in COUPLINGS:
        raise ValueError(f"coupling kind {cls.kind!r} registered twice")
    COUPLINGS[cls.kind] = cls
    return cls


#: What a coupling part sees: the one view of a step
#: (:class:`rigidmd.core.stepcontext.StepContext`), never the dynamics: the state, the body
#: model, the per-step record, the force evaluator, the step number, ``fixcom``,
#: ``cell_moves``, ``compiled`` and the barostat's ``cell_note``.
CouplingView = StepContext


class Coupling:
    r"""Base class of the parts a rigid dynamics is composed of.

    Subclasses set :attr:`kind`, :attr:`section` and :attr:`parameters`,
    validate their parameters in ``__init__`` (before any dynamics exists),
    check them against the system in :meth:`check`, create their variables
    in :meth:`bind`, and implement :meth:`first_half` (and
    :meth:`second_half` when the two half steps differ), :meth:`energy`,
    :meth:`get_state`, :meth:`set_state`, :meth:`todict` and
    :meth:`lammps_fix`.  A part that moves the cell (:attr:`moves_cell`)
    answers :meth:`drift_matrices`.

    In :meth:`rigidmd.RigidDynamics.step` the parts act in this order, each
    half step ``h`` being half the time step (ASE time units):

    .. code-block:: text

        get_state() of every part (kept to undo a step that fails)
        part_1.first_half(view, h) ... part_n.first_half(view, h)
        the scheme's deterministic step: kicks, drift, rotation, one force call
            (part.middle(view, h) between two half drifts, for parts that act there)
        part_n.second_half(view, h) ... part_1.second_half(view, h)

    If anything in the step raises, the state, the record and every part
    (:meth:`set_state` with what :meth:`get_state` gave) are restored and the
    error is raised again.  :meth:`energy` is read when the conserved energy is
    asked for (``dyn.get_conserved_energy()``, the log).

    A part belongs to one dynamics (:attr:`bound` after :meth:`bind`).
    """

    #: Name in the registry and in configuration files.
    kind: ClassVar[str] = ""
    #: Configuration section: ``"thermostat"`` or ``"barostat"``.
    section: ClassVar[str] = ""
    #: Parameters, in constructor order.
    parameters: ClassVar[tuple] = ()

    #: Whether the part was bound to a dynamics.
    bound = False
    #: Whether the dynamics must ask the calculator for the stress at every force call.
    needs_stress: ClassVar[bool] = False
    #: Whether the part moves the cell (a barostat; at most one per dynamics).
    moves_cell: ClassVar[bool] = False
    #: Whether the part reads the potential energy (``view.record.energy``) at every step,
    #: so that every force call asks the calculator for it (a Monte Carlo move's old energy).
    needs_energy: ClassVar[bool] = False
    #: Whether the part keeps the total momentum (a thermostat's ``fixcm``, resolved by
    #: :meth:`bind`).
    fixcm: bool = False
    #: The ``fixcm`` asked for; None: True unless a barostat moves the cell (:meth:`bind`).
    fixcm_option: bool | None = False
    #: Names of the columns the part adds to the MD log (values from :meth:`log_values`).
    log_columns: ClassVar[tuple] = ()
    #: Whether the part acts in the middle of the scheme's step (:meth:`middle`), between
    #: its two half drifts (the O of BAOAB); the scheme must then have a ``middle`` operator.
    acts_in_middle: ClassVar[bool] = False
    #: Whether a cell-moving part moves the cell in the scheme's drift
    #: (:meth:`drift_matrices` not a plain drift): such a drift cannot be cut in two around
    #: a :meth:`middle` action.
    drift_moves_cell: ClassVar[bool] = False

    def check(self, atoms: Atoms, model: BodyModel, dt: float) -> None:
        """Check the parameters against a system and time step; change nothing.

        Called by the dynamics' constructor after the atoms and bodies were
        validated and before anything is changed: raising here (``ValueError``
        with one line saying what to change) leaves everything as it was.  The
        base class refuses a part already bound and calls :meth:`check_timestep`;
        an override calls ``super().check(atoms, model, dt)``.

        Parameters
        ----------
        atoms : ase.Atoms
            The atoms, with their calculator.
        model : rigidmd.core.model.BodyModel
            The bodies: masses, moments, degrees of freedom.
        dt : float
            Time step (ASE time units).
        """
        if self.bound:
            raise ValueError(f"this {type(self).__name__} already belongs to another dynamics; "
                             "make a new one for each dynamics")
        self.check_timestep(dt)

    def check_timestep(self, dt: float) -> None:
        """Refuse a time step (ASE units) the part cannot work with; change nothing.

        Called by :meth:`check` and again when the time step changes.
        """

    def bind(self, view: CouplingView) -> None:
        """Attach to a dynamics (after :meth:`check`), creating the part's variables.

        Called once, by the dynamics' constructor, after every part was checked;
        ``view`` has the initial state and the record of the first force call.
        Sizes that depend on the system (degrees of freedom, chains) are set
        here.  An override calls ``super().bind(view)`` first.
        """
        self.bound = True

    def first_half(self, view: CouplingView, h: float) -> None:
        """Act on ``view.state`` for a time ``h`` before the integrator's step.

        Parameters
        ----------
        view : CouplingView
            The state to change in place (``view.state.V``, ``.p``, ``.v``) and
            the record to tell about the change (see :class:`CouplingView`).
        h : float
            Half the time step (ASE time units).
        """
        raise NotImplementedError

    def second_half(self, view: CouplingView, h: float) -> None:
        """Act for a time ``h`` after the integrator's step (by default as before it).

        The forces of ``view.record`` are then those of the new positions.
        """
        self.first_half(view, h)

    def middle(self, view: CouplingView, h: float) -> None:
        """Act for a time ``h`` in the middle of the scheme's step (:attr:`acts_in_middle`).

        Called by the scheme's ``middle`` operator, between its two half drifts,
        for each part that acts there, in the order of the parts.
        """
        raise NotImplementedError

    def reported_kinetic_energies(self, view: CouplingView) -> tuple | None:
        """(translational, rotational) kinetic energy (eV) the log and summary report, or None.

        None (the default): those of the state at the end of the step.  A part whose
        scheme samples the kinetic distribution elsewhere in the step (BAOAB: right
        after its O step) returns the values it kept there.
        """
        return None

    def drift_matrices(self, view: CouplingView, h: float) -> tuple:
        """A cell-moving part's drift over ``h``: ``(A, B, S, note)``; changes nothing.

        ``A, B, S`` as in :func:`rigidmd.core.operators.affine_drift`; ``note`` (or
        None) is kept in ``view.cell_note`` for the second half.
        """
        raise NotImplementedError

    def energy(self, view: CouplingView) -> float:
        """This part's term in the conserved energy (eV).

        The dynamics' ``get_conserved_energy()`` is the total energy plus the
        terms of every part: minus the energy a part has put in (a Langevin or
        Bussi thermostat), or the energy of its own variables (a Nosé–Hoover
        chain, a barostat's cell).  Zero by default.
        """
        return 0.0

    def log_values(self) -> tuple:
        """Values of :attr:`log_columns` now (numbers, one per column)."""
        return ()

    def get_state(self) -> dict:
        """The part's own variables, as a dict of floats, arrays and RNG states (copies).

        Called before every step (to undo a step that fails) and when a
        checkpoint is written: keep it cheap, and return copies (a checkpoint
        stores the dict: numbers, arrays, lists and dicts of them, the states
        :func:`rng_state` returns).  Parameters are not state: they come back
        through :meth:`todict`.
        """
        return {}

    def set_state(self, state: dict) -> None:
        """Restore variables returned by :meth:`get_state`.

        Called after a failed step and when a dynamics is rebuilt from a
        checkpoint (on a new part made from :meth:`todict` and bound).
        """

    def lammps_fix(self, time_unit: float, seed=None) -> "LammpsFix":
        """The LAMMPS equivalent (:class:`LammpsFix`); raises :class:`NotExportable` if none.

        Parameters
        ----------
        time_unit : float
            LAMMPS's time unit in ASE time units (a damping time ``tau`` is
            written ``tau / time_unit``).
        seed : int, optional
            Seed for a stochastic fix.
        """
        raise NotExportable(f"{self.section} kind {self.kind!r} has no LAMMPS equivalent")

    def todict(self) -> dict:
        """Parameters of this part, for trajectories, logs and checkpoints.

        ``{"kind": kind, name: value, ...}`` with the constructor's keywords and
        plain values (numbers, strings, None): a checkpoint rebuilds the part as
        ``COUPLINGS[kind](**rest)``, and ``rigidmd run --resume`` compares it with
        the configuration's.
        """
        return {"kind": self.kind}


def check_rng(rng):
    """Accept what ASE's stochastic integrators accept as ``rng``.

    A :class:`numpy.random.Generator`, a :class:`numpy.random.RandomState`,
    or the module :mod:`numpy.random` itself (ASE's default); None gives a new
    unseeded Generator.  Each of these can save and restore its state, which
    the rollback of a failed step and checkpoints need.
    """
    if rng is None:
        return np.random.default_rng()
    if isinstance(rng, np.random.Generator) or isinstance(rng, np.random.RandomState) \
            or rng is np.random:
        return rng
    raise TypeError(f"rng must be a numpy.random.Generator, a numpy.random.RandomState or "
                    f"numpy.random, got {type(rng).__name__}")


def rng_state(rng):
    """A copy of the state of an ``rng`` accepted by :func:`check_rng`."""
    if isinstance(rng, np.random.Generator):
        return {"generator": dict(rng.bit_generator.state)}
    return {"legacy": rng.get_state(legacy=False)}


def rng_kind(rng) -> dict:
    """What kind of generator ``rng`` is, so that :func:`new_rng` can make another."""
    if isinstance(rng, np.random.Generator):
        return {"type": "generator", "bit_generator": type(rng.bit_generator).__name__}
    return {"type": "legacy"}


def new_rng(kind: dict):
    """A new generator of the kind :func:`rng_kind` described (its state set later)."""
    if kind["type"] == "generator":
        return np.random.Generator(getattr(np.random, kind["bit_generator"])())
    return np.random.RandomState()


def set_rng_state(rng, state):
    """Restore a state returned by :func:`rng_state`."""
    if "generator" in state:
        rng.bit_generator.state = state["generator"]
    else:
        rng.set_state(state["legacy"])


def check_composition(couplings, fixcom: bool):
    """Refuse what no dynamics can compose; returns the part that moves the cell, or None.

    Changes nothing: a thermostat's ``fixcm=None`` is resolved when it is bound
    (True, or False when a part moves the cell).
    """
    for i, part in enumerate(couplings):
        if not isinstance(part, Coupling):
            raise TypeError(f"couplings must be coupling parts (rigidmd.couplings.base), "
                            f"got {type(part).__name__}")
        if any(part is other for other in couplings[:i]):  # it would act twice a half step
            raise ValueError(f"couplings: the same {part.kind} part is given twice; give each "
                             "part once")
    movers = [part for part in couplings if part.moves_cell]
    if len(movers) > 1:
        raise ValueError(f"two parts move the cell ({movers[0].kind}, {movers[1].kind}); "
                         "use one barostat")
    if movers and any(part.fixcm_option for part in couplings):
        raise ValueError("thermostat fixcm=True with a barostat: the barostat's equations "
                         "count the centre of mass's degrees of freedom; use fixcm=False")
    middle = [part for part in couplings if part.acts_in_middle]
    if movers and middle and movers[0].drift_moves_cell:
        raise ValueError(f"{middle[0].kind} acts in the middle of the step, which cuts the "
                         f"drift in two, and the {movers[0].kind} barostat moves the cell in that "
                         "drift: not supported; use the Monte Carlo barostat for NPT")
    if movers and fixcom:
        raise ValueError("ase.constraints.FixCom with a barostat: the barostat's equations "
                         "count the centre of mass's degrees of freedom; remove FixCom")
    targets = [(part, part.temperature_K) for part in couplings
               if getattr(part, "temperature_K", None) is not None]
    for part, value in targets[1:]:
        first, reference = targets[0]
        if value != reference:
            raise ValueError(
                f"{part.section} temperature_K = {value:g} K differs from the {first.section}'s "
                f"{reference:g} K: one dynamics has one target temperature "
                "(set_temperature changes every part)")
    return movers[0] if movers else None


def export_parts(couplings) -> list[dict]:
    """Each coupling part as a checkpoint stores it: class, parameters, variables, generator.

    ``rng_owner`` is the index of the first part with the same generator
    object (a shared generator stays shared when the parts are rebuilt).
    """
    parts = []
    for part in couplings:
        rng = getattr(part, "rng", None)
        owner = None if rng is None else next(
            i for i, other in enumerate(couplings) if getattr(other, "rng", None) is rng)
        parts.append({"class": type(part).__name__, "parameters": part.todict(),
                      "state": part.get_state(), "rng_owner": owner,
                      "rng": None if rng is None else rng_kind(rng)})
    return parts


class Target:
    """The target temperature of one dynamics, held once and read by every part that has one.

    A part with a target temperature keeps its own value until it is bound; the dynamics
    then gives all such parts one :class:`Target` (:func:`share_target`), so that the
    thermostat and the barostat never disagree and one :meth:`set_temperature` changes it
    for all of them.

    Attributes
    ----------
    temperature_K : float or None
        The target (K); None for a dynamics without a part that has one.
    parts : list
        The parts that read it; each checks a new value (``checked_temperature``).
    """

    def __init__(self, temperature_K: float | None = None):
        self.temperature_K = temperature_K
        self.parts = []

    def set_temperature(self, temperature_K) -> None:
        """Change the target (K) for every part; each part checks it first, and a value one
        of them refuses changes nothing."""
        if not self.parts:
            raise ValueError("no part of this dynamics has a target temperature")
        values = [part.checked_temperature(temperature_K) for part in self.parts]
        self.temperature_K = values[0]


def share_target(couplings) -> Target:
    """One :class:`Target` for the parts of a dynamics that have a target temperature.

    Called after :func:`check_composition` (which refused parts with different targets);
    each such part (one with ``checked_temperature``) reads the target from now on.
    """
    parts = [part for part in couplings if hasattr(part, "checked_temperature")]
    target = Target(parts[0].temperature_K if parts else None)
    for part in parts:
        part.target = target
        target.parts.append(part)
    return target
