r"""Thermostats: the coupling parts and the dynamics classes users construct.

The parts (:class:`LangevinThermostat`, :class:`BussiThermostat`,
:class:`NoseHooverThermostat`; registered in :data:`rigidmd.couplings.base.COUPLINGS`)
act on the rigid degrees of freedom (centre-of-mass velocities, body-frame
angular momenta about the axes with a moment, point particles) for half a
step before and after the deterministic step.  Temperatures count degrees of
freedom as ASE does: no centre-of-mass correction unless the total momentum
is kept (``fixcm=True`` or ASE's ``FixCom``), which removes 3, as LAMMPS
always does (``6N - 3`` for N rigid waters).  ``fixcm`` defaults to True
unless a barostat moves the cell (see :class:`Thermostat`).

:class:`RigidLangevin`, :class:`RigidBussi` and :class:`RigidNoseHoover` take
the arguments of ASE's ``Langevin`` (``friction``), ``Bussi`` (``taut``) and
``NoseHooverChainNVT`` (``tdamp``, ``tchain``, ``tloop``), plus the rigid
arguments of :class:`~rigidmd.core.dynamics.RigidDynamics` (``bodies``,
``integrator``, ...): each is a :class:`~rigidmd.core.dynamics.RigidDynamics` with
one thermostat part.  ``get_conserved_energy()`` returns the energy that the
thermostatted dynamics conserves: total energy minus the energy the
thermostat put in (Langevin, Bussi), or plus the chains' energy (Nosé–Hoover).
"""

import warnings

import numpy as np
from ase import units

from rigidmd.core import operators as ops
from rigidmd.core.dynamics import RigidDynamics
from rigidmd.couplings import _kernels
from rigidmd.couplings.base import (
    TEMPERATURE,
    Coupling,
    CouplingView,
    LammpsFix,
    NoseHooverChain,
    NotExportable,
    Parameter,
    check_flag,
    check_positive_integer,
    check_rng,
    check_temperature,
    check_time,
    register,
    rng_state,
    set_rng_state,
)

__all__ = ["RigidLangevin", "RigidBussi", "RigidNoseHoover", "Thermostat",
           "LangevinThermostat", "BussiThermostat", "NoseHooverThermostat"]


