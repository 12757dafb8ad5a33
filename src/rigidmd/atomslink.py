"""What a rigid dynamics checks in, and marks on, its :class:`ase.Atoms`.

The degree-of-freedom marker ASE's temperature reads, the bodies written into
the tags, one-call evaluation of several calculator properties, and the
checks of positions and momenta that run before any state changes.
"""

import warnings

import numpy as np
from ase import units

from rigidmd.bodies import RigidBodies

__all__ = ["RigidBodyDOF", "check_finite", "check_massless_momenta", "calculate_together",
           "store_bodies_in_tags", "kinetic_energy", "temperature"]


class RigidBodyDOF:
    """Marks rigid bodies for ASE's degree-of-freedom count.

    A rigid dynamics puts one of these in ``atoms.constraints`` so that
    :meth:`ase.Atoms.get_temperature` and :class:`ase.md.MDLogger` count 6
    degrees of freedom per body (5 per linear body) and 3 per point particle.
    It never changes positions, momenta or forces.  It has no ``todict``, so
    trajectory writers skip it and ``.traj`` files stay readable by plain
    :func:`ase.io.read`.

    Parameters
    ----------
    removed_dof : int
        ``3 * len(atoms)`` minus the rigid degrees of freedom.
    body_ids : array_like of int, shape (n_atoms,), optional
        Each atom's body (-1: none), for calculators that need molecules
        (:class:`rigidmd.lammps.LAMMPSCalculator` excludes pairs within one).
    """

    def __init__(self, removed_dof, body_ids=None):
        self.removed_dof = int(removed_dof)
        self.body_ids = None if body_ids is None else np.array(body_ids) + 1

    def get_removed_dof(self, atoms):
        return self.removed_dof

    def adjust_positions(self, atoms, new):
        pass

    def adjust_momenta(self, atoms, momenta):
        pass

    def adjust_forces(self, atoms, forces):
        pass

    def index_shuffle(self, atoms, ind):
        # A subset of atoms is no longer the same set of bodies: drop it.
        raise NotImplementedError

    def __repr__(self):
        return f"RigidBodyDOF(removed_dof={self.removed_dof})"


def calculate_together(calc, atoms, names):
    """Have an ASE calculator compute several properties in one call.

    What :meth:`ase.calculators.calculator.BaseCalculator.get_property` does
    for one property, for several: a calculator asked for forces and later
    for the energy or stress of the same positions would otherwise be called
    twice (and LAMMPS, for one, would evaluate the forces twice).
    Calculators without ASE's ``calculate``/``check_state`` are left alone
    (their properties are then asked one by one).
    """
    if not (hasattr(calc, "calculate") and hasattr(calc, "check_state")):
        return
    names = [name for name in names if name in getattr(calc, "implemented_properties", names)]
    changes = calc.check_state(atoms)
    if changes:
        calc.atoms = None
        calc.results = {}
    missing = [name for name in names if name not in calc.results]
    if missing:
        if getattr(calc, "use_cache", True):
            calc.atoms = atoms.copy()
        calc.calculate(atoms, missing, changes)


def check_finite(values, quantity, unit, when=""):
    """Raise a ValueError naming the first atom whose ``quantity`` is NaN or infinite.

    One reduction when everything is finite (a NaN or an infinity anywhere
    makes the sum non-finite).
    """
    values = np.asarray(values, dtype=float)
    if np.isfinite(values.sum()):
        return
    bad = np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))
    what = "cell vector" if quantity == "cell" else "atom"
    raise ValueError(f"{what} {int(bad[0])} has a non-finite {quantity} "
                     f"{values[bad[0]].tolist()} ({unit}){' ' + when if when else ''}"
                     f"{f'; {len(bad)} in all' if len(bad) > 1 else ''}")


def check_massless_momenta(atoms, when=""):
    """Refuse a momentum on an atom of mass 0: a virtual site only moves with its body.

    ASE's velocity tools (``MaxwellBoltzmannDistribution``, ``Stationary``,
    ``set_velocities``) give such atoms zero momentum; a non-zero one was set
    by hand and has no rigid-body meaning, so it is refused, not dropped.
    """
    masses = atoms.get_masses()
    if np.all(masses > 0):
        return
    momenta = atoms.get_momenta()
    bad = np.flatnonzero((masses == 0) & np.any(momenta != 0, axis=1))
    if bad.size:
        a = int(bad[0])
        raise ValueError(
            f"atom {a} ({atoms[a].symbol}) has mass 0 but momentum {momenta[a].tolist()} "
            f"(amu Å / ASE time){' ' + when if when else ''}: a massless atom (a virtual site) "
            "moves with its body; give it zero momentum")


def same_partition(a, b):
    """Whether two labellings of the atoms group them the same way (labels may differ)."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def store_bodies_in_tags(atoms, body_ids):
    """Tags = body index + 1 (-1 for free atoms): every ``.traj`` frame carries the bodies.

    Body ``b`` gets tag ``b + 1``, the molecule ID LAMMPS data files and
    :class:`rigidmd.lammps.LAMMPSCalculator` use (which read IDs <= 0 as "no
    molecule").

    ASE's trajectory files keep tags but drop custom arrays such as
    ``mol-id``; ``bodies=None`` (or ``"tags"``) on a frame read back then finds
    the same bodies.  Tags that already group the atoms as the bodies do are
    kept; other non-zero tags are kept too, with a warning.
    """
    def distinct(ids):  # free atoms (negative) each in a group of their own
        return np.where(ids < 0, -1 - np.arange(len(ids)), ids)

    tags = atoms.get_tags()
    if same_partition(distinct(RigidBodies.from_tags(atoms).body_ids), distinct(body_ids)):
        return
    if np.any(tags != 0):
        warnings.warn("the atoms' tags group them differently from the rigid bodies; "
                      "rigidmd keeps the tags, so trajectory frames do not carry the bodies "
                      "(give bodies=... when reading them back)", stacklevel=4)
        return
    atoms.set_tags(np.where(body_ids >= 0, body_ids + 1, -1))


def kinetic_energy(atoms):
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


def temperature(atoms):
    """Temperature (K) as :meth:`ase.Atoms.get_temperature`, with :func:`kinetic_energy`.

    Degrees of freedom: 3 per atom less what the constraints remove (a
    :class:`RigidBodyDOF` leaves the rigid ones).
    """
    dof = 3 * len(atoms) - sum(c.get_removed_dof(atoms) for c in atoms.constraints)
    return 2.0 * kinetic_energy(atoms) / (dof * units.kB)
