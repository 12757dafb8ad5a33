"""Rigid-body NPT with a Monte Carlo barostat: :class:`RigidMCBarostat`.

The barostat part is :class:`~rigidmd.couplings.montecarlo.MonteCarloBarostat`; the
thermostat part is a :class:`~rigidmd.couplings.thermostats.BussiThermostat` or any
thermostat part.
"""

from rigidmd.couplings.base import Coupling, check_rng
from rigidmd.couplings.montecarlo import MonteCarloBarostat
from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.md.coupled import BarostattedDynamics

__all__ = ["RigidMCBarostat"]


class RigidMCBarostat(BarostattedDynamics):
    r"""Rigid-body NPT with a Monte Carlo barostat: no stress needed.

    A thermostat part (the Bussi thermostat with ``taut``, or any
    ``thermostat`` part) and a :class:`MonteCarloBarostat`, which every
    ``every`` steps scales the centres of mass and the cell (orientations
    kept) and accepts with the Metropolis rule of the NPT ensemble of
    molecules.  One extra energy call per move; the calculator needs no
    stress.  ``get_conserved_energy()`` subtracts the energy the accepted
    moves put in, so its drift measures the integration error.

    Parameters
    ----------
    atoms : ase.Atoms
        A periodic system.
    timestep : float
        ASE time units.
    temperature_K : float
        K (thermostat and barostat).
    pressure_au : float
        eV/Å³.
    taut : float, optional
        Relaxation time of the default Bussi thermostat (ASE time units).
    thermostat : rigidmd.couplings.base.Coupling, optional
        A thermostat part instead (e.g. ``LangevinThermostat(T, friction,
        fixcm=False)``); give ``taut`` or ``thermostat``.
    couple : {"iso", "aniso", "tri"}, default "iso"
    every : int, default 25
        Steps between moves.
    rng : numpy.random.Generator, optional
        Shared by the default thermostat and the barostat.
    adapt_moves : int, default 500
        Moves during which the move size adapts (then frozen).
    step : float, default 0.01
        Initial move size (see :class:`MonteCarloBarostat`).
    **kwargs
        As for :class:`~rigidmd.core.dynamics.RigidDynamics`.
    """

    part_types = (Coupling, MonteCarloBarostat)  # any thermostat part, as the constructor

    def __init__(self, atoms, timestep, temperature_K, pressure_au, taut=None, *,
                 thermostat=None, couple="iso", every=25, rng=None, adapt_moves=500,
                 step=0.01, **kwargs):
        rng = check_rng(rng)
        if (taut is None) == (thermostat is None):
            raise TypeError("RigidMCBarostat: give taut (a Bussi thermostat) or a thermostat "
                            "part, not both or neither")
        if thermostat is None:
            thermostat = BussiThermostat(temperature_K, taut, rng)
        elif not isinstance(thermostat, Coupling) or thermostat.section != "thermostat":
            raise TypeError("thermostat must be a thermostat part "
                            f"(rigidmd.couplings.thermostats), got {type(thermostat).__name__}")
        barostat = MonteCarloBarostat(temperature_K, pressure_au, couple, every, rng,
                                      adapt_moves, step)
        if thermostat.temperature_K != barostat.temperature_K:
            raise ValueError(f"the thermostat's temperature ({thermostat.temperature_K:g} K) "
                             f"differs from temperature_K ({barostat.temperature_K:g} K)")
        super().__init__(atoms, timestep, thermostat, barostat, **kwargs)