SEED = Parameter("rng", "seed", "seed", required=False)

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

    ``fixcm=None`` (the default of the parts) becomes True when the dynamics
    is composed, or False if a barostat moves the cell (the barostats'
    equations count the centre of mass; an explicit ``fixcm=True`` with a
    barostat is refused).  Without it a global thermostat (Bussi,
    Nosé–Hoover) rescales the total momentum with every other velocity; the
    forces conserve it, so a zero momentum stays zero and the kinetic energy
    of :math:`N_f` degrees of freedom lands on :math:`N_f - 3`: the system
    then samples :math:`T N_f / (N_f - 3)`, 0.23 % above the target for 216
    rigid waters and 1.9 % for 27.
    """

    section = "thermostat"

    def __init__(self, temperature_K, fixcm=None):
        self.temperature_K = check_temperature(temperature_K)
        #: What was asked: True, False or None (True unless a barostat moves the cell).
        self.fixcm_option = None if fixcm is None else check_flag("fixcm", fixcm)
        #: Whether the total momentum is kept; None until a dynamics resolves the option.
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
        #: The total momentum is kept: by ``fixcm`` or by ASE's ``FixCom`` on the atoms.
        self.holds_momentum = self.fixcm or view.fixcom
        n = view.model.translational_dof
        #: Translational degrees of freedom the thermostat acts on (3 fewer when it
        #: keeps the total momentum).
        self.n_translational = max(n - 3, 0) if self.holds_momentum else n

    #: Whether :meth:`check_net_force` has warned (once per thermostat).
    warned = False
    #: Calls of :meth:`check_net_force`; it looks at every 8th (8 µs of NumPy for 216
    #: bodies, a wall's contact lasts many steps).
    net_force_calls = 0

    def check_net_force(self, record) -> None:
        """Warn once if the forces do not conserve the momentum that ``fixcm=None`` keeps.

        A wall or an external field makes the centre of mass a thermal degree of
        freedom: keeping the momentum then holds the rest at the target and leaves
        it out of the count.  Pair forces cancel to roundoff and PPPM/PME to about
        1e-5 of a force per atom; the threshold is 1e-3 of the summed magnitudes, and
        at least :data:`NET_FORCE_FLOOR` (forces that are all roundoff, no pair in
        range, sum to ~1e-17 eV/Å, which no relative bound tells from a field).
        """
        self.net_force_calls += 1
        if self.net_force_calls % 8 != 1:
            return
        net = float(np.linalg.norm(record.F.sum(axis=0) + record.f.sum(axis=0)))
        if net > max(NET_FORCE_FLOOR,
                     1e-3 * float(np.abs(record.F).sum() + np.abs(record.f).sum())):
            self.warned = True
            warnings.warn(
                f"{self.kind} thermostat: it keeps the total momentum (fixcm=True, the "
                f"default) but the forces do not conserve it (net force {net:.3g} eV/Å): "
                "with a wall or an external field the centre of mass is a thermal degree "
                "of freedom; pass fixcm=False", stacklevel=2)

    def centre_velocity(self, view: CouplingView) -> np.ndarray:
        """:math:`U = P / M` (Å / ASE time), shape (3,); zero unless the momentum is kept."""
        s, m = view.state, view.model
        if not self.holds_momentum:
            return np.zeros(3)
        P = m.mass @ s.V + m.free_masses @ s.v
        return P / (m.mass.sum() + m.free_masses.sum())

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
        m, record = view.model, view.record
        if not self.holds_momentum:
            return record.translational_energy, record.rotational_energy
        if self.fixcm_option is None and not self.warned:
            self.check_net_force(record)
        U = self.centre_velocity(view)
        K_cm = 0.5 * (m.mass.sum() + m.free_masses.sum()) * float(U @ U)
        return record.translational_energy - K_cm, record.rotational_energy

    def scale(self, view: CouplingView, translational: float, rotational: float) -> None:
        """Multiply translational velocities (relative to U) and angular momenta."""
        s, record = view.state, view.record
        if self.holds_momentum:
            U = self.centre_velocity(view)
            s.V[...] = U + translational * (s.V - U)
            s.v[...] = U + translational * (s.v - U)
            record.velocities_changed()
            s.p *= rotational
            return
        if view.compiled:  # the three scalings in one pass over the state buffer
            _kernels.scale_velocities(s.data, len(s.X), len(s.x), float(translational),
                                      float(rotational))
        else:
            s.V *= translational
            s.v *= translational
            s.p *= rotational
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
        return {"kind": self.kind, "temperature_K": self.temperature_K, "fixcm": self.fixcm}


class _Stochastic(Thermostat):
    """A thermostat that draws random numbers and keeps count of the energy it adds."""

    def __init__(self, temperature_K, rng=None, fixcm=None):
        super().__init__(temperature_K, fixcm)
        self.rng = check_rng(rng)
        #: Energy the thermostat has put into the system so far (eV).
        self.work = 0.0

    def energy(self, view: CouplingView | None = None) -> float:
        """Minus the energy the thermostat has added: total + this is conserved (eV)."""
        return -self.work

    def get_state(self):
        return {"work": self.work, "rng": rng_state(self.rng)}

    def set_state(self, state):
        self.work = float(state["work"])
        set_rng_state(self.rng, state["rng"])


@register
class LangevinThermostat(_Stochastic):
    r"""Langevin friction and noise on every rigid degree of freedom.

    Each half step :math:`h` is the exact Ornstein–Uhlenbeck update, with
    :math:`c = e^{-\gamma h}` and :math:`\xi \sim \mathcal N(0, 1)`:

    .. math::
        V \leftarrow c V + \sqrt{(1 - c^2) k_B T / M}\;\xi,\qquad
        L_{b,k} \leftarrow c L_{b,k} + \sqrt{(1 - c^2) k_B T I_k}\;\xi

    (not about a zero-moment axis), and likewise for point particles, as
    LAMMPS ``fix rigid/nve ... langevin`` does.  Around a deterministic step
    this is the O–(NO_SQUISH)–O splitting, canonical with :math:`O(\Delta t^2)`
    errors.

    Parameters
    ----------
    temperature_K : float
        K.
    friction : float
        :math:`\gamma`, per ASE time unit (``0.01 / ase.units.fs`` is 0.01 fs⁻¹),
        as in ASE's ``Langevin``.  ``friction * timestep`` must not exceed 0.5.
    rng : numpy.random.Generator, optional
    fixcm : bool or None, default None
        Keep the total momentum (see :class:`Thermostat`), as ASE's ``Langevin``;
        None: True unless a barostat moves the cell.
    """

    kind = "langevin"
    parameters = (TEMPERATURE, Parameter("friction", "friction", "rate", example="0.01 1/fs"),
                  SEED, fixcm_parameter(None))

    def __init__(self, temperature_K, friction, rng=None, fixcm=None):
        super().__init__(temperature_K, rng, fixcm)
        self.friction = self._check_friction(friction)

    @staticmethod
    def _check_friction(friction):
        try:
            gamma = float(friction)
        except (TypeError, ValueError):
            raise TypeError(f"friction must be a number per ASE time unit, got {friction!r}"
                            ) from None
        if not (np.isfinite(gamma) and gamma >= 0):
            raise ValueError(f"friction must be >= 0 (per ASE time unit), got {friction!r}")
        return gamma

    def check_timestep(self, dt):
        """Refuse ``friction * dt > 0.5``: almost surely friction given in the wrong unit."""
        # Typical values give friction * timestep ~ 0.001-0.05; above 0.5 the
        # velocities forget themselves within a step.
        if self.friction * dt > 0.5:
            raise ValueError(
                f"friction = {self.friction:g} per ASE time unit damps the velocities within "
                f"one step of {dt:g}: friction is in 1/(ASE time), e.g. "
                f"0.01 / ase.units.fs = {0.01 / units.fs:.4g}, not in 1/fs or 1/ps"
            )

    def set_friction(self, friction: float, timestep: float | None = None) -> None:
        """Change the friction (per ASE time unit), checked against ``timestep`` when given."""
        gamma = self._check_friction(friction)
        old, self.friction = self.friction, gamma
        if timestep is not None:
            try:
                self.check_timestep(timestep)
            except ValueError:
                self.friction = old
                raise

    def first_half(self, view: CouplingView, h: float) -> None:
        s, m, kT, rng, record = view.state, view.model, self.kT, self.rng, view.record
        if self.holds_momentum and self.fixcm_option is None and not self.warned:
            self.check_net_force(record)
        before = record.translational_energy + record.rotational_energy
        U = self.centre_velocity(view)
        c = np.exp(-self.friction * h)
        sigma = np.sqrt((1.0 - c * c) * kT)
        s.V[...] = c * s.V + sigma * rng.standard_normal(s.V.shape) / np.sqrt(m.mass)[:, None]
        s.v[...] = c * s.v + sigma * rng.standard_normal(s.v.shape) / np.sqrt(
            m.free_masses)[:, None]
        L_body = ops.body_angular_momentum(s.q, s.p)
        noise = sigma * np.sqrt(m.moments) * rng.standard_normal(L_body.shape)
        s.p[...] = ops.conjugate_momentum(s.q, c * L_body + noise)
        self.set_centre_velocity(view, U)
        record.velocities_changed()
        self.work += record.translational_energy + record.rotational_energy - before

    def lammps_fix(self, time_unit, seed=12345):
        """``langevin`` keyword of ``rigid/nve/small`` and ``fix langevin`` on free atoms.

        ``time_unit`` is the LAMMPS time unit in ASE time units; LAMMPS's
        damping time is ``1 / friction``.
        """
        if self.friction == 0:
            raise NotExportable("thermostat.friction: LAMMPS needs a positive friction")
        args = (f"{self.temperature_K!r} {self.temperature_K!r} "
                f"{1.0 / self.friction / time_unit!r} {int(seed)}")
        return LammpsFix("nve", f"langevin {args}", ("nve", f"langevin {args}"),
                         notes=self.fixcm_notes())

    def todict(self):
        return super().todict() | {"friction": self.friction}


def bussi_kinetic_energy(K, K_target, ndof, c, rng):
    r"""New kinetic energy of stochastic velocity rescaling (Bussi et al. 2007, eq. A7).

    .. math::
        K' = cK + (1-c)\frac{\bar K}{N_f}\Big(R_1^2 + \sum_{i=2}^{N_f} R_i^2\Big)
             + 2 R_1 \sqrt{c (1-c) K \bar K / N_f}

    with :math:`R_i \sim \mathcal N(0, 1)` and :math:`\sum_{i\ge2} R_i^2`
    drawn as a :math:`\chi^2_{N_f-1}`.

    Returns
    -------
    new : float
        :math:`K'` (eV).
    sign : float
        Sign of the rescaling factor.
    """
    r1 = rng.standard_normal()
    rest = 2.0 * rng.standard_gamma(0.5 * (ndof - 1)) if ndof > 1 else 0.0
    ratio = K_target / ndof
    new = (c * K + (1.0 - c) * ratio * (r1 * r1 + rest)
           + 2.0 * r1 * np.sqrt(c * (1.0 - c) * K * ratio))
    sign = np.sign(r1 + np.sqrt(c * K / ((1.0 - c) * ratio))) if c < 1 else 1.0
    return new, sign


@register
class BussiThermostat(_Stochastic):
    r"""Stochastic velocity rescaling (Bussi, Donadio & Parrinello 2007).

    The translational kinetic energy (centres of mass and point particles)
    and the rotational kinetic energy are each rescaled, half a step before
    and after the deterministic step, to a value drawn so that each samples
    its canonical distribution with :math:`N_f` degrees of freedom and
    relaxes with time constant ``taut``.

    Parameters
    ----------
    temperature_K : float
        K.
    taut : float
        Relaxation time (ASE time units), as in ASE's ``Bussi``.
    rng : numpy.random.Generator, optional
    fixcm : bool or None, default None
        Keep the total momentum (see :class:`Thermostat`); None: True unless a
        barostat moves the cell.

    References
    ----------
    G. Bussi, D. Donadio and M. Parrinello, J. Chem. Phys. 126, 014101 (2007).
    """

    kind = "bussi"
    parameters = (TEMPERATURE, Parameter("taut", "taut", "time", example="100 fs"), SEED,
                  fixcm_parameter(None))

    def __init__(self, temperature_K, taut, rng=None, fixcm=None):
        super().__init__(temperature_K, rng, fixcm)
        self.taut = check_time("taut", taut)

    def first_half(self, view: CouplingView, h: float) -> None:
        c = np.exp(-h / self.taut)
        factors = []
        for K, ndof in zip(self.kinetic_energies(view),
                           (self.n_translational, view.model.rotational_dof), strict=True):
            if ndof == 0 or K <= 0:
                factors.append(1.0)
                continue
            new, sign = bussi_kinetic_energy(K, 0.5 * ndof * self.kT, ndof, c, self.rng)
            self.work += new - K
            factors.append(sign * np.sqrt(new / K))
        self.scale(view, *factors)

    def lammps_fix(self, time_unit, seed=12345):
        raise NotExportable("thermostat.kind: LAMMPS has no Bussi thermostat for rigid bodies; "
                            "use langevin or nose_hoover")

    def todict(self):
        return super().todict() | {"taut": self.taut}


@register
class NoseHooverThermostat(Thermostat):
    r"""Nosé–Hoover chains on translation and rotation (LAMMPS ``fix rigid/nvt``).

    Two :class:`NoseHooverChain` of length ``tchain``, one on the
    translational and one on the rotational degrees of freedom (Kamberaj,
    Low & Neal 2005), each propagated for half a step before and after the
    deterministic step.  :meth:`energy` is the chains' energy.

    Parameters
    ----------
    temperature_K : float
        K, positive: the chain masses are proportional to it.
    tdamp : float
        Chain time constant (ASE time units), as in ASE's
        ``NoseHooverChainNVT``; at least the time step (100 steps is typical).
    tchain : int, default 3
        Chain length.
    tloop : int, default 1
        Sub-steps of each half-step chain update.
    fixcm : bool or None, default None
        Keep the total momentum (see :class:`Thermostat`); None: True unless a
        barostat moves the cell.

    References
    ----------
    H. Kamberaj, R. J. Low and M. P. Neal, J. Chem. Phys. 122, 224114 (2005);
    G. J. Martyna, M. E. Tuckerman, D. J. Tobias and M. L. Klein, Mol. Phys. 87,
    1117 (1996).
    """

    kind = "nose_hoover"
    parameters = (TEMPERATURE, Parameter("tdamp", "tdamp", "time", example="100 fs"),
                  Parameter("tchain", "tchain", "integer", required=False, default=3),
                  Parameter("tloop", "tloop", "integer", required=False, default=1),
                  fixcm_parameter(None))

    def __init__(self, temperature_K, tdamp, tchain=3, tloop=1, fixcm=None):
        super().__init__(temperature_K, fixcm)
        self._check_positive(self.temperature_K)
        self.tdamp = check_time("tdamp", tdamp)
        self.tchain = check_positive_integer("tchain", tchain)
        self.tloop = check_positive_integer("tloop", tloop)
        self.chains = ()

    @staticmethod
    def _check_positive(temperature_K):
        if temperature_K == 0:
            raise ValueError(
                "temperature_K = 0: Nose-Hoover chain masses are N_f k_B T tdamp^2, so a "
                "chain at 0 K has no mass and cannot act; cool with a Langevin or Bussi "
                "thermostat, which reach 0 K")

    def set_temperature(self, temperature_K):
        value = check_temperature(temperature_K)
        self._check_positive(value)
        self.temperature_K = value

    def check_timestep(self, dt):
        if self.tdamp < dt:
            raise ValueError(
                f"tdamp = {self.tdamp:g} is shorter than the time step {dt:g}: "
                "the chain cannot be integrated (100 time steps is typical)"
            )

    def bind(self, view: CouplingView) -> None:
        super().bind(view)
        self.chains = tuple(NoseHooverChain(ndof, self.tdamp, self.tchain, self.tloop)
                            for ndof in (self.n_translational, view.model.rotational_dof))
        for chain in self.chains:
            chain.compiled = view.compiled

    def first_half(self, view: CouplingView, h: float) -> None:
        K_t, K_r = self.kinetic_energies(view)
        translation, rotation = self.chains
        self.scale(view, translation.propagate(K_t, self.kT, h),
                   rotation.propagate(K_r, self.kT, h))

    def energy(self, view: CouplingView | None = None) -> float:
        """Energy of the two chains (eV)."""
        return sum(chain.energy(self.kT) for chain in self.chains)

    def get_state(self):
        return {"chains": [chain.get_state() for chain in self.chains]}

    def set_state(self, state):
        for chain, saved in zip(self.chains, state["chains"], strict=True):
            chain.set_state(saved)

    def lammps_fix(self, time_unit, seed=None):
        """``rigid/nvt/small ... temp T T tdamp tparam tchain tloop 3``; ``fix nvt`` on free atoms.

        LAMMPS's chains use Yoshida–Suzuki weights of order 3 within each
        sub-step, ours plain sub-steps: the same ensemble, not the same
        trajectory.
        """
        temp = f"temp {self.temperature_K!r} {self.temperature_K!r} {self.tdamp / time_unit!r}"
        return LammpsFix("nvt", f"{temp} tparam {self.tchain} {self.tloop} 3",
                         (f"nvt {temp} tchain {self.tchain} tloop {self.tloop}",),
                         notes=self.fixcm_notes())

    def todict(self):
        return super().todict() | {"tdamp": self.tdamp, "tchain": self.tchain,
                                   "tloop": self.tloop}


# ---------------------------------------------------------------- user constructors
class _Thermostatted(RigidDynamics):
    """A rigid dynamics with one thermostat part, exposed as ``self.thermostat``."""

    def __init__(self, atoms, timestep, thermostat, **kwargs):
        if "couplings" in kwargs:
            raise TypeError(f"{type(self).__name__} builds its own thermostat; "
                            "use RigidDynamics(couplings=...) to compose parts")
        self.thermostat = thermostat
        super().__init__(atoms, timestep, couplings=[thermostat], **kwargs)

    @property
    def temperature_K(self):
        """Target temperature (K)."""
        return self.thermostat.temperature_K

    @property
    def thermostat_work(self):
        """Energy a stochastic thermostat has put into the system so far (eV)."""
        return self.thermostat.work

    def todict(self):
        return super().todict() | self.thermostat.todict()


_UNITS = {"temperature_K": "K", "friction": "per ASE time unit", "taut": "ASE time units",
          "tdamp": "ASE time units"}


def _required(cls, **values):
    missing = [name for name, value in values.items() if value is None]
    if missing:
        needed = " and ".join(f"{name} ({_UNITS[name]})" for name in values)
        raise TypeError(f"{cls} needs {needed}; missing: {', '.join(missing)}")


class RigidLangevin(_Thermostatted):
    r"""Langevin dynamics of rigid bodies.

    See :class:`LangevinThermostat`.

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    friction : float
        :math:`\gamma`, per ASE time unit (``0.01 / ase.units.fs`` is 0.01 fs⁻¹),
        as in ASE's ``Langevin``.  ``friction * timestep`` must not exceed 0.5.
    rng : numpy.random.Generator, numpy.random.RandomState or numpy.random, optional
    fixcm : bool or None, default None
        Keep the total momentum (no drift of the whole system), as ASE's ``Langevin``;
        None is True, with a warning at the first step if the forces do not conserve the
        momentum (a wall, an external field: pass False there).
    **kwargs
        ``bodies``, ``integrator``, ``integrator_options``, ``trajectory``,
        ``logfile``, ``loginterval``, ``backend`` as for
        :class:`~rigidmd.core.dynamics.RigidDynamics`.
    """

    def __init__(self, atoms, timestep, temperature_K=None, friction=None, *, rng=None,
                 fixcm=None, **kwargs):
        _required("RigidLangevin", temperature_K=temperature_K, friction=friction)
        super().__init__(atoms, timestep,
                         LangevinThermostat(temperature_K, friction, rng, fixcm), **kwargs)

    @property
    def friction(self):
        """Friction (per ASE time unit)."""
        return self.thermostat.friction

    def set_friction(self, friction):
        """Change the friction (per ASE time unit), as ASE's ``Langevin.set_friction``."""
        self.thermostat.set_friction(friction, self.dt)


