"""The arrays a time step changes, and nothing else."""

from dataclasses import dataclass

import numpy as np

__all__ = ["RigidState", "STATE_FIELDS"]

#: The state's arrays, in order.
STATE_FIELDS = ("X", "V", "q", "p", "x", "v", "cell")


@dataclass
class RigidState:
    r"""Dynamical state of the rigid bodies, the free atoms and the cell.

    Attributes
    ----------
    X : numpy.ndarray, shape (n_bodies, 3)
        Centres of mass (Å), unwrapped.
    V : numpy.ndarray, shape (n_bodies, 3)
        Centre-of-mass velocities (Å per ASE time unit).
    q : numpy.ndarray, shape (n_bodies, 4)
        Orientations ``(w, x, y, z)``; :math:`R(q)` maps body to lab frame.
    p : numpy.ndarray, shape (n_bodies, 4)
        NO_SQUISH conjugate quaternion momenta
        :math:`p = 2\, q \otimes (0, L_b)` (amu Å² per ASE time unit), with
        :math:`L_b` the body-frame angular momentum.
    x : numpy.ndarray, shape (n_free, 3)
        Positions of the atoms that are point particles (Å).
    v : numpy.ndarray, shape (n_free, 3)
        Their velocities (Å per ASE time unit).
    cell : numpy.ndarray, shape (3, 3)
        Cell vectors as rows (Å), as :attr:`ase.Atoms.cell`; only a barostat
        changes it.
    """

    X: np.ndarray
    V: np.ndarray
    q: np.ndarray
    p: np.ndarray
    x: np.ndarray
    v: np.ndarray
    cell: np.ndarray

    def copy(self) -> "RigidState":
        """A deep copy."""
        return RigidState(self.X.copy(), self.V.copy(), self.q.copy(), self.p.copy(),
                          self.x.copy(), self.v.copy(), self.cell.copy())

    def copy_into(self, other: "RigidState") -> None:
        """Overwrite ``other``'s arrays in place with this state's values.

        Spelled out field by field: this runs at every step (the rollback's
        backup), where walking ``dataclasses.fields`` cost 11 µs.
        """
        np.copyto(other.X, self.X)
        np.copyto(other.V, self.V)
        np.copyto(other.q, self.q)
        np.copyto(other.p, self.p)
        np.copyto(other.x, self.x)
        np.copyto(other.v, self.v)
        np.copyto(other.cell, self.cell)
