r"""What the thermostats and barostats share, on the coupling interface of the core.

The interface itself (:class:`~rigidmd.core.coupling.Coupling`,
:class:`~rigidmd.core.coupling.CouplingView`, the registry
:data:`~rigidmd.core.coupling.COUPLINGS`, ...) is :mod:`rigidmd.core.coupling`;
this module re-exports its names, as :mod:`rigidmd.couplings` does.  The parts
themselves live beside the classes users construct:
:mod:`rigidmd.couplings.thermostats`, :mod:`rigidmd.couplings.barostats`,
:mod:`rigidmd.couplings.baoab` and :mod:`rigidmd.couplings.montecarlo`.

:class:`Thermostat` is what the thermostats share (the target temperature,
``fixcm`` and the total momentum, the kinetic energies they act on and their
scaling, which the record follows); :class:`NoseHooverChain` is the chain the
Nosé–Hoover thermostat and the MTK barostat share; ``check_*`` check a part's
parameters before any dynamics exists.
"""

import warnings

import numpy as np
from ase import units

from rigidmd.core.backend import NUMPY, Backend
from rigidmd.core.checks import real_number
from rigidmd.core.coupling import (
    COUPLINGS,
    Coupling,
    CouplingView,
    LammpsFix,
    NotExportable,
    Parameter,
    check_composition,
    check_rng,
    export_parts,
    new_rng,
    register,
    rng_kind,
    rng_state,
    set_rng_state,
)
from rigidmd.couplings import _numpy  # noqa: F401  (registers the backends' operations)

__all__ = ["Coupling", "CouplingView", "Parameter", "COUPLINGS", "register", "NotExportable",
           "LammpsFix", "NoseHooverChain", "Thermostat", "TargetTemperature", "NET_FORCE_FLOOR",
           "check_rng", "rng_state", "set_rng_state", "rng_kind", "new_rng", "check_composition",
           "export_parts", "check_temperature", "check_time", "check_flag",
           "check_positive_integer", "TEMPERATURE"]


def check_temperature(temperature_K):
    """``temperature_K`` as a float, >= 0 and finite, or a clear error."""
    value = real_number("temperature_K", temperature_K, "a number (K)")
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"temperature_K must be >= 0 K, got {temperature_K!r}")
    return value


def check_time(name, value):
    """A positive finite time (ASE units) as a float, or a clear error naming ``name``."""
    value = real_number(name, value, "a time in ASE units")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive time (ASE units), got {value!r}")
    return value


def check_flag(name, value):
    """A bool (``True``/``False``, not a string or number), or a clear error naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


#: The largest chain lengths and loop counts: a step does the work of each in turn and is
#: never interrupted (``tloop: 10**9`` took 570 s a step, ``tchain: 10**11`` asked for
#: 745 GiB); ASE's and LAMMPS's defaults are 3 and 1.
INTEGER_LIMITS = {"tchain": 100, "pchain": 100, "tloop": 100, "ploop": 100}


def check_positive_integer(name, value):
    """``value`` as an int from 1 to :data:`INTEGER_LIMITS` ``[name]`` (no limit when
    absent), else a ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    most = INTEGER_LIMITS.get(name)
    if most is not None and value > most:
        raise ValueError(f"{name} must be at most {most}, got {value!r}")
    return int(value)


#: The ``temperature`` field of a thermostat's or barostat's section (``temperature_K``).
TEMPERATURE = Parameter("temperature_K", "temperature", "temperature", example="300 K")


class TargetTemperature:
    """A part with a target temperature: its own until bound, then its dynamics' one.

    The dynamics gives its parts one :class:`rigidmd.core.coupling.Target`
    (:func:`rigidmd.core.coupling.share_target`); :attr:`temperature_K` reads it, and
    :meth:`set_temperature` changes it for every part of the dynamics (each part checks
    the value first, with :meth:`checked_temperature`).
    """

    #: The dynamics' shared target (:class:`rigidmd.core.coupling.Target`); None until bound.
    target = None
    _temperature_K = None

    @property
    def temperature_K(self) -> float:
        """The target temperature (K): the dynamics' shared one once bound; assigning it is
        :meth:`set_temperature`."""
        target = self.target
        return self._temperature_K if target is None else target.temperature_K

    @temperature_K.setter
    def temperature_K(self, value) -> None:
        self.set_temperature(value)

    @property
    def kT(self) -> float:
        """:math:`k_B T` (eV)."""
        return units.kB * self.temperature_K

    def checked_temperature(self, temperature_K) -> float:
        """``temperature_K`` as a float if this part can work at it, or a clear error."""
        return check_temperature(temperature_K)

    def set_temperature(self, temperature_K) -> None:
        """Change the target temperature (K), as ASE's thermostats do: for every part of the
        dynamics once bound (each checks it first)."""
        if self.target is None:
            self._temperature_K = self.checked_temperature(temperature_K)
        else:
            self.target.set_temperature(temperature_K)


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


class Thermostat(TargetTemperature, Coupling):
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
        self._temperature_K = self.checked_temperature(temperature_K)
        #: What was asked: True, False or None (True unless a barostat moves the cell).
        self.fixcm_option = None if fixcm is None else check_flag("fixcm", fixcm)
        #: Whether the total momentum is kept; None until :meth:`bind` resolves the option.
        self.fixcm = self.fixcm_option

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

        Written in place, then :meth:`rigidmd.core.record.StepRecord.scaled`: the
        record's kinetic sums follow the scaling (no new sum over bodies).
        """
        s, record = view.state, view.record
        if self.holds_momentum:
            U, M = self.centre(view)
            s.V[...] = U + translational * (s.V - U)
            s.v[...] = U + translational * (s.v - U)
            s.p[...] *= rotational
            record.scaled(translational, rotational, about=(U, M))
            return
        # the three scalings in one pass over the state buffer
        view.backend.scale_velocities(s.data, len(s.X), len(s.x), float(translational),
                                      float(rotational))
        record.scaled(translational, rotational)

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

