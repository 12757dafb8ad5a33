r"""What a rigid dynamics object reports: per-body state, energies and pressure.

:class:`RigidObservables` is the part of :class:`rigidmd.RigidDynamics` that
reads the rigid state without changing it: degrees of freedom, centre-of-mass
and angular quantities, kinetic energies, and the molecular virial, stress
and pressure (for barostats and logs).  Units are ASE's: Å, eV, amu and ASE
time.
"""

import numpy as np
from ase import units
from ase.calculators.calculator import PropertyNotImplementedError

from rigidmd import operators as ops
from rigidmd.atomslink import kinetic_energy

__all__ = ["RigidObservables", "NonFiniteForceError"]


class NonFiniteForceError(ValueError):
    """The calculator returned a force, energy or stress that is NaN or infinite."""


class RigidObservables:
    """Read-only views of a rigid dynamics object's state (mixin of RigidDynamics)."""

    # ------------------------------------------------------------ per-body state
    @property
    def degrees_of_freedom(self):
        """Rigid degrees of freedom: 6 per body, 5 per linear body, 3 per point particle."""
        return self.model.degrees_of_freedom

    @property
    def translational_dof(self):
        """Centre-of-mass and point-particle degrees of freedom: 3 each."""
        return self.model.translational_dof

    @property
    def rotational_dof(self):
        """Rotational degrees of freedom: 3 per body, 2 per linear body."""
        return self.model.rotational_dof

    @property
    def com_positions(self):
        """Centres of mass of the bodies (Å), unwrapped, shape (n_bodies, 3)."""
        return self.state.X.copy()

    @property
    def com_velocities(self):
        """Centre-of-mass velocities (Å per ASE time unit), shape (n_bodies, 3)."""
        return self.state.V.copy()

    @property
    def quaternions(self):
        """Orientations ``(w, x, y, z)``, body to lab frame, shape (n_bodies, 4)."""
        return self.state.q.copy()

    @property
    def moments_of_inertia(self):
        """Principal moments (amu Å²), ascending, shape (n_bodies, 3)."""
        return self.model.moments.copy()

    @property
    def angular_momenta(self):
        """Lab-frame angular momenta about the centres of mass, shape (n_bodies, 3).

        Units amu Å² per ASE time unit.
        """
        return ops.lab_angular_momentum(self.state.q, self.state.p)

    @property
    def angular_velocities(self):
        """Lab-frame angular velocities (rad / ASE time), shape (n_bodies, 3)."""
        s = self.state
        return ops.angular_velocity(s.q, ops.body_angular_momentum(s.q, s.p),
                                    self.model.inv_moments)

    @property
    def translational_kinetic_energies(self):
        r"""Per-body :math:`\tfrac12 M |V|^2` (eV), shape (n_bodies,)."""
        return 0.5 * self.model.mass * np.sum(self.state.V**2, axis=1)

    @property
    def rotational_kinetic_energies(self):
        r"""Per-body rotational energy (eV), shape (n_bodies,).

        :math:`\tfrac12 \sum_k L_{b,k}^2 / I_k` over the axes with :math:`I_k > 0`.
        """
        L_body = ops.body_angular_momentum(self.state.q, self.state.p)
        return 0.5 * np.sum(L_body**2 * self.model.inv_moments, axis=1)

    def get_angular_momentum(self):
        r"""Total angular momentum about the origin (amu Å² / ASE time), shape (3,).

        :math:`\sum_b (X_b \times M_b V_b + R(q_b) L_{b}) + \sum_{free} x \times m v`,
        with :math:`L_b` from the NO_SQUISH momentum.  For a linear body this
        includes the axial component that NO_SQUISH's splitting builds up (as in
        LAMMPS), which atom velocities cannot show; this total, not the atoms'
        :math:`\sum_i x_i \times p_i`, is what the integrator conserves.
        """
        s, m = self.state, self.model
        L = np.cross(s.X, m.mass[:, None] * s.V).sum(axis=0) + self.angular_momenta.sum(axis=0)
        return L + np.cross(s.x, m.free_masses[:, None] * s.v).sum(axis=0)

    def get_translational_kinetic_energy(self):
        """Kinetic energy of the centres of mass plus that of the point particles (eV)."""
        free = 0.5 * np.sum(self.model.free_masses[:, None] * self.state.v**2)
        return float(self.translational_kinetic_energies.sum() + free)

    def get_rotational_kinetic_energy(self):
        """Rotational kinetic energy of all bodies (eV)."""
        return float(self.rotational_kinetic_energies.sum())

    # ------------------------------------------------------------ pressure
    def _molecular_virial(self, forces):
        r"""The molecular virial (eV, 3x3): the atomic virial less its intramolecular part."""
        try:
            stress = self.atoms.get_stress(voigt=False, include_ideal_gas=False)
        except PropertyNotImplementedError:
            raise PropertyNotImplementedError(
                f"the calculator {type(self.atoms.calc).__name__} provides no stress, so the "
                "pressure is unknown; use a calculator with stress (e.g. "
                "rigidmd.lammps.LAMMPSCalculator)") from None
        stress = np.asarray(stress, dtype=float)
        if not np.isfinite(stress.sum()):
            raise NonFiniteForceError(f"calculator returned a non-finite stress {stress.tolist()} "
                                      f"after step {self.nsteps}")
        virial = -self.get_volume() * stress
        return virial - ops.intramolecular_virial(self._ctx.r, forces, self.model)

    def get_volume(self):
        """Volume of the cell (Å³); a clear error for a cell that is not periodic."""
        if not self.atoms.pbc.all():
            raise ValueError("the volume and pressure need a cell periodic in all three "
                             f"directions; atoms.pbc is {self.atoms.pbc.tolist()}")
        return float(abs(np.linalg.det(self.state.cell)))

    def get_density(self):
        """Mass density (g/cm³)."""
        grams = self.atoms.get_masses().sum() * units._amu * 1e3
        return float(grams / (self.get_volume() * 1e-24))

    def molecular_virial(self):
        r"""Molecular virial :math:`\sum_b X_b \otimes F_b + \sum_{free} x\otimes f` (eV, 3x3).

        The calculator's atomic virial :math:`-V\sigma` less the
        intramolecular part :math:`\sum_b\sum_{i\in b} d_i \otimes f_i`
        (symmetrised), at the current positions.
        """
        if self._needs_stress and self._virial is not None:
            return self._virial
        return self._molecular_virial(np.asarray(self.atoms.get_forces(md=True), dtype=float))

    def get_stress(self, include_ideal_gas=True, voigt=True):
        r"""Molecular stress (eV/Å³) in ASE's sign convention and Voigt order.

        .. math::
            \sigma = -\frac{1}{V}\Big(\sum_b X_b \otimes F_b
                + \sum_b M_b V_b \otimes V_b + \sum_{free} m\, v \otimes v\Big)

        with the positional part from :meth:`molecular_virial` (the kinetic
        part only with ``include_ideal_gas``).  Centres of mass, not atoms,
        carry the pressure of rigid molecules; the instantaneous atomic
        pressure including the constraint forces that keep the molecules rigid
        has the same trace.  The antisymmetric part of the intramolecular
        virial (the bodies' torques, zero on average) is left out.

        Parameters
        ----------
        include_ideal_gas : bool, default True
        voigt : bool, default True
            ``(xx, yy, zz, yz, xz, xy)``, else a 3x3 matrix.

        Raises
        ------
        ase.calculators.calculator.PropertyNotImplementedError
            The calculator provides no stress (the message names it).
        ValueError
            The cell is not periodic in all three directions.
        """
        volume = self.get_volume()
        W = self.molecular_virial()
        if include_ideal_gas:
            W = W + ops.kinetic_tensor(self.state, self.model)
        sigma = -W / volume
        if voigt:
            return sigma[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]
        return sigma

    def get_pressure(self):
        """Instantaneous molecular pressure, minus a third of the stress trace (eV/Å³)."""
        return float(-np.trace(self.get_stress(voigt=False)) / 3.0)

    def get_conserved_energy(self):
        """Total energy plus every coupling part's term (eV): what the dynamics conserves.

        For NVE this is the total energy; a stochastic thermostat subtracts the
        energy it put in, Nosé–Hoover chains add their own energy.
        """
        energy = self.atoms.get_potential_energy() + kinetic_energy(self.atoms)
        return float(energy + sum(part.energy() for part in self.couplings))
