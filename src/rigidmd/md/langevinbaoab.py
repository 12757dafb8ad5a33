r"""BAOAB Langevin dynamics of rigid bodies: :class:`RigidLangevinBAOAB` (ASE's
``LangevinBAOAB``).

The part is :class:`~rigidmd.couplings.baoab.LangevinBAOABThermostat`.
"""

import numpy as np

from rigidmd.couplings.baoab import LangevinBAOABThermostat
from rigidmd.couplings.base import check_time
from rigidmd.md.coupled import ThermostattedDynamics

__all__ = ["RigidLangevinBAOAB"]


class RigidLangevinBAOAB(ThermostattedDynamics):
    r"""BAOAB Langevin dynamics of rigid bodies (see :mod:`rigidmd.couplings.baoab`).

    The O step sits in the middle of the deterministic step
    (:class:`LangevinBAOABThermostat`), with one force call per step.  The log
    and the run summary report the kinetic energies right after O; the Atoms'
    momenta, the trajectory and checkpoints hold the end-of-step state.

    Parameters
    ----------
    atoms : ase.Atoms
    timestep : float
        ASE time units.
    temperature_K : float
        K.
    friction : float, optional
        :math:`\gamma`, per ASE time unit (``0.001 / ase.units.fs`` is 1 ps⁻¹);
        no limit on ``friction * timestep``.
    T_tau : float, optional
        ASE's ``LangevinBAOAB`` argument: the friction's time (ASE time units),
        ``friction = 1 / T_tau``.  Give ``friction`` or ``T_tau``.
    rng : numpy.random.Generator, numpy.random.RandomState or numpy.random, optional
    fixcm : bool or None, default None
        Keep the total momentum, as :class:`~rigidmd.RigidLangevin`.
    **kwargs
        As for :class:`~rigidmd.core.dynamics.RigidDynamics`; ``integrator``
        must have a ``middle`` operator (default ``"baoab"``).

    References
    ----------
    B. Leimkuhler and C. Matthews, J. Chem. Phys. 138, 174102 (2013);
    R. L. Davidchack, T. E. Ouldridge and M. V. Tretyakov, J. Chem. Phys. 142,
    144114 (2015).
    """

    part_types = (LangevinBAOABThermostat,)

    def __init__(self, atoms, timestep, temperature_K=None, friction=None, *, T_tau=None,
                 rng=None, fixcm=None, **kwargs):
        npt = sorted(set(kwargs) & {"externalstress", "P_tau", "hydrostatic",
                                    "disable_cell_langevin", "mask"})
        if npt:  # ASE's LangevinBAOAB arguments for its NPT
            raise TypeError(f"RigidLangevinBAOAB: {npt[0]} is for ASE's LangevinBAOAB NPT; "
                            "this class is NVT: for NPT compose its thermostat part with "
                            "RigidMCBarostat (see the thermostats guide, NPT)")
        if friction is not None and T_tau is not None:
            raise TypeError("RigidLangevinBAOAB takes friction (per ASE time unit) or T_tau "
                            "(its time, friction = 1 / T_tau), not both")
        if T_tau is not None:
            tau = check_time("T_tau", T_tau)
            if not np.isfinite(1.0 / tau):
                raise ValueError(f"T_tau {T_tau!r} (ASE units) is too small: its inverse, the "
                                 "friction, is not a finite number")
            friction = 1.0 / tau
        if temperature_K is None or friction is None:
            missing = ", ".join(name for name, value in (("temperature_K", temperature_K),
                                                         ("friction or T_tau", friction))
                                if value is None)
            raise TypeError(f"RigidLangevinBAOAB needs temperature_K (K) and friction (per "
                            f"ASE time unit) or T_tau (ASE time units); missing: {missing}")
        kwargs.setdefault("integrator", "baoab")
        super().__init__(atoms, timestep,
                         LangevinBAOABThermostat(temperature_K, friction, rng, fixcm),
                         **kwargs)

    @property
    def friction(self):
        """Friction (per ASE time unit)."""
        return self.thermostat.friction

    def set_friction(self, friction):
        """Change the friction (per ASE time unit)."""
        self.thermostat.set_friction(friction)
