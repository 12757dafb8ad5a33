r"""Rigid-body thermostats: Langevin, Bussi and Nosé–Hoover chains.

Each class takes the arguments of its ASE point-particle counterpart
(:class:`ase.md.langevin.Langevin`, :class:`ase.md.bussi.Bussi`,
:class:`ase.md.nose_hoover_chain.NoseHooverChainNVT`) plus the ``bodies``,
``integrator`` and ``integrator_options`` of :class:`~rigidmd.RigidVerlet`,
so switching from ASE is a rename.  Every thermostat acts on the rigid
degrees of freedom: centre-of-mass velocities, body-frame angular momenta
about the axes with a nonzero moment (6 per body, 5 per linear body) and the
velocities of point particles (3 each).  It is applied for half a time step
before and after the deterministic step (NO_SQUISH by default), a symmetric
splitting.

Temperatures count degrees of freedom as ASE does (no centre-of-mass
correction); LAMMPS subtracts 3 (``6N − 3`` for N rigid waters).

``get_conserved_energy()`` returns the energy that the thermostatted
dynamics conserves: total energy minus the energy the thermostat put in
(Langevin, Bussi), or plus the chain's energy (Nosé–Hoover).
"""

import numpy as np
from ase import units

from rigidmd import operators as ops
from rigidmd.dynamics import RigidVerlet

__all__ = ["RigidLangevin", "RigidBussi", "RigidNoseHoover"]


def _check_temperature(temperature_K):
    try:
        value = float(temperature_K)
    except (TypeError, ValueError):
        raise TypeError(f"temperature_K must be a number (K), got {temperature_K!r}") from None
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"temperature_K must be >= 0 K, got {temperature_K!r}")
    return value


