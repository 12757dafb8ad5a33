"""Stochastic velocity rescaling of rigid bodies: :class:`RigidBussi` (ASE's ``Bussi``).

The part is :class:`~rigidmd.couplings.thermostats.BussiThermostat`.
"""

from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.md.coupled import ThermostattedDynamics, required_arguments

__all__ = ["RigidBussi"]


class RigidBussi(ThermostattedDynamics):
    r"""Stochastic velocity rescaling of rigid bodies.

    See :class:`BussiThermostat`.  The arguments are ASE's ``Bussi``'s, in its
    order (``atoms, timestep, temperature_K, taut, rng``), and ``fixcm`` (by
    keyword), which ASE's has not.

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
        The fifth positional argument, as in ASE's ``Bussi``.
    fixcm : bool or None, default None
        Keep the total momentum (no drift of the whole system) and count 3 fewer
        degrees of freedom; None is True, with a warning at the first step whose
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

    part_types = (BussiThermostat,)

    def __init__(self, atoms, timestep, temperature_K=None, taut=None, rng=None, *,
                 fixcm=None, **kwargs):
        required_arguments("RigidBussi", temperature_K=temperature_K, taut=taut)
        super().__init__(atoms, timestep, BussiThermostat(temperature_K, taut, rng, fixcm),
                         **kwargs)

    @property
    def taut(self):
        """Relaxation time (ASE time units)."""
        return self.thermostat.taut
