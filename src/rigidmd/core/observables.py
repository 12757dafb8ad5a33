r"""What a rigid system reports: the one home of every observable.

Two layers, both here:

* functions of :class:`~rigidmd.core.state.RigidState`,
  :class:`~rigidmd.core.model.BodyModel` and, for the pressure, the
  per-step record's virial and kinetic tensor; none changes its arguments
  (the per-step record, :class:`~rigidmd.core.record.StepRecord`, caches
  some of them for a step, computing them with these functions);
* :class:`RigidObservables`, the accessors a dynamics offers
  (``dyn.angular_velocities``, ``dyn.get_stress()``, ...), each a thin call
  of a function above; :class:`~rigidmd.core.dynamics.RigidDynamics` inherits
  them.

A new observable is a function here (and, when a dynamics should offer it,
an accessor on :class:`RigidObservables`); a quantity a coupling part reads
every step goes into the record too, computed by the function here.  Units
are ASE's: Å, eV, amu and ASE time.
"""

import warnings

import numpy as np
from ase import units

from rigidmd.core import operators as ops
from rigidmd.core.dof import kinetic_energy, temperature
from rigidmd.core.model import BodyModel
from rigidmd.core.state import RigidState

__all__ = ["volume", "kinetic_tensor", "kinetic_tensor_of", "translational_kinetic_energies",
           "rotational_kinetic_energies", "rotational_kinetic_energy", "angular_momenta",
           "angular_velocities", "largest_angular_speed", "total_angular_momentum",
           "free_kinetic_energy", "molecular_virial", "torque_virial", "stress_tensor",
           "voigt", "kinetic_dof", "kinetic_temperatures", "RigidObservables"]


def volume(cell: np.ndarray) -> float:
    """Volume of a cell (Å³), :math:`|\\det h|`."""
    return float(abs(np.linalg.det(cell)))


def kinetic_tensor(state: RigidState, model: BodyModel) -> np.ndarray:
    r"""Translational kinetic tensor :math:`\sum_b M_b V_b\otimes V_b + \sum_{free} m\,v\otimes v`.

    Twice the translational kinetic energy on the trace (eV), shape (3, 3).
    """
    return kinetic_tensor_of(state.V, state.v, model)


def kinetic_tensor_of(V: np.ndarray, v: np.ndarray, model: BodyModel) -> np.ndarray:
    """:func:`kinetic_tensor` of given centre-of-mass and point-particle velocities."""
    return (np.einsum("b,bi,bj->ij", model.mass, V, V)
            + np.einsum("f,fi,fj->ij", model.free_masses, v, v))


def translational_kinetic_energies(state: RigidState, model: BodyModel) -> np.ndarray:
    r"""Per-body :math:`\tfrac12 M |V|^2` (eV), shape (n_bodies,)."""
    return 0.5 * model.mass * np.sum(state.V**2, axis=1)


def free_kinetic_energy(state: RigidState, model: BodyModel) -> float:
    """Kinetic energy of the point particles (eV)."""
    return float(0.5 * np.sum(model.free_masses[:, None] * state.v**2))


def rotational_kinetic_energies(state: RigidState, model: BodyModel) -> np.ndarray:
    r"""Per-body :math:`\tfrac12 \sum_k L_{b,k}^2 / I_k` over axes with :math:`I_k > 0` (eV)."""
    L_body = ops.body_angular_momentum(state.q, state.p)
    return 0.5 * np.sum(L_body**2 * model.inv_moments, axis=1)


def rotational_kinetic_energy(state: RigidState, model: BodyModel) -> float:
    """Rotational kinetic energy of all bodies (eV)."""
    return float(rotational_kinetic_energies(state, model).sum())


def angular_momenta(state: RigidState, model: BodyModel) -> np.ndarray:
    """Lab-frame angular momenta about the centres of mass (amu Å² / ASE time), (n_bodies, 3)."""
    return ops.lab_angular_momentum(state.q, state.p)


def angular_velocities(state: RigidState, model: BodyModel) -> np.ndarray:
    """Lab-frame angular velocities (rad / ASE time), shape (n_bodies, 3)."""
    return ops.angular_velocity(state.q, ops.body_angular_momentum(state.q, state.p),
                                model.inv_moments)