def _check_time(name, value, timestep):
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a time in ASE units, got {value!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive time (ASE units), got {value!r}")
    return value


class _RigidThermostat(RigidVerlet):
    """Shared machinery: degrees of freedom per group, kinetic energies, rescaling."""

    def __init__(self, atoms, timestep, temperature_K, *, rng=None, **kwargs):
        self.temperature_K = _check_temperature(temperature_K)
        self.rng = np.random.default_rng() if rng is None else rng
        if not hasattr(self.rng, "standard_normal"):
            raise TypeError(f"rng must be a numpy.random.Generator, got {rng!r}")
        super().__init__(atoms, timestep, **kwargs)
        #: Energy the thermostat has put into the system so far (eV).
        self.thermostat_work = 0.0

    @property
    def kT(self):
        return units.kB * self.temperature_K

    @property
    def translational_dof(self):
        """Centre-of-mass and point-particle degrees of freedom: 3 each."""
        return 3 * (self.geometry.n_bodies + len(self._free))

    @property
    def rotational_dof(self):
        """Rotational degrees of freedom: 3 per body, 2 per linear body."""
        return int(np.count_nonzero(self.geometry.moments))

    def _kinetic_energies(self):
        """(translational, rotational) kinetic energy of the state (eV)."""
        return self.get_translational_kinetic_energy(), self.get_rotational_kinetic_energy()

    def _scale(self, translational, rotational):
        """Multiply translational velocities and angular momenta by the given factors."""
        s = self._state
        s.V *= translational
        s.v *= translational
        s.p *= rotational

    def _advance(self):
        half = 0.5 * self.dt
        self._thermostat(half)
        super()._advance()
        self._thermostat(half)
        self._write_momenta()

    def _thermostat(self, h):
        raise NotImplementedError

    def _save_extra(self):
        return self.thermostat_work, self.rng.bit_generator.state

    def _restore_extra(self, saved):
        self.thermostat_work, self.rng.bit_generator.state = saved

    def get_conserved_energy(self):
        """Total energy minus the energy the thermostat has added (eV)."""
        return self.atoms.get_total_energy() - self.thermostat_work

    def todict(self):
        d = super().todict()
        d["temperature_K"] = self.temperature_K
        return d


class RigidLangevin(_RigidThermostat):
    r"""Langevin dynamics of rigid bodies.

    Friction and noise act on the centre-of-mass velocities, on the
    body-frame angular momenta per principal axis (not about a zero-moment
    axis), and on point particles, as LAMMPS ``fix rigid/nve ... langevin``
    does.  Each half step :math:`h = \Delta t/2` is the exact
    Ornstein–Uhlenbeck update, with :math:`c = e^{-\gamma h}` and
    :math:`\xi \sim \mathcal N(0, 1)`:

    .. math::
        V \leftarrow c V + \sqrt{(1 - c^2) k_B T / M}\;\xi,\qquad
        L_{b,k} \leftarrow c L_{b,k} + \sqrt{(1 - c^2) k_B T I_k}\;\xi

    around one deterministic step (O–NO_SQUISH–O), which samples the
    canonical ensemble with :math:`O(\Delta t^2)` errors.

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
    rng : numpy.random.Generator, optional
    **kwargs
        ``bodies``, ``integrator``, ``integrator_options``, ``trajectory``,
        ``logfile``, ``loginterval``, ``backend`` as for :class:`RigidVerlet`.
    """

    def __init__(self, atoms, timestep, temperature_K=None, friction=None, *, rng=None,
                 **kwargs):
        if temperature_K is None or friction is None:
            raise TypeError("RigidLangevin needs temperature_K (K) and friction "
                            "(per ASE time unit)")
        try:
            gamma = float(friction)
        except (TypeError, ValueError):
            raise TypeError(f"friction must be a number per ASE time unit, got {friction!r}"
                            ) from None
        if not (np.isfinite(gamma) and gamma >= 0):
            raise ValueError(f"friction must be >= 0 (per ASE time unit), got {friction!r}")
        # Typical values give friction * timestep ~ 0.001-0.05; above 0.5 the
        # velocities forget themselves within a step: almost surely a unit slip.
        if gamma * float(timestep) > 0.5:
            raise ValueError(
                f"friction = {gamma:g} per ASE time unit damps the velocities within one "
                f"step of {float(timestep):g}: friction is in 1/(ASE time), e.g. "
                f"0.01 / ase.units.fs = {0.01 / units.fs:.4g}, not in 1/fs or 1/ps"
            )
        self.friction = gamma
        super().__init__(atoms, timestep, temperature_K, rng=rng, **kwargs)

    def _thermostat(self, h):
        s, g, kT, rng = self._state, self.geometry, self.kT, self.rng
        before = sum(self._kinetic_energies())
        c = np.exp(-self.friction * h)
        sigma = np.sqrt((1.0 - c * c) * kT)
        s.V[...] = c * s.V + sigma * rng.standard_normal(s.V.shape) / np.sqrt(g.mass)[:, None]
        s.v[...] = c * s.v + sigma * rng.standard_normal(s.v.shape) / np.sqrt(
            self._free_masses)[:, None]
        L_body = ops.body_angular_momentum(s.q, s.p)
        noise = sigma * np.sqrt(g.moments) * rng.standard_normal(L_body.shape)
        s.p[...] = ops.conjugate_momentum(s.q, c * L_body + noise)
        self.thermostat_work += sum(self._kinetic_energies()) - before

    def todict(self):
        d = super().todict()
        d["friction"] = self.friction
        return d


def _bussi_kinetic_energy(K, K_target, ndof, c, rng):
    r"""New kinetic energy of stochastic velocity rescaling (Bussi et al. 2007, eq. A7).

    .. math::
        K' = cK + (1-c)\frac{\bar K}{N_f}\Big(R_1^2 + \sum_{i=2}^{N_f} R_i^2\Big)
             + 2 R_1 \sqrt{c (1-c) K \bar K / N_f}

    with :math:`R_i \sim \mathcal N(0, 1)` and :math:`\sum_{i\ge2} R_i^2`
    drawn as a :math:`\chi^2_{N_f-1}`.  Returns (K', sign), where ``sign`` is
    the sign of the rescaling factor.
    """
    r1 = rng.standard_normal()
    rest = 2.0 * rng.standard_gamma(0.5 * (ndof - 1)) if ndof > 1 else 0.0
    ratio = K_target / ndof
    new = (c * K + (1.0 - c) * ratio * (r1 * r1 + rest)
           + 2.0 * r1 * np.sqrt(c * (1.0 - c) * K * ratio))
    sign = np.sign(r1 + np.sqrt(c * K / ((1.0 - c) * ratio))) if c < 1 else 1.0
    return new, sign


class RigidBussi(_RigidThermostat):
    r"""Stochastic velocity rescaling of rigid bodies (Bussi, Donadio & Parrinello 2007).

    The translational kinetic energy (centres of mass and point particles)
    and the rotational kinetic energy are each rescaled, half a step before
    and after the deterministic step, to a value drawn so that each samples
    its canonical distribution with :math:`N_f` degrees of freedom and
    relaxes with time constant ``taut``.  The energy exchanged is kept in
    :attr:`thermostat_work`; :meth:`get_conserved_energy` subtracts it.

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    taut : float
        Relaxation time (ASE time units), as in ASE's ``Bussi``.
    rng : numpy.random.Generator, optional
    **kwargs
        As for :class:`RigidVerlet`.

    References
    ----------
    G. Bussi, D. Donadio and M. Parrinello, J. Chem. Phys. 126, 014101 (2007).
    """

    def __init__(self, atoms, timestep, temperature_K=None, taut=None, *, rng=None, **kwargs):
        if temperature_K is None or taut is None:
            raise TypeError("RigidBussi needs temperature_K (K) and taut (ASE time units)")
        self.taut = _check_time("taut", taut, timestep)
        super().__init__(atoms, timestep, temperature_K, rng=rng, **kwargs)

    def _thermostat(self, h):
        c = np.exp(-h / self.taut)
        factors = []
        for K, ndof in zip(self._kinetic_energies(), (self.translational_dof,
                                                      self.rotational_dof), strict=True):
            if ndof == 0 or K <= 0:
                factors.append(1.0)
                continue
            new, sign = _bussi_kinetic_energy(K, 0.5 * ndof * self.kT, ndof, c, self.rng)
            self.thermostat_work += new - K
            factors.append(sign * np.sqrt(new / K))
        self._scale(*factors)

    def todict(self):
        d = super().todict()
        d["taut"] = self.taut
        return d


class RigidNoseHoover(_RigidThermostat):
    r"""Nosé–Hoover chains for rigid bodies (Kamberaj, Low & Neal 2005; LAMMPS ``fix rigid/nvt``).

    Two chains of length ``tchain``, one on the translational and one on the
    rotational degrees of freedom, are propagated for half a step before and
    after the deterministic step by the Trotter factorisation of Martyna,
    Tuckerman, Tobias and Klein (1996), with ``tloop`` sub-steps.  Chain
    masses are :math:`Q_1 = N_f k_B T \tau^2`, :math:`Q_{j>1} = k_B T \tau^2`
    with :math:`\tau` = ``tdamp``.  The conserved energy is

    .. math::
        H = E + \sum_\mathrm{chains}\Big[\sum_j \tfrac12 Q_j \xi_j^2
            + N_f k_B T \eta_1 + k_B T \sum_{j>1} \eta_j\Big].

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    tdamp : float
        Chain time constant (ASE time units), as in ASE's
        ``NoseHooverChainNVT``; at least the time step (100 steps is typical).
    tchain : int, default 3
        Chain length.
    tloop : int, default 1
        Sub-steps of each half-step chain update.
    **kwargs
        As for :class:`RigidVerlet`.

    References
    ----------
    H. Kamberaj, R. J. Low and M. P. Neal, J. Chem. Phys. 122, 224114 (2005);
    G. J. Martyna, M. E. Tuckerman, D. J. Tobias and M. L. Klein, Mol. Phys. 87,
    1117 (1996).
    """

    def __init__(self, atoms, timestep, temperature_K=None, tdamp=None, tchain=3, tloop=1,
                 **kwargs):
        if temperature_K is None or tdamp is None:
            raise TypeError("RigidNoseHoover needs temperature_K (K) and tdamp (ASE time units)")
        self.tdamp = _check_time("tdamp", tdamp, timestep)
        if self.tdamp < float(timestep):
            raise ValueError(
                f"tdamp = {self.tdamp:g} is shorter than the time step {float(timestep):g}: "
                "the chain cannot be integrated (100 time steps is typical)"
            )
        for name, value in (("tchain", tchain), ("tloop", tloop)):
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        self.tchain, self.tloop = int(tchain), int(tloop)
        super().__init__(atoms, timestep, temperature_K, **kwargs)
        # (xi, eta) per chain: translational, rotational.
        self._xi = np.zeros((2, self.tchain))
        self._eta = np.zeros((2, self.tchain))

    def _masses(self, ndof):
        Q = np.full(self.tchain, self.kT * self.tdamp**2)
        Q[0] *= ndof
        return Q

    def _chain_half(self, c, K, ndof, h):
        """Propagate chain ``c`` over ``h``; returns the velocity scale factor."""
        if ndof == 0 or self.kT == 0:
            return 1.0
        xi, eta, kT = self._xi[c], self._eta[c], self.kT
        Q = self._masses(ndof)
        M = self.tchain
        scale = 1.0
        delta = h / self.tloop

        def force(j, K2):
            if j == 0:
                return (K2 - ndof * kT) / Q[0]
            return (Q[j - 1] * xi[j - 1] ** 2 - kT) / Q[j]

        for _ in range(self.tloop):
            # Half kick of the chain over delta/2, from the end of the chain ...
            K2 = 2.0 * K * scale**2
            xi[M - 1] += 0.5 * delta * force(M - 1, K2)
            for j in range(M - 2, -1, -1):
                damp = np.exp(-0.25 * delta * xi[j + 1])
                xi[j] = (xi[j] * damp + 0.5 * delta * force(j, K2)) * damp
            # ... the particles' scaling and the positions of the chain ...
            scale *= np.exp(-delta * xi[0])
            eta += delta * xi
            # ... and the other half kick, back to the end of the chain.
            K2 = 2.0 * K * scale**2
            for j in range(M - 1):
                damp = np.exp(-0.25 * delta * xi[j + 1])
                xi[j] = (xi[j] * damp + 0.5 * delta * force(j, K2)) * damp
            xi[M - 1] += 0.5 * delta * force(M - 1, K2)
        return scale

    def _thermostat(self, h):
        K_t, K_r = self._kinetic_energies()
        self._scale(self._chain_half(0, K_t, self.translational_dof, h),
                    self._chain_half(1, K_r, self.rotational_dof, h))

    def chain_energy(self):
        """Energy of the two chains (eV)."""
        total = 0.0
        for c, ndof in enumerate((self.translational_dof, self.rotational_dof)):
            if ndof == 0:
                continue
            Q = self._masses(ndof)
            total += (0.5 * np.sum(Q * self._xi[c] ** 2) + ndof * self.kT * self._eta[c, 0]
                      + self.kT * np.sum(self._eta[c, 1:]))
        return float(total)

    def get_conserved_energy(self):
        """Total energy plus the chains' energy (eV)."""
        return self.atoms.get_total_energy() + self.chain_energy()

    def _save_extra(self):
        return self._xi.copy(), self._eta.copy()

    def _restore_extra(self, saved):
        self._xi, self._eta = saved

    def todict(self):
        d = super().todict()
        d.update(tdamp=self.tdamp, tchain=self.tchain, tloop=self.tloop)
        return d

