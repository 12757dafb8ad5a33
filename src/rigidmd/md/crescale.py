"""Stochastic cell rescaling and velocity rescaling: :class:`RigidCRescale`.

The parts are :class:`~rigidmd.couplings.thermostats.BussiThermostat` and
:class:`~rigidmd.couplings.barostats.CRescaleBarostat`.
"""

from rigidmd.couplings.barostats import CRescaleBarostat
from rigidmd.couplings.base import check_rng
from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.md.coupled import BarostattedDynamics

__all__ = ["RigidCRescale"]


class RigidCRescale(BarostattedDynamics):
    r"""Rigid-body NPT by stochastic cell rescaling and stochastic velocity rescaling.

    See :class:`~rigidmd.couplings.thermostats.BussiThermostat` and
    :class:`CRescaleBarostat`.
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
        :class:`CRescaleBarostat`).
    **kwargs
        As for :class:`~rigidmd.core.dynamics.RigidDynamics`.
    """

    part_types = (BussiThermostat, CRescaleBarostat)

    def __init__(self, atoms, timestep, temperature_K, pressure_au, taut, taup,
                 compressibility_au, *, couple="iso", rng=None, every=1, **kwargs):
        rng = check_rng(rng)
        super().__init__(
            atoms, timestep, BussiThermostat(temperature_K, taut, rng),
            CRescaleBarostat(temperature_K, pressure_au, taup, compressibility_au, couple, rng,
                             every), **kwargs)
