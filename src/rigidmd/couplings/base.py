r"""Coupling parts: the base of thermostats and barostats, their registry and their view.

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
evaluator and the step number).  The parts themselves live beside the
classes users construct: :mod:`rigidmd.couplings.thermostats`,
:mod:`rigidmd.couplings.barostats` and :mod:`rigidmd.couplings.montecarlo`.

:class:`Thermostat` is what the thermostats share (the target temperature,
``fixcm`` and the total momentum, the kinetic energies they act on and their
scaling, which the record follows); :class:`NoseHooverChain` is the chain the
Nosé–Hoover thermostat and the MTK barostat share.

:data:`COUPLINGS` maps each kind's name (``"langevin"``, ``"bussi"``,
``"nose_hoover"``, ``"monte_carlo"``, ...) to its class; the class's
:attr:`Coupling.parameters` say which parameters it takes, with which units, so
that the configuration checker, the command line and the LAMMPS export all read
one registry.
"""

import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from ase import Atoms, units

from rigidmd.core.backend import NUMPY, Backend
from rigidmd.core.forces import ForceEvaluator
from rigidmd.core.model import BodyModel
from rigidmd.core.record import StepRecord
from rigidmd.core.state import RigidState
from rigidmd.couplings import _numpy  # noqa: F401  (registers the backends' operations)

__all__ = ["Coupling", "CouplingView", "Parameter", "COUPLINGS", "register", "NotExportable",
           "LammpsFix", "NoseHooverChain", "NET_FORCE_FLOOR", "check_rng", "rng_state",
           "set_rng_state",
           "rng_kind", "new_rng", "check_composition", "export_parts",
           "check_temperature", "check_time", "check_flag", "check_positive_integer",
           "TEMPERATURE"]

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


@dataclass
class CouplingView:
    """What a coupling part sees: never the dynamics, only what a half step needs.

    Attributes
    ----------
    state : rigidmd.core.state.RigidState
        The body state the part acts on, changed in place: ``V`` (n_bodies, 3),
        centre-of-mass velocities in Å per ASE time unit; ``p`` (n_bodies, 4),
        NO_SQUISH quaternion momenta (amu Å² per ASE time unit); ``v``
        (n_free, 3), velocities of the atoms in no body; ``X``, ``q``, ``x``
        positions and orientations, which the parts leave alone.  A barostat's
        cell moves only through its drift query (:meth:`Coupling.drift_matrices`).
    model : rigidmd.core.model.BodyModel
        Masses (``mass``, amu, shape (n_bodies,); ``free_masses``, (n_free,)),
        principal moments (``moments``, amu Å², (n_bodies, 3)) and the counts of
        degrees of freedom (``translational_dof``, ``rotational_dof``).
    record : rigidmd.core.record.StepRecord
        Forces, virial and energy of the last force call; volume, kinetic
        tensor and the translational and rotational kinetic energies (eV),
        computed at most once.  A part that changes velocities or momenta must
        tell it, right after the change: ``scale_translation(factor)`` (or
        ``scale_translation_about(factor, centre, mass)``) and
        ``scale_rotation(factor)`` for a scaling (the kinetic sums follow it
        without a new sum over the bodies), ``velocities_changed()`` for any
        other change (the next reader sums again).  :meth:`Thermostat.scale`
        scales and tells.
    evaluator : rigidmd.core.forces.ForceEvaluator
        Energy-only questions about trial configurations
        (``save_results``, ``trial_energy``, ``restore_results``) and the forces
        of an accepted one (``evaluate``).
    step : int
        Steps completed before the one being taken.
    fixcom : bool
        The total momentum is held at zero (ASE's ``FixCom`` on the atoms).
    cell_moves : bool
        A part of the dynamics moves the cell (a barostat).
    """

    state: RigidState
    model: BodyModel
    record: StepRecord
    evaluator: ForceEvaluator
    step: int = 0
    fixcom: bool = False
    cell_moves: bool = False

    @property
    def backend(self) -> Backend:
        """The backend the parts run on (the record's link's): each operation with a
        compiled kernel is a method of it (:mod:`rigidmd.core.backend`)."""
        return self.record.backend


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
        None) is kept in ``view.record.cell_move`` for the second half.
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


