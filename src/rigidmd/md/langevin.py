"""Langevin dynamics of rigid bodies: :class:`RigidLangevin` (ASE's ``Langevin``).

The part is :class:`~rigidmd.couplings.thermostats.LangevinThermostat`.
"""

from rigidmd.couplings.thermostats import LangevinThermostat
from rigidmd.md.coupled import ThermostattedDynamics, required_arguments

__all__ = ["RigidLangevin"]


class RigidLangevin(ThermostattedDynamics):
    r"""Langevin dynamics of rigid bodies.

    See :class:`LangevinThermostat`.  The arguments are in the order of ASE's
    ``Langevin`` (``atoms, timestep, temperature, friction, fixcm``, then ``rng``
    by keyword) with one difference: the third is ``temperature_K``, in K, where
    ASE's is ``temperature`` in eV (deprecated there; ``temperature_K`` is a
    keyword of ASE's).  Pass ``temperature_K=`` by name and a call reads the same
    for both.

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
    fixcm : bool or None, default None
        Keep the total momentum (no drift of the whole system), as ASE's ``Langevin``
        (its fifth positional argument there too, default True); None is True, with
        a warning at the first step whose forces do not conserve the momentum (a
        wall, an external field: pass False there).
    rng : numpy.random.Generator, numpy.random.RandomState or numpy.random, optional
        By keyword, as in ASE's ``Langevin``.
    **kwargs
        ``bodies``, ``integrator``, ``integrator_options``, ``trajectory``,
        ``logfile``, ``loginterval``, ``backend`` as for
        :class:`~rigidmd.core.dynamics.RigidDynamics`.
    """

    part_types = (LangevinThermostat,)

    def __init__(self, atoms, timestep, temperature_K=None, friction=None, fixcm=None, *,
                 rng=None, **kwargs):
        required_arguments("RigidLangevin", temperature_K=temperature_K, friction=friction)
        super().__init__(atoms, timestep,
                         LangevinThermostat(temperature_K, friction, rng, fixcm), **kwargs)

    @property
    def friction(self):
        """Friction (per ASE time unit)."""
        return self.thermostat.friction

    def set_friction(self, friction):
        """Change the friction (per ASE time unit), as ASE's ``Langevin.set_friction``."""
        self.thermostat.set_friction(friction, self.dt)
