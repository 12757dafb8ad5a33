r"""What a rigid system reports, as functions of its state, model and per-step record.

Each function reads :class:`~rigidmd.state.RigidState`,
:class:`~rigidmd.model.BodyModel` and, for the pressure, a
:class:`~rigidmd.record.StepRecord`; none changes them.
:class:`~rigidmd.dynamics.RigidDynamics` exposes them as thin properties
(``dyn.angular_velocities``, ``dyn.get_stress()``, ...).  Units are ASE's: Å,
eV, amu and ASE time.
"""

import numpy as np

from rigidmd import operators as ops
from rigidmd.model import BodyModel
from rigidmd.state import RigidState

__all__ = ["volume", "kinetic_tensor", "kinetic_tensor_of", "translational_kinetic_energies",
           "rotational_kinetic_energies", "rotational_kinetic_energy", "angular_momenta",
           "angular_velocities", "largest_angular_speed", "total_angular_momentum",
           "free_kinetic_energy", "molecular_virial", "torque_virial", "stress_tensor",
           "voigt"]


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
    (:func:`rigidmd.operators.intramolecular_virial`) is taken out: what the
    pressure needs (the barostats).  Less :func:`torque_virial` too, it is the
    full :math:`W = \sum_b X_b\otimes F_b + \sum_\mathrm{free} x\otimes f`,
    the derivative of the energy under a deformation of the cell that moves
    the centres of mass and keeps the orientations (:mod:`rigidmd.relaxcell`).

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