def largest_angular_speed(state: RigidState, model: BodyModel) -> tuple[int, float]:
    r"""The body turning fastest and its :math:`|\omega|` (rad / ASE time).

    :math:`|\omega| = |L_b / I|` (a rotation keeps the norm), with
    :math:`L_b = \tfrac12\,\mathrm{vec}(q^*\otimes p)` written out: no
    quaternion products, for the step-size check.
    """
    q, p = state.q, state.p
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    p0, p1, p2, p3 = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    inv = model.inv_moments
    o1 = 0.5 * (w * p1 - x * p0 - y * p3 + z * p2) * inv[:, 0]
    o2 = 0.5 * (w * p2 - y * p0 - z * p1 + x * p3) * inv[:, 1]
    o3 = 0.5 * (w * p3 - z * p0 - x * p2 + y * p1) * inv[:, 2]
    speed2 = o1 * o1 + o2 * o2 + o3 * o3
    b = int(np.argmax(speed2))
    return b, float(np.sqrt(speed2[b]))


def total_angular_momentum(state: RigidState, model: BodyModel) -> np.ndarray:
    r"""Total angular momentum about the origin (amu Å² / ASE time), shape (3,).

    :math:`\sum_b (X_b \times M_b V_b + R(q_b) L_{b}) + \sum_{free} x \times m v`.
    """
    s, m = state, model
    L = np.cross(s.X, m.mass[:, None] * s.V).sum(axis=0)
    L = L + angular_momenta(state, model).sum(axis=0)
    return L + np.cross(s.x, m.free_masses[:, None] * s.v).sum(axis=0)


def molecular_virial(atomic_stress: np.ndarray, cell_volume: float, r: np.ndarray,
                     forces: np.ndarray, model: BodyModel) -> np.ndarray:
    r"""Molecular virial (eV, 3x3): the atomic virial :math:`-V\sigma` less its intramolecular part.

    The symmetric part :math:`\mathrm{sym}(R)` of
    :math:`R = \sum_b\sum_{i\in b} r_i\otimes f_i`
    (:func:`rigidmd.core.operators.intramolecular_virial`) is taken out: what the
    pressure needs (the barostats).  Less :func:`torque_virial` too, it is the
    full :math:`W = \sum_b X_b\otimes F_b + \sum_\mathrm{free} x\otimes f`,
    the derivative of the energy under a deformation of the cell that moves
    the centres of mass and keeps the orientations (:mod:`rigidmd.relax.cell`).

    Parameters
    ----------
    atomic_stress : numpy.ndarray, shape (3, 3)
        The calculator's stress without the ideal-gas part (eV/Å³).
    cell_volume : float
        Å³.
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements of the body atoms (Å), in ``model.order``.
    forces : numpy.ndarray, shape (n_atoms, 3)
        Atom forces (eV/Å).
    model : BodyModel
    """
    return -cell_volume * atomic_stress - ops.intramolecular_virial(r, forces, model)


def torque_virial(torques: np.ndarray) -> np.ndarray:
    r"""The antisymmetric part of the intramolecular virial, :math:`\tfrac12[\sum_b\tau_b]_\times`.

    :math:`[\tau]_{\times,ij} = \epsilon_{ijk}\tau_k` (eV, 3x3), from the lab
    torques about the centres of mass, ``torques`` of shape (n_bodies, 3) (eV):
    :math:`R_{ij} - R_{ji}` of :math:`R = \sum_b\sum_{i\in b} r_i\otimes f_i`.
    """
    tx, ty, tz = torques.sum(axis=0) if len(torques) else np.zeros(3)
    return 0.5 * np.array([[0.0, tz, -ty], [-tz, 0.0, tx], [ty, -tx, 0.0]])


def stress_tensor(virial: np.ndarray, kinetic: np.ndarray | None, cell_volume: float
                  ) -> np.ndarray:
    r"""Molecular stress :math:`\sigma = -(\mathsf W + \mathsf K)/V` (eV/Å³), shape (3, 3).

    ``kinetic`` None leaves out the ideal-gas part.
    """
    W = virial if kinetic is None else virial + kinetic
    return -W / cell_volume