def check_temperature(temperature_K):
    """``temperature_K`` as a float, >= 0 and finite, or a clear error."""
    try:
        value = float(temperature_K)
    except (TypeError, ValueError):
        raise TypeError(f"temperature_K must be a number (K), got {temperature_K!r}") from None
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"temperature_K must be >= 0 K, got {temperature_K!r}")
    return value


def check_time(name, value):
    """A positive finite time (ASE units) as a float, or a clear error naming ``name``."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a time in ASE units, got {value!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive time (ASE units), got {value!r}")
    return value


def check_flag(name, value):
    """A bool (``True``/``False``, not a string or number), or a clear error naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_positive_integer(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


#: The ``temperature`` field of a thermostat's or barostat's section (``temperature_K``).
TEMPERATURE = Parameter("temperature_K", "temperature", "temperature", example="300 K")


class NoseHooverChain:
    r"""One Nosé–Hoover chain acting on a group of :math:`N_f` degrees of freedom.

    Masses :math:`Q_1 = N_f k_B T \tau^2`, :math:`Q_{j>1} = k_B T \tau^2`;
    propagated by the Trotter factorisation of Martyna, Tuckerman, Tobias and
    Klein (1996) with ``tloop`` sub-steps.  Its energy is
    :math:`\sum_j \tfrac12 Q_j \xi_j^2 + N_f k_B T \eta_1 + k_B T \sum_{j>1}\eta_j`.

    Parameters
    ----------
    ndof : int
        Degrees of freedom of the group it acts on.
    tdamp : float
        Time constant (ASE time units).
    tchain, tloop : int

    """

    def __init__(self, ndof, tdamp, tchain, tloop):
        self.ndof, self.tdamp, self.tchain, self.tloop = ndof, tdamp, tchain, tloop
        self.xi = np.zeros(tchain)
        self.eta = np.zeros(tchain)

    def masses(self, kT):
        Q = np.full(self.tchain, kT * self.tdamp**2)
        Q[0] *= self.ndof
        return Q

    def propagate(self, K, kT, h, backend: Backend = NUMPY):
        """Advance over ``h`` with the group's kinetic energy ``K``; returns its velocity scale.

        On ``backend`` (the caller's ``view.backend``):
        :func:`rigidmd.couplings._numpy.chain_propagate` or its kernel.
        """
        return backend.chain_propagate(self.xi, self.eta, self.ndof, kT * self.tdamp**2, K, kT,
                                       h, self.tloop)

    def act_on(self, p, mass, kT, h, backend: Backend = NUMPY):
        r"""Advance over ``h`` on a momentum of kinetic energy :math:`\sum p^2 / 2m`; scale it.

        ``p`` (2-D, changed in place) is the momentum the chain acts on, ``mass`` its
        mass (a barostat's cell momentum :math:`p_g` and mass :math:`W`).
        """
        backend.chain_scale(p, mass, self.xi, self.eta, self.ndof, kT * self.tdamp**2, kT, h,
                            self.tloop)

    def energy(self, kT):
        if self.ndof == 0:
            return 0.0
        Q = self.masses(kT)
        return float(0.5 * np.sum(Q * self.xi**2) + self.ndof * kT * self.eta[0]
                     + kT * np.sum(self.eta[1:]))

    def get_state(self):
        return {"xi": self.xi.copy(), "eta": self.eta.copy()}

    def set_state(self, state):
        self.xi[...] = state["xi"]
        self.eta[...] = state["eta"]


#: Net force (eV/Å) below which the forces count as conserving the momentum whatever
#: their size: on a 216-water box it moves the centre 1.2 Å and does 1.2e-6 eV of work in
#: a nanosecond (kT is 0.026 eV), while roundoff sums to ~1e-17 (measured: 8 LJ dimers with
#: no pair in range, which the relative bound alone warned about).
NET_FORCE_FLOOR = 1e-6


def fixcm_parameter(default):
    return Parameter("fixcm", "fixcm", "flag", required=False, default=default)


class Thermostat(Coupling):
    r"""Shared parts of the thermostats: the target temperature and kinetic energies.

    With ``fixcm`` the thermostat leaves the total momentum
    :math:`P = \sum_b M_b V_b + \sum_{free} m v` (and so the centre of mass's
    motion) as it finds it: it acts on the velocities relative to the centre
    of mass velocity :math:`U = P / M` and on :math:`N_f - 3` translational
    degrees of freedom, as ASE's ``Langevin(fixcm=True)`` does.  Long
    thermostatted runs then do not drift as a whole (a drift adds to a
    measured diffusion coefficient).

    ``fixcm=None`` (the default of the parts) becomes True when the part is
    bound to a dynamics, or False if a barostat moves the cell (the barostats'
    equations count the centre of mass; an explicit ``fixcm=True`` with a
    barostat is refused).  Without it a global thermostat (Bussi,
    Nosé–Hoover) rescales the total momentum with every other velocity; the
    forces conserve it, so a zero momentum stays zero and the kinetic energy
    of :math:`N_f` degrees of freedom lands on :math:`N_f - 3`: the system
    then samples :math:`T N_f / (N_f - 3)`, 0.23 % above the target for 216
    rigid waters and 1.9 % for 27.

    A subclass calls ``super().__init__(temperature_K, fixcm)`` and
    ``super().bind(view)`` (which resolves ``fixcm`` and counts
    :attr:`n_translational`), reads what it acts on with :meth:`kinetic_energies`
    and changes it with :meth:`scale`, which also tells the record.
    """

    section = "thermostat"

    def __init__(self, temperature_K, fixcm=None):
        self.temperature_K = check_temperature(temperature_K)
        #: What was asked: True, False or None (True unless a barostat moves the cell).
        self.fixcm_option = None if fixcm is None else check_flag("fixcm", fixcm)
        #: Whether the total momentum is kept; None until :meth:`bind` resolves the option.
        self.fixcm = self.fixcm_option

    @property
    def kT(self):
        """:math:`k_B T` (eV)."""
        return units.kB * self.temperature_K

    def set_temperature(self, temperature_K):
        """Change the target temperature (K), as ASE's thermostats do."""
        self.temperature_K = check_temperature(temperature_K)

    def bind(self, view: CouplingView) -> None:
        super().bind(view)
        #: Whether the thermostat keeps the total momentum: ``fixcm``, or for None
        #: whether no part moves the cell.
        self.fixcm = not view.cell_moves if self.fixcm_option is None else self.fixcm_option
        #: The total momentum is kept: by ``fixcm`` or by ASE's ``FixCom`` on the atoms.
        self.holds_momentum = self.fixcm or view.fixcom
        n = view.model.translational_dof
        #: Translational degrees of freedom the thermostat acts on (3 fewer when it
        #: keeps the total momentum).
        self.n_translational = max(n - 3, 0) if self.holds_momentum else n
        #: Whether :meth:`second_half` looks at the net force: the momentum is kept by
        #: the default (``fixcm=None``), which a wall or a field makes wrong.
        self.watches_net_force = self.fixcm_option is None and self.fixcm

    #: Whether :meth:`check_net_force` has warned (once per thermostat).
    warned = False
    watches_net_force = False

    def check_net_force(self, view: CouplingView) -> None:
        """Warn once if the forces do not conserve the momentum that ``fixcm=None`` keeps.

        A wall or an external field makes the centre of mass a thermal degree of
        freedom: keeping the momentum then holds the rest at the target and leaves
        it out of the count.  Pair forces cancel to roundoff and PPPM/PME to about
        1e-5 of a force per atom; the threshold is 1e-3 of the summed magnitudes, and
        at least :data:`NET_FORCE_FLOOR` (forces that are all roundoff, no pair in
        range, sum to ~1e-17 eV/Å, which no relative bound tells from a field).
        Called once per step, on the forces of the step's (last) force call.
        """
        net, size = view.record.net_force()
        if net <= max(NET_FORCE_FLOOR, 1e-3 * size):
            return
        self.warned = True
        if view.fixcom:  # ASE's FixCom holds it too: fixcm=False alone changes nothing
            advice = ("ASE's FixCom on the atoms and the thermostat's default fixcm=None "
                      "both keep it; remove FixCom from atoms.constraints and pass "
                      "fixcm=False")
        else:
            advice = "pass fixcm=False"
        warnings.warn(
            f"{self.kind} thermostat: the total momentum is kept (fixcm=None, the default, "
            f"keeps it when no barostat moves the cell) but the forces do not conserve it "
            f"(net force {net:.3g} eV/Å at step {view.step + 1}): with a wall or an "
            f"external field the centre of mass is a thermal degree of freedom; {advice}",
            stacklevel=2)

    def second_half(self, view: CouplingView, h: float) -> None:
        """The first half's action; once per step, the net-force check of the default fixcm."""
        if self.watches_net_force and not self.warned:
            self.check_net_force(view)
        self.first_half(view, h)

    def centre(self, view: CouplingView) -> tuple[np.ndarray, float]:
        """:math:`U = P / M` (Å / ASE time, shape (3,)) and the total mass :math:`M` (amu)."""
        s, m = view.state, view.model
        M = m.mass.sum() + m.free_masses.sum()
        return (m.mass @ s.V + m.free_masses @ s.v) / M, M

    def centre_velocity(self, view: CouplingView) -> np.ndarray:
        """:math:`U = P / M` (Å / ASE time), shape (3,); zero unless the momentum is kept."""
        return self.centre(view)[0] if self.holds_momentum else np.zeros(3)

    def set_centre_velocity(self, view: CouplingView, U: np.ndarray) -> None:
        """Shift all translational velocities so that :math:`P/M` is ``U`` again."""
        if self.holds_momentum:
            shift = U - self.centre_velocity(view)
            s = view.state
            s.V += shift
            s.v += shift

    def kinetic_energies(self, view: CouplingView) -> tuple[float, float]:
        """(translational, rotational) kinetic energy the thermostat acts on (eV).

        When the momentum is kept the translational part is that relative
        to the centre of mass.
        """
        record = view.record
        if not self.holds_momentum:
            return record.translational_energy, record.rotational_energy
        U, M = self.centre(view)
        return record.translational_energy - 0.5 * M * float(U @ U), record.rotational_energy

    def scale(self, view: CouplingView, translational: float, rotational: float) -> None:
        """Multiply translational velocities (relative to U) and angular momenta.

        The record's kinetic sums follow the scaling (no new sum over bodies).
        """
        s, record = view.state, view.record
        if self.holds_momentum:
            U, M = self.centre(view)
            s.V[...] = U + translational * (s.V - U)
            s.v[...] = U + translational * (s.v - U)
            s.p *= rotational
            record.scale_translation_about(translational, U, M)
        else:  # the three scalings in one pass over the state buffer
            view.backend.scale_velocities(s.data, len(s.X), len(s.x), float(translational),
                                          float(rotational))
            record.scale_translation(translational)
        record.scale_rotation(rotational)

    def fixcm_notes(self):
        """What the deck says about ``fixcm``, which LAMMPS's rigid thermostats do not have."""
        if self.fixcm is False:
            return ()
        when = "(fixcm=True)" if self.fixcm else "unless a barostat moves the cell (fixcm=None)"
        return (f"rigidmd's {self.kind} thermostat keeps the total momentum {when}; "
                "LAMMPS's rigid thermostat acts on it too, so statistics differ by 3 "
                "degrees of freedom",)

    def todict(self):
        """The parameters as given: ``fixcm`` None stays None (a dynamics resolves it)."""
        return {"kind": self.kind, "temperature_K": self.temperature_K,
                "fixcm": self.fixcm_option}


def check_composition(couplings, fixcom: bool):
    """Refuse what no dynamics can compose; returns the part that moves the cell, or None.

    Changes nothing: a thermostat's ``fixcm=None`` is resolved when it is bound
    (True, or False when a part moves the cell).
    """
    for part in couplings:
        if not isinstance(part, Coupling):
            raise TypeError(f"couplings must be coupling parts (rigidmd.couplings.base), "
                            f"got {type(part).__name__}")
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
