r"""Rigid-body NPT with ASE's argument names: :class:`RigidNPT` and :class:`RigidCRescale`.

Each is a :class:`~rigidmd.dynamics.RigidDynamics` composed of a thermostat
part and a barostat part (:mod:`rigidmd.coupling`); the barostat moves the
centres of mass (and point particles) with the cell, never the orientations,
inside the integrator's drift, so both work with every integrator scheme.

* :class:`RigidNPT`: Nosé–Hoover chains on translation and rotation and the
  Martyna–Tuckerman–Klein barostat with its own chain (as LAMMPS
  ``fix rigid/npt``, after Kamberaj, Low & Neal 2005), for production.
* :class:`RigidCRescale`: the Bussi thermostat and stochastic cell rescaling
  (Bernetti & Bussi 2020): first order in the volume, robust from far-off
  starting densities; the recommended equilibration tool.
"""

from rigidmd.coupling.barostats import CRescaleBarostat, MTKBarostat
from rigidmd.coupling.thermostats import BussiThermostat, NoseHooverThermostat
from rigidmd.dynamics import RigidDynamics

__all__ = ["RigidNPT", "RigidCRescale"]


class _Barostatted(RigidDynamics):
    """A rigid dynamics with a thermostat part and a barostat part."""

    def __init__(self, atoms, timestep, thermostat, barostat, **kwargs):
        if "couplings" in kwargs:
            raise TypeError(f"{type(self).__name__} builds its own thermostat and barostat; "
                            "use RigidDynamics(couplings=...) to compose parts")
        self.thermostat, self.barostat = thermostat, barostat
        super().__init__(atoms, timestep, couplings=[thermostat, barostat], **kwargs)

    @property
    def temperature_K(self):
        """Target temperature (K)."""
        return self.thermostat.temperature_K

    @property
    def pressure_au(self):
        """Target pressure (eV/Å³)."""
        return self.barostat.pressure_au

    def todict(self):
        return super().todict() | {"thermostat": self.thermostat.todict(),
                                   "barostat": self.barostat.todict()}


class RigidNPT(_Barostatted):
    r"""Isothermal–isobaric rigid-body dynamics: Nosé–Hoover chains and the MTK barostat.

    See :class:`~rigidmd.coupling.thermostats.NoseHooverThermostat` and
    :class:`~rigidmd.coupling.barostats.MTKBarostat`.  ``get_conserved_energy()``
    includes the barostat's kinetic energy, :math:`P_0 V` and every chain.

    Parameters
    ----------
    atoms : ase.Atoms
        A periodic system whose calculator provides stress.
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    pressure_au : float
        eV/Å³ (``1.01325 * ase.units.bar`` for 1 atm).
    tdamp : float
        Thermostat time constant (ASE time units; 100 steps is typical).
    pdamp : float
        Barostat time constant (ASE time units; at least 10 steps, 1000 typical).
    couple : {"iso", "aniso", "tri"}, default "iso"
        Volume only, the three lengths, or every strain (a triclinic cell;
        LAMMPS's rigid barostats cannot do this).
    tchain, pchain, tloop, ploop : int
        Chain lengths and sub-steps of the thermostat and of the barostat.
    **kwargs
        As for :class:`~rigidmd.dynamics.RigidDynamics` (``bodies``,
        ``integrator``, ``trajectory``, ``logfile``, ...).
    """

    def __init__(self, atoms, timestep, temperature_K, pressure_au, tdamp, pdamp, *,
                 couple="iso", tchain=3, pchain=3, tloop=1, ploop=1, **kwargs):
        super().__init__(
            atoms, timestep, NoseHooverThermostat(temperature_K, tdamp, tchain, tloop),
            MTKBarostat(temperature_K, pressure_au, pdamp, couple, pchain, ploop), **kwargs)


class RigidCRescale(_Barostatted):
    r"""Rigid-body NPT by stochastic cell rescaling and stochastic velocity rescaling.

    See :class:`~rigidmd.coupling.thermostats.BussiThermostat` and
    :class:`~rigidmd.coupling.barostats.CRescaleBarostat`.
    ``get_conserved_energy()`` is the effective energy: its drift measures
    the integration error.

    Parameters
    ----------
    atoms : ase.Atoms
        A periodic system whose calculator provides stress.
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    pressure_au : float
        eV/Å³.
    taut : float
        Thermostat relaxation time (ASE time units).
    taup : float
        Barostat relaxation time (ASE time units; at least 10 steps).
    compressibility_au : float
        Isothermal compressibility (Å³/eV; water: ``4.5e-5 / ase.units.bar``).
    couple : {"iso", "aniso", "tri"}, default "iso"
    rng : numpy.random.Generator, optional
        Shared by the thermostat and the barostat.
    every : int, default 1
        Move the cell every ``every`` steps (see
        :class:`~rigidmd.coupling.barostats.CRescaleBarostat`).
    **kwargs
        As for :class:`~rigidmd.dynamics.RigidDynamics`.
    """

    def __init__(self, atoms, timestep, temperature_K, pressure_au, taut, taup,
                 compressibility_au, *, couple="iso", rng=None, every=1, **kwargs):
        from rigidmd.coupling import check_rng

        rng = check_rng(rng)
        super().__init__(
            atoms, timestep, BussiThermostat(temperature_K, taut, rng),
            CRescaleBarostat(temperature_K, pressure_au, taup, compressibility_au, couple, rng,
                             every), **kwargs)
