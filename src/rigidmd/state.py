"""The arrays a time step changes, and nothing else."""

from dataclasses import dataclass, fields

import numpy as np

__all__ = ["RigidState"]


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

    def copy(self):
        """A deep copy."""
        return RigidState(*(getattr(self, f.name).copy() for f in fields(self)))

    def copy_into(self, other):
        """Overwrite ``other``'s arrays in place with this state's values."""
        for f in fields(self):
            np.copyto(getattr(other, f.name), getattr(self, f.name))
