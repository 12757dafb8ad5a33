"""What ASE's temperature reads on a rigid system: degrees of freedom and kinetic energy.

:class:`RigidBodyDOF` is the marker a rigid dynamics puts in
``atoms.constraints``; :func:`kinetic_energy` and :func:`temperature` are
ASE's, with massless virtual sites left out.
"""

import numpy as np
from ase import Atoms, units

__all__ = ["RigidBodyDOF", "kinetic_energy", "temperature"]


class RigidBodyDOF:
    """Marks rigid bodies for ASE's degree-of-freedom count.

    A rigid dynamics puts one of these in ``atoms.constraints`` so that
    :meth:`ase.Atoms.get_temperature` and :class:`ase.md.MDLogger` count 6
    degrees of freedom per body (5 per linear body) and 3 per point particle,
    3 fewer when the dynamics holds the total momentum (a thermostat's
    ``fixcm=True``; ASE's ``FixCom`` counts its own 3).  It never changes
    positions, momenta or forces.  It has no ``todict``, so trajectory
    writers skip it and ``.traj`` files stay readable by plain
    :func:`ase.io.read`.

    Parameters
    ----------
    removed_dof : int
        ``3 * len(atoms)`` minus the degrees of freedom left.
    molecule_ids : array_like of int, shape (n_atoms,), optional
        Each atom's body as a molecule ID (body ``b`` is ``b + 1``, an atom in
        no body -1; :func:`rigidmd.core.bodies.molecule_ids`), for calculators
        that need molecules (:class:`rigidmd.lammps.LAMMPSCalculator`
        excludes pairs within one; IDs <= 0 are no molecule).  With them the
        marker knows how many atoms it counts: atoms extended since (``atoms +
        other``, ``extend``) are refused by :meth:`get_removed_dof`, and
        ``atoms.repeat`` repeats the bodies (:meth:`repeat`).
    held : int, default 0
        The centre-of-mass degrees of freedom ``removed_dof`` counts as held
        (3 under a thermostat's ``fixcm``): one system's, not each body's, so a
        repeated system holds them once.
    """

    def __init__(self, removed_dof: int, molecule_ids=None, held: int = 0):
        self.removed_dof = int(removed_dof)
        self.body_ids = None if molecule_ids is None else np.array(molecule_ids)
        self.held = int(held)

    def get_removed_dof(self, atoms):
        if self.body_ids is not None and len(atoms) != len(self.body_ids):
            raise ValueError(
                f"RigidBodyDOF: these {len(atoms)} atoms are not the {len(self.body_ids)} a "
                "rigid dynamics marked (extended since?), so their rigid degrees of freedom "
                "are unknown; take the marker out (atoms.constraints = [c for c in "
                "atoms.constraints if not isinstance(c, rigidmd.RigidBodyDOF)]) or count "
                "with rigidmd.rigid_temperature(atoms, bodies=...)")
        return self.removed_dof

    def repeat(self, m, n):
        """The marker of ``atoms.repeat(m)`` (``n`` atoms repeated ``m = (m1, m2, m3)``
        times, as ASE's ``Atoms.repeat`` asks its constraints): each copy's bodies are
        bodies of their own, the held centre of mass the whole system's."""
        copies = int(np.prod(m))
        ids = None
        if self.body_ids is not None:
            if len(self.body_ids) != n:
                self.get_removed_dof(range(n))  # refused, in its words
            step = max(int(self.body_ids.max()), 0)
            ids = np.concatenate([np.where(self.body_ids > 0, self.body_ids + c * step,
                                           self.body_ids) for c in range(copies)])
        per_copy = self.removed_dof - self.held
        return type(self)(per_copy * copies + self.held, ids, self.held)

    def adjust_positions(self, atoms, new):
        pass

    def adjust_momenta(self, atoms, momenta):
        pass

    def adjust_forces(self, atoms, forces):
        pass

    def index_shuffle(self, atoms, ind):
        # A subset of atoms is no longer the same set of bodies: drop it.
        raise NotImplementedError

    def __deepcopy__(self, memo):
        # Every calculator call deep-copies the constraints (ASE's Atoms.copy of the
        # atoms it keeps): 3.9 us through copy's generic reduction, 1.5 us this way
        # (the list of one RigidBodyDOF for 216 bodies).
        return type(self)(self.removed_dof, self.body_ids, self.held)

    def __repr__(self):
        return f"RigidBodyDOF(removed_dof={self.removed_dof})"


def kinetic_energy(atoms: Atoms) -> float:
    r"""Kinetic energy of the atoms, :math:`\sum_i |p_i|^2 / 2 m_i` over atoms with mass (eV).

    ASE's :meth:`ase.Atoms.get_kinetic_energy` forms :math:`p/m`, which is
    0/0 (NaN) on a massless virtual site; a virtual site carries no kinetic
    energy, so it is left out here.
    """
    momenta, masses = atoms.get_momenta(), atoms.get_masses()
    massive = masses > 0
    if massive.all():  # ASE's own arithmetic, to the bit
        return float(0.5 * np.vdot(momenta, momenta / masses[:, None]))
    p = momenta[massive]
    return float(0.5 * np.vdot(p, p / masses[massive, None]))


def temperature(atoms: Atoms) -> float:
    """Temperature (K) as :meth:`ase.Atoms.get_temperature`, with :func:`kinetic_energy`.

    Degrees of freedom: 3 per atom less what the constraints remove (a
    :class:`RigidBodyDOF` leaves the rigid ones).
    """
    dof = 3 * len(atoms) - sum(c.get_removed_dof(atoms) for c in atoms.constraints)
    return 2.0 * kinetic_energy(atoms) / (dof * units.kB)
