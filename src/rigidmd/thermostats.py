r"""Thermostatted rigid-body dynamics with ASE's argument names.

:class:`RigidLangevin`, :class:`RigidBussi` and :class:`RigidNoseHoover` take
the arguments of ASE's ``Langevin`` (``friction``), ``Bussi`` (``taut``) and
``NoseHooverChainNVT`` (``tdamp``, ``tchain``, ``tloop``), plus the rigid
arguments of :class:`~rigidmd.dynamics.RigidDynamics` (``bodies``,
``integrator``, ...).  Each is a :class:`~rigidmd.dynamics.RigidDynamics`
with one thermostat part from :mod:`rigidmd.coupling.thermostats`, which
acts for half a step before and after the deterministic step.

``get_conserved_energy()`` returns the energy that the thermostatted
dynamics conserves: total energy minus the energy the thermostat put in
(Langevin, Bussi), or plus the chains' energy (Nosé–Hoover).
"""

from rigidmd.coupling.thermostats import (
    BussiThermostat,
    LangevinThermostat,
    NoseHooverThermostat,
)
from rigidmd.dynamics import RigidDynamics

__all__ = ["RigidLangevin", "RigidBussi", "RigidNoseHoover"]


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

    def set_temperature(self, temperature=None, *, temperature_K=None):
        """Change the target temperature, as ASE's thermostats do (``temperature_K`` in K)."""
        self.thermostat.set_temperature(
            self._process_temperature(temperature, temperature_K, "K"))
        self._energy_ref = None  # the chains' energy jumps with the target: a new reference

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

    See :class:`~rigidmd.coupling.thermostats.LangevinThermostat`.

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
    fixcm : bool, default True
        Keep the total momentum (no drift of the whole system), as ASE's ``Langevin``.
    **kwargs
        ``bodies``, ``integrator``, ``integrator_options``, ``trajectory``,
        ``logfile``, ``loginterval``, ``backend`` as for
        :class:`~rigidmd.dynamics.RigidDynamics`.
    """

    def __init__(self, atoms, timestep, temperature_K=None, friction=None, *, rng=None,
                 fixcm=True, **kwargs):
        _required("RigidLangevin", temperature_K=temperature_K, friction=friction)
        super().__init__(atoms, timestep,
                         LangevinThermostat(temperature_K, friction, rng, fixcm), **kwargs)

    @property
    def friction(self):
        """Friction (per ASE time unit)."""
        return self.thermostat.friction

    def set_friction(self, friction):
        """Change the friction (per ASE time unit), as ASE's ``Langevin.set_friction``."""
        self.thermostat.set_friction(friction)


class RigidBussi(_Thermostatted):
    r"""Stochastic velocity rescaling of rigid bodies.

    See :class:`~rigidmd.coupling.thermostats.BussiThermostat`.

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
    fixcm : bool, default False
        Keep the total momentum (no drift of the whole system).
    **kwargs
        As for :class:`~rigidmd.dynamics.RigidDynamics`.

    References
    ----------
    G. Bussi, D. Donadio and M. Parrinello, J. Chem. Phys. 126, 014101 (2007).
    """

    def __init__(self, atoms, timestep, temperature_K=None, taut=None, *, rng=None,
                 fixcm=False, **kwargs):
        _required("RigidBussi", temperature_K=temperature_K, taut=taut)
        super().__init__(atoms, timestep, BussiThermostat(temperature_K, taut, rng, fixcm),
                         **kwargs)

    @property
    def taut(self):
        """Relaxation time (ASE time units)."""
        return self.thermostat.taut


class RigidNoseHoover(_Thermostatted):
    r"""Nosé–Hoover chains for rigid bodies (LAMMPS ``fix rigid/nvt``).

    See :class:`~rigidmd.coupling.thermostats.NoseHooverThermostat`.

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
    fixcm : bool, default False
        Keep the total momentum (no drift of the whole system).
    **kwargs
        As for :class:`~rigidmd.dynamics.RigidDynamics`.

    References
    ----------
    H. Kamberaj, R. J. Low and M. P. Neal, J. Chem. Phys. 122, 224114 (2005);
    G. J. Martyna, M. E. Tuckerman, D. J. Tobias and M. L. Klein, Mol. Phys. 87,
    1117 (1996).
    """

    def __init__(self, atoms, timestep, temperature_K=None, tdamp=None, tchain=3, tloop=1,
                 *, fixcm=False, **kwargs):
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