def voigt(sigma: np.ndarray) -> np.ndarray:
    """A symmetric 3x3 tensor in ASE's Voigt order ``(xx, yy, zz, yz, xz, xy)``."""
    return sigma[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]


_voigt = voigt  # RigidObservables.get_stress's argument ``voigt`` hides the function


def kinetic_dof(model: BodyModel, holds_momentum: bool) -> tuple[int, int]:
    """(translational, rotational) degrees of freedom of the kinetic temperatures.

    Translational: 3 per body and per point particle, less 3 when the total
    momentum is held (``fixcm``, ASE's ``FixCom``); rotational: 3 per body, 2
    per linear body.  Their sum is what ``atoms.get_temperature()`` counts
    under the dynamics' :class:`~rigidmd.core.dof.RigidBodyDOF`.
    """
    n_tr = model.translational_dof - (3 if holds_momentum else 0)
    return max(n_tr, 0), model.rotational_dof


def kinetic_temperatures(K_tr: float, K_rot: float, dof: tuple[int, int]) -> tuple[float, float]:
    """(T_tr, T_rot) in K of the kinetic energies ``K_tr, K_rot`` (eV) over ``dof``; a part
    with no degree of freedom reads 0 K."""
    return tuple(2.0 * K / (n * units.kB) if n else 0.0
                 for K, n in zip((K_tr, K_rot), dof, strict=True))


