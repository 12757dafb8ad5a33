"""Nosé–Hoover chains and the MTK barostat: :class:`RigidNPT` (LAMMPS's
``fix rigid/npt``).

The parts are :class:`~rigidmd.couplings.thermostats.NoseHooverThermostat` and
:class:`~rigidmd.couplings.barostats.MTKBarostat`.
"""

from rigidmd.couplings.barostats import MTKBarostat
from rigidmd.couplings.thermostats import NoseHooverThermostat
from rigidmd.md.coupled import BarostattedDynamics

__all__ = ["RigidNPT"]


class RigidNPT(BarostattedDynamics):
    r"""Isothermal–isobaric rigid-body dynamics: Nosé–Hoover chains and the MTK barostat.

    See :class:`~rigidmd.couplings.thermostats.NoseHooverThermostat` and
    :class:`MTKBarostat`.  ``get_conserved_energy()``
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
        As for :class:`~rigidmd.core.dynamics.RigidDynamics` (``bodies``,
        ``integrator``, ``trajectory``, ``logfile``, ...).
    """

    part_types = (NoseHooverThermostat, MTKBarostat)

    def __init__(self, atoms, timestep, temperature_K, pressure_au, tdamp, pdamp, *,
                 couple="iso", tchain=3, pchain=3, tloop=1, ploop=1, **kwargs):
        super().__init__(
            atoms, timestep, NoseHooverThermostat(temperature_K, tdamp, tchain, tloop),
            MTKBarostat(temperature_K, pressure_au, pdamp, couple, pchain, ploop), **kwargs)
