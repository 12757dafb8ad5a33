r"""Thermostats: the coupling parts (the dynamics classes users construct are in :mod:`rigidmd.md`).

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

import math

import numpy as np
from ase import units

from rigidmd.core import operators as ops
from rigidmd.core.checks import real_number
from rigidmd.couplings.base import (
    TEMPERATURE,
    CouplingView,
    LammpsFix,
    NoseHooverChain,
    NotExportable,
    Parameter,
    Thermostat,
    check_positive_integer,
    check_rng,
    check_temperature,
    check_time,
    fixcm_parameter,
    register,
    rng_state,
    set_rng_state,
)

__all__ = ["Thermostat",
           "LangevinThermostat", "BussiThermostat", "NoseHooverThermostat"]


SEED = Parameter("rng", "seed", "seed", required=False)

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


def check_friction(friction) -> float:
    """A friction (per ASE time unit) as a float >= 0, or one clear line."""
    gamma = real_number("friction", friction, "a number per ASE time unit")
    if not (np.isfinite(gamma) and gamma >= 0):
        raise ValueError(f"friction must be >= 0 (per ASE time unit), got {friction!r}")
    return gamma


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
        self.friction = check_friction(friction)

    def check_timestep(self, dt):
        """Refuse ``friction * dt > 0.5``: almost surely friction given in the wrong unit."""
        # Typical values give friction * timestep ~ 0.001-0.05; above 0.5 the
        # velocities forget themselves within a step.
        if self.friction * dt > 0.5:
            raise ValueError(
                f"friction {self.friction * units.fs:.4g}/fs times the time step "
                f"{dt / units.fs:.4g} fs is {self.friction * dt:.3g}, above 0.5: the velocities "
                "would forget themselves within a step; lower the friction (in Python it is "
                f"per ASE time unit: 0.01 / ase.units.fs = {0.01 / units.fs:.4g} for 0.01/fs)"
            )

    def set_friction(self, friction: float, timestep: float | None = None) -> None:
        """Change the friction (per ASE time unit), checked against ``timestep`` when given."""
        gamma = check_friction(friction)
        old, self.friction = self.friction, gamma
        if timestep is not None:
            try:
                self.check_timestep(timestep)
            except ValueError:
                self.friction = old
                raise

    def first_half(self, view: CouplingView, h: float) -> None:
        s, m, kT, rng, record = view.state, view.model, self.kT, self.rng, view.record
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
        s.touched(momenta=True)  # written in place
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
    # Python floats and math.sqrt: NumPy's numbers to the bit (sqrt is correctly rounded
    # in both), without a NumPy scalar operation per number.
    r1 = float(rng.standard_normal())
    rest = 2.0 * float(rng.standard_gamma(0.5 * (ndof - 1))) if ndof > 1 else 0.0
    ratio = K_target / ndof
    new = (c * K + (1.0 - c) * ratio * (r1 * r1 + rest)
           + 2.0 * r1 * math.sqrt(c * (1.0 - c) * K * ratio))
    if c < 1:
        x = r1 + math.sqrt(c * K / ((1.0 - c) * ratio))
        sign = 1.0 if x > 0 else -1.0 if x < 0 else 0.0
    else:
        sign = 1.0
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

    _decay = (None, None, 1.0)  # (h, taut, exp(-h / taut)) of the last half step

    def first_half(self, view: CouplingView, h: float) -> None:
        h_last, taut, c = self._decay
        if h != h_last or taut != self.taut:
            c = float(np.exp(-h / self.taut))
            self._decay = (h, self.taut, c)
        factors = []
        kT = self.kT
        for K, ndof in zip(self.kinetic_energies(view),
                           (self.n_translational, view.model.rotational_dof), strict=True):
            if ndof == 0 or K <= 0:
                factors.append(1.0)
                continue
            new, sign = bussi_kinetic_energy(K, 0.5 * ndof * kT, ndof, c, self.rng)
            self.work += new - K
            factors.append(sign * math.sqrt(max(new, 0.0) / K))  # new < 0: roundoff of 0
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
        self.tdamp = check_time("tdamp", tdamp)
        self.tchain = check_positive_integer("tchain", tchain)
        self.tloop = check_positive_integer("tloop", tloop)
        self.chains = ()

    def checked_temperature(self, temperature_K) -> float:
        value = check_temperature(temperature_K)
        if value == 0:
            raise ValueError(
                "temperature_K = 0: Nose-Hoover chain masses are N_f k_B T tdamp^2, so a "
                "chain at 0 K has no mass and cannot act; cool with a Langevin or Bussi "
                "thermostat, which reach 0 K")
        return value

    def check_timestep(self, dt):
        if self.tdamp < dt:
            raise ValueError(
                f"tdamp: {self.tdamp / units.fs:g} fs is shorter than the time step "
                f"{dt / units.fs:g} fs: the chain cannot be integrated (100 time steps is "
                "typical)"
            )

    def bind(self, view: CouplingView) -> None:
        super().bind(view)
        self.chains = tuple(NoseHooverChain(ndof, self.tdamp, self.tchain, self.tloop)
                            for ndof in (self.n_translational, view.model.rotational_dof))

    def first_half(self, view: CouplingView, h: float) -> None:
        K_t, K_r = self.kinetic_energies(view)
        translation, rotation = self.chains
        kT = self.kT
        backend = view.backend
        if not self.holds_momentum:  # chains and scaling in one call
            s, record = view.state, view.record
            factors = backend.nose_hoover_scale(
                s.data, len(s.X), len(s.x), translation.xi, translation.eta, translation.ndof,
                rotation.xi, rotation.eta, rotation.ndof, kT * self.tdamp**2, K_t, K_r, kT, h,
                self.tloop)
            record.scaled(factors[0], factors[1])
            return
        self.scale(view, translation.propagate(K_t, kT, h, backend),
                   rotation.propagate(K_r, kT, h, backend))

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
