r"""BAOAB Langevin dynamics of rigid bodies: the O step in the middle of NO_SQUISH.

One step of :math:`\Delta t = h` is

.. code-block:: text

    B(h/2)   kick: V += (h/2) F/M,  p += (h/2) 2 q ⊗ (0, R(q)ᵀ τ)
    A(h/2)   drift X += (h/2) V, NO_SQUISH free rotor over h/2
             (R3(h/4) R2(h/4) R1(h/2) R2(h/4) R3(h/4))
    O(h)     exact Ornstein–Uhlenbeck step of V and of the body-frame L_b
    A(h/2)   as above; the atoms placed; one calculator call
    B(h/2)   kick with the new forces and torques

(the ``baoab`` scheme of :mod:`rigidmd.core.schemes`; the O step is the
:meth:`LangevinBAOABThermostat.middle` of the part, called by the scheme's
``middle`` operator).  The orientation does not change in O, so O samples the
kinetic distribution exactly for any ``friction * timestep``; the splitting's
configurational error is that of BAOAB (Leimkuhler & Matthews), much smaller
than that of the O-NO_SQUISH-O splitting of :class:`~rigidmd.RigidLangevin` at
the same step.

Where the momenta are read: the momenta right after O sample the kinetic
distribution; at the end of the step (after the last half kick) they carry
BAOAB's kinetic bias (a few K low in :math:`T_\mathrm{rot}` for water at 4 fs).
The part keeps the kinetic energies after O (:meth:`~LangevinBAOABThermostat.
reported_kinetic_energies`): the MD log's ``Ekin``, ``T`` (and ``Etot``), the
run summary and :meth:`~rigidmd.core.observables.RigidObservables.get_kinetic_temperatures`
report them.  The state, the checkpoint, the Atoms' momenta (what ASE's
observers and the trajectory see) and the conserved energy are those at the
end of the step: the exact state from which the next step continues.
"""

import numpy as np

from rigidmd.couplings.base import (
    TEMPERATURE,
    CouplingView,
    NotExportable,
    Parameter,
    fixcm_parameter,
    register,
)
from rigidmd.couplings.thermostats import SEED, _Stochastic, check_friction

__all__ = ["LangevinBAOABThermostat"]


@register
class LangevinBAOABThermostat(_Stochastic):
    r"""The O step of BAOAB, in the middle of the step (see :mod:`rigidmd.couplings.baoab`).

    With :math:`c = e^{-\gamma h}` and :math:`\xi \sim \mathcal N(0, 1)`:

    .. math::
        P \leftarrow c P + \sqrt{(1 - c^2) M k_B T}\;\xi,\qquad
        L_{b,k} \leftarrow c L_{b,k} + \sqrt{(1 - c^2) I_k k_B T}\;\xi

    on the centre-of-mass momenta, the body-frame angular momenta (a component
    about an axis with :math:`I_k = 0`, of a linear body, only decays) and the
    point particles; with ``fixcm`` about the centre-of-mass velocity, which it
    keeps.  The deviates are drawn in one call per step, in the order
    :math:`V`, free atoms, :math:`L_b`.  Its ``first_half`` and ``second_half``
    do nothing (the latter checks the net force for ``fixcm=None``).

    Parameters
    ----------
    temperature_K : float
        K.
    friction : float
        :math:`\gamma`, per ASE time unit (``0.001 / ase.units.fs`` is 1 ps⁻¹); any
        ``friction * timestep`` (the O step is exact).
    rng : numpy.random.Generator, optional
    fixcm : bool or None, default None
        Keep the total momentum (see :class:`~rigidmd.couplings.base.Thermostat`).

    References
    ----------
    B. Leimkuhler and C. Matthews, Appl. Math. Res. Express 2013, 34 (2013);
    J. Chem. Phys. 138, 174102 (2013).  R. L. Davidchack, T. E. Ouldridge and
    M. V. Tretyakov, J. Chem. Phys. 142, 144114 (2015); arXiv:1708.03357 (2017).
    """

    kind = "langevin_baoab"
    parameters = (TEMPERATURE, Parameter("friction", "friction", "rate", example="1 1/ps"),
                  SEED, fixcm_parameter(None))
    acts_in_middle = True

    def __init__(self, temperature_K, friction, rng=None, fixcm=None):
        super().__init__(temperature_K, rng, fixcm)
        self.friction = check_friction(friction)
        self.reported = None  # (K_tr, K_rot) after the last O step, eV

    def set_friction(self, friction: float) -> None:
        """Change the friction (per ASE time unit); any value >= 0."""
        self.friction = check_friction(friction)

    def first_half(self, view: CouplingView, h: float) -> None:
        """Nothing: the part acts in the middle of the step."""

    def second_half(self, view: CouplingView, h: float) -> None:
        """Nothing but the net-force check of ``fixcm=None``."""
        if self.watches_net_force and not self.warned:
            self.check_net_force(view)

    def middle(self, view: CouplingView, h: float) -> None:
        """The O step over ``h``; keeps the kinetic energies after it for the log."""
        s, m, record = view.state, view.model, view.record
        before = record.translational_energy + record.rotational_energy
        U = self.centre_velocity(view)
        c = float(np.exp(-self.friction * h))
        sigma = float(np.sqrt((1.0 - c * c) * self.kT))
        n, nf = len(s.X), len(s.x)
        noise = self.rng.standard_normal(6 * n + 3 * nf)
        scales = (1.0 / np.sqrt(m.mass), 1.0 / np.sqrt(m.free_masses), np.sqrt(m.moments))
        view.backend.ornstein_uhlenbeck(s.data, n, nf, c, sigma, *scales, noise)
        s.touched(momenta=True)  # written in place
        self.set_centre_velocity(view, U)
        self.work += record.translational_energy + record.rotational_energy - before
        self.reported = self.kinetic_energies(view)

    def reported_kinetic_energies(self, view: CouplingView) -> tuple | None:
        """(translational, rotational) kinetic energy after the last O step (eV), or None.

        Translational relative to the centre of mass when the momentum is kept.
        """
        return self.reported

    def get_state(self):
        reported = np.full(2, np.nan) if self.reported is None else np.array(self.reported)
        return super().get_state() | {"reported": reported}

    def set_state(self, state):
        super().set_state(state)
        reported = np.asarray(state["reported"], dtype=float)
        self.reported = None if np.isnan(reported).any() else tuple(map(float, reported))

    def lammps_fix(self, time_unit, seed=12345):
        raise NotExportable(
            "thermostat.kind: langevin_baoab is a BAOAB splitting, which no LAMMPS rigid "
            "fix runs (rigid/nve/small langevin is the O-NO_SQUISH-O splitting of kind "
            "langevin); export with kind langevin")

    def todict(self):
        return super().todict() | {"friction": self.friction}