class RigidBussi(_Thermostatted):
    r"""Stochastic velocity rescaling of rigid bodies.

    See :class:`BussiThermostat`.

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    taut : float
        Relaxation time (ASE time units), as in ASE's ``Bussi``.
    rng : numpy.random.Generator, numpy.random.RandomState or numpy.random, optional
    fixcm : bool or None, default None
        Keep the total momentum (no drift of the whole system) and count 3 fewer
        degrees of freedom; None is True, with a warning at the first step if the
        forces do not conserve the momentum (a wall, an external field: pass False
        there).  With False the thermostat acts on the centre of mass too; from a
        zero total momentum (which the forces and the rescaling keep zero) the
        system then samples :math:`T\cdot 6N/(6N-3)` for N rigid molecules
        (+0.7 K at 298 K and 216 waters), as LAMMPS's ``fix rigid/nvt``.
    **kwargs
        As for :class:`~rigidmd.core.dynamics.RigidDynamics`.

    References
    ----------
    G. Bussi, D. Donadio and M. Parrinello, J. Chem. Phys. 126, 014101 (2007).
    """

    def __init__(self, atoms, timestep, temperature_K=None, taut=None, *, rng=None,
                 fixcm=None, **kwargs):
        _required("RigidBussi", temperature_K=temperature_K, taut=taut)
        super().__init__(atoms, timestep, BussiThermostat(temperature_K, taut, rng, fixcm),
                         **kwargs)

    @property
    def taut(self):
        """Relaxation time (ASE time units)."""
        return self.thermostat.taut


