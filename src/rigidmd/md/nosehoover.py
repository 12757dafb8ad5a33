"""Nosé–Hoover chains for rigid bodies: :class:`RigidNoseHoover` (ASE's
``NoseHooverChainNVT``).

The part is :class:`~rigidmd.couplings.thermostats.NoseHooverThermostat`.
"""

from rigidmd.couplings.thermostats import NoseHooverThermostat
from rigidmd.md.coupled import ThermostattedDynamics, required_arguments

__all__ = ["RigidNoseHoover"]


class RigidNoseHoover(ThermostattedDynamics):
    r"""Nosé–Hoover chains for rigid bodies (LAMMPS ``fix rigid/nvt``).

    See :class:`NoseHooverThermostat`.  The positional arguments are ASE's
    ``NoseHooverChainNVT``'s (``atoms, timestep, temperature_K, tdamp, tchain,
    tloop``, with its defaults), and ``fixcm`` (by keyword), which ASE's has not.

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

    part_types = (NoseHooverThermostat,)

    def __init__(self, atoms, timestep, temperature_K=None, tdamp=None, tchain=3, tloop=1,
                 *, fixcm=None, **kwargs):
        required_arguments("RigidNoseHoover", temperature_K=temperature_K, tdamp=tdamp)
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

    @property
    def thermostat_work(self):
        """Energy the thermostat has put into the system so far (eV): what the chains gave,
        minus their energy (they start with none), as the stochastic thermostats book it."""
        return -self.chain_energy()