class RigidObservables:
    """The observables a rigid dynamics offers, read from its parts (a mixin).

    The class using it provides ``state``, ``model``, ``record``,
    ``evaluator`` (a :class:`~rigidmd.core.forces.ForceEvaluator`), ``link``,
    ``view`` and ``couplings`` (the coupling parts and what they see), ``atoms`` and
    ``holds_momentum`` (whether the total momentum is held).
    """

    @property
    def removed_kinetic_energy(self) -> float:
        """Kinetic energy (eV) the last projection onto rigid motion removed (``link``'s)."""
        return self.link.removed_kinetic_energy

    @property
    def degrees_of_freedom(self) -> int:
        """The degrees of freedom every temperature of this dynamics counts.

        6 per body, 5 per linear body, 3 per point particle, less the 3 of the
        centre of mass where the dynamics holds the total momentum (a
        thermostat's ``fixcm``, ASE's ``FixCom`` on the atoms): the count that
        ``atoms.get_temperature()``, the MD log and the run summary use.  The
        bodies' own count, centre of mass included, is
        ``model.degrees_of_freedom``.
        """
        held = 3 if self.holds_momentum else 0
        return max(self.model.degrees_of_freedom - held, 0)

    @property
    def translational_dof(self) -> int:
        """Centre-of-mass and point-particle degrees of freedom: 3 each."""
        return self.model.translational_dof

    @property
    def rotational_dof(self) -> int:
        """Rotational degrees of freedom: 3 per body, 2 per linear body."""
        return self.model.rotational_dof

    @property
    def com_positions(self) -> np.ndarray:
        """Centres of mass of the bodies (Å), unwrapped, shape (n_bodies, 3)."""
        return self.state.X.copy()

    @property
    def com_velocities(self) -> np.ndarray:
        """Centre-of-mass velocities (Å per ASE time unit), shape (n_bodies, 3)."""
        return self.state.V.copy()

    @property
    def quaternions(self) -> np.ndarray:
        """Orientations ``(w, x, y, z)``, body to lab frame, shape (n_bodies, 4)."""
        return self.state.q.copy()

    @property
    def moments_of_inertia(self) -> np.ndarray:
        """Principal moments (amu Å²), ascending, shape (n_bodies, 3)."""
        return self.model.moments.copy()

    @property
    def angular_momenta(self) -> np.ndarray:
        """Lab angular momenta about the centres of mass (amu Å² / ASE time), (n_bodies, 3)."""
        return angular_momenta(self.state, self.model)

    @property
    def angular_velocities(self) -> np.ndarray:
        """Lab-frame angular velocities (rad / ASE time), shape (n_bodies, 3)."""
        return angular_velocities(self.state, self.model)

    @property
    def translational_kinetic_energies(self) -> np.ndarray:
        r"""Per-body :math:`\tfrac12 M |V|^2` (eV), shape (n_bodies,)."""
        return translational_kinetic_energies(self.state, self.model)

    @property
    def rotational_kinetic_energies(self) -> np.ndarray:
        r"""Per-body rotational energy :math:`\tfrac12 \sum_k L_{b,k}^2 / I_k` (eV), (n_bodies,)."""
        return rotational_kinetic_energies(self.state, self.model)

    def get_angular_momentum(self) -> np.ndarray:
        r"""Total angular momentum about the origin (amu Å² / ASE time), shape (3,).

        For a linear body this includes the axial component that NO_SQUISH's
        splitting builds up (as in LAMMPS), which atom velocities cannot show;
        this total, not the atoms' :math:`\sum_i x_i \times p_i`, is what the
        integrator conserves (:func:`rigidmd.core.observables.total_angular_momentum`).
        """
        return total_angular_momentum(self.state, self.model)

    def get_translational_kinetic_energy(self) -> float:
        """Kinetic energy of the centres of mass plus that of the point particles (eV)."""
        return float(self.translational_kinetic_energies.sum()
                     + free_kinetic_energy(self.state, self.model))

    def get_rotational_kinetic_energy(self) -> float:
        """Rotational kinetic energy of all bodies (eV)."""
        return rotational_kinetic_energy(self.state, self.model)

    def get_volume(self) -> float:
        """Volume of the cell (Å³); a clear error for a cell that is not periodic."""
        if not self.atoms.pbc.all():
            raise ValueError("the volume and pressure need a cell periodic in all three "
                             f"directions; atoms.pbc is {self.atoms.pbc.tolist()}")
        return self.record.volume

    def get_density(self) -> float:
        """Mass density (g/cm³)."""
        grams = self.atoms.get_masses().sum() / units.kg * 1e3
        return float(grams / (self.get_volume() * 1e-24))

    def molecular_virial(self) -> np.ndarray:
        r"""Molecular virial :math:`\sum_b X_b \otimes F_b + \sum_{free} x\otimes f` (eV, 3x3).

        The calculator's atomic virial :math:`-V\sigma` less the
        intramolecular part :math:`\sum_b\sum_{i\in b} d_i \otimes f_i`
        (symmetrised), at the current positions: the per-step record's under
        a barostat, else asked of the calculator now.
        """
        if self.evaluator.stress and self.record.virial is not None:
            return self.record.virial
        self.get_volume()  # a clear error for a cell that is not periodic
        forces = np.asarray(self.atoms.get_forces(md=True), dtype=float)
        return self.evaluator.molecular_virial(forces)

    def get_stress(self, include_ideal_gas: bool = True, voigt: bool = True) -> np.ndarray:
        r"""Molecular stress (eV/Å³) in ASE's sign convention and Voigt order.

        :math:`\sigma = -(\mathsf W + \mathsf K)/V` with the positional part
        :math:`\mathsf W` from :meth:`molecular_virial` and the kinetic tensor
        :math:`\mathsf K` of the centres of mass and point particles (only with
        ``include_ideal_gas``); see :func:`rigidmd.core.observables.stress_tensor`.
        Centres of mass, not atoms, carry the pressure of rigid molecules; the
        atomic pressure including the constraint forces has the same trace.

        Raises
        ------
        ase.calculators.calculator.PropertyNotImplementedError
            The calculator provides no stress (the message names it).
        ValueError
            The cell is not periodic in all three directions.
        """
        volume = self.get_volume()
        kinetic = self.record.kinetic_tensor if include_ideal_gas else None
        sigma = stress_tensor(self.molecular_virial(), kinetic, volume)
        return _voigt(sigma) if voigt else sigma

    def get_pressure(self) -> float:
        """Instantaneous molecular pressure, minus a third of the stress trace (eV/Å³)."""
        return float(-np.trace(self.get_stress(voigt=False)) / 3.0)

    @property
    def reports_own_kinetic_energies(self) -> bool:
        """Whether a coupling part keeps the kinetic energies the log reports (BAOAB's)."""
        return any(part.reported_kinetic_energies(self.view) is not None
                   for part in self.couplings)

    def get_reported_kinetic_energy(self) -> tuple[float, float]:
        """(kinetic energy in eV, temperature in K) as the log and the summary show them.

        The Atoms' (:func:`rigidmd.core.dof.kinetic_energy`,
        :func:`rigidmd.core.dof.temperature`), or the sum of
        :meth:`get_kinetic_energies` over every kinetic degree of freedom when a
        part keeps its own (:attr:`reports_own_kinetic_energies`) or the total
        momentum is held: the centre of mass's kinetic energy, a constant then and
        not among the degrees of freedom counted, is left out (ASE's
        ``atoms.get_temperature()`` counts it over the same degrees of freedom, and
        reads higher by ``P²/(M k_B N_f)`` when the held momentum is not zero).
        """
        if not (self.reports_own_kinetic_energies or self.holds_momentum):
            return kinetic_energy(self.atoms), temperature(self.atoms)
        ekin = sum(self.get_kinetic_energies())
        return ekin, kinetic_temperatures(
            ekin, 0.0, (sum(kinetic_dof(self.model, self.holds_momentum)), 0))[0]

    def get_kinetic_energies(self) -> tuple[float, float]:
        """(translational, rotational) kinetic energy the log and the summary report (eV).

        Those a coupling part keeps where its scheme samples the kinetic
        distribution (:class:`~rigidmd.RigidLangevinBAOAB`: right after its O step,
        see :mod:`rigidmd.couplings.baoab`), else the state's at the end of the
        step; the translational part relative to the centre of mass when the total
        momentum is held.  When code between steps (an observer, the caller of
        ``irun``, a user between runs) has changed the Atoms' momenta or positions
        since the dynamics wrote them, those of the Atoms (read onto the bodies as
        the next step will read them): no step has acted on them yet.
        """
        s = self._state_the_atoms_hold()
        if s is None:
            for part in self.couplings:
                values = part.reported_kinetic_energies(self.view)
                if values is not None:
                    return float(values[0]), float(values[1])
            s = self.state
        m = self.model
        K_tr = float(translational_kinetic_energies(s, m).sum() + free_kinetic_energy(s, m))
        if self.holds_momentum:
            M = m.mass.sum() + m.free_masses.sum()
            P = m.mass @ s.V + m.free_masses @ s.v
            K_tr -= 0.5 * float(P @ P) / M if M > 0 else 0.0
        return K_tr, rotational_kinetic_energy(s, m)

    def _state_the_atoms_hold(self):
        """The state read from the Atoms when their positions or momenta are no longer those
        the dynamics' state gives (changed between steps; the next step reads them), else
        None.  Compared to 1e-9 of their size: the compiled and NumPy placements part by
        roundoff, a change a user makes does not."""
        link, state, m = self.link, self.state, self.model
        atoms = link.atoms
        positions = np.empty_like(atoms.arrays["positions"])
        momenta = np.empty_like(atoms.arrays["momenta"])
        positions[m.free], momenta[m.free] = state.x, m.free_masses[:, None] * state.v
        r = link.backend.place(state, m, None, positions)
        link.backend.write_momenta(state, m, r, momenta)

        def same(mine, theirs):
            scale = max(float(np.abs(theirs).max(initial=0.0)), 1e-300)
            return float(np.abs(mine - theirs).max(initial=0.0)) <= 1e-9 * scale

        moved = not (same(positions, atoms.arrays["positions"])
                     and same(np.asarray(state.cell), atoms.cell.array))
        if not moved and same(momenta, atoms.arrays["momenta"]):
            return None
        held = state.copy()
        with warnings.catch_warnings():  # the next step reads them, and warns, as it does
            warnings.simplefilter("ignore")
            if moved:
                link.read_positions(held)
            link.read_momenta(held)
        return held

    def get_kinetic_temperatures(self) -> tuple[float, float]:
        """(T_tr, T_rot) in K: :meth:`get_kinetic_energies` over :func:`kinetic_dof`."""
        return kinetic_temperatures(*self.get_kinetic_energies(),
                                    kinetic_dof(self.model, self.holds_momentum))

    def get_conserved_energy(self) -> float:
        """Total energy plus every coupling part's term (eV): what the dynamics conserves.

        For NVE this is the total energy; a stochastic thermostat subtracts the
        energy it put in, Nosé–Hoover chains add their own energy.
        """
        energy = self.atoms.get_potential_energy() + kinetic_energy(self.atoms)
        return float(energy + sum(part.energy(self.view) for part in self.couplings))