class RigidNoseHoover(_Thermostatted):
    r"""Nosé–Hoover chains for rigid bodies (LAMMPS ``fix rigid/nvt``).

    See :class:`NoseHooverThermostat`.

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K, positive.
    tdamp : float
        Chain time constant (ASE time units), as in ASE's
        ``NoseHooverChainNVT``; at least the time step (100 steps is typical).
    tchain : int, default 3
        Chain length.
    tloop : int, default 1
        Sub-steps of each half-step chain update.
    fixcm : bool or None, default None
        Keep the total momentum (no drift of the whole system) and count 3 fewer
        degrees of freedom; None is True, with a warning if the forces do not
        conserve the momentum (see :class:`RigidBussi`; False acts on all
        :math:`6N`, as LAMMPS's ``fix rigid/nvt``).
    **kwargs
        As for :class:`~rigidmd.core.dynamics.RigidDynamics`.

    References
    ----------
    H. Kamberaj, R. J. Low and M. P. Neal, J. Chem. Phys. 122, 224114 (2005);
    G. J. Martyna, M. E. Tuckerman, D. J. Tobias and M. L. Klein, Mol. Phys. 87,
    1117 (1996).
    """

    def __init__(self, atoms, timestep, temperature_K=None, tdamp=None, tchain=3, tloop=1,
                 *, fixcm=None, **kwargs):
        _required("RigidNoseHoover", temperature_K=temperature_K, tdamp=tdamp)
        super().__init__(atoms, timestep,
                         NoseHooverThermostat(temperature_K, tdamp, tchain, tloop, fixcm),
                         **kwargs)

    @property
    def tdamp(self):
        """Chain time constant (ASE time units)."""
        return self.thermostat.tdamp

    def chain_energy(self):
        """Energy of the two chains (eV)."""
        return self.thermostat.energy()
