r"""The time-invariant description of a system's rigid bodies.

A :class:`BodyModel` holds what never changes during a run: which atoms form
which body and in what order, masses, principal moments of inertia (and their
safe inverses), body-frame atom coordinates, the free atoms and the degrees of
freedom.  What a step changes (centres of mass, orientations, momenta, the
cell) lives in :class:`rigidmd.core.state.RigidState`.  :func:`measure` builds a
model from a partition of the atoms and one configuration, and returns that
configuration's centres of mass and orientations alongside.

Conventions (see also :mod:`rigidmd.core.quaternion`): atom :math:`i` of body
:math:`b` sits at :math:`x_i = X_b + R(q_b)\, d_i`, where :math:`X_b` is the
centre of mass and :math:`d_i` the body-frame coordinate.  The body frame is
the principal frame, so the inertia tensor there is
:math:`\mathrm{diag}(I_1, I_2, I_3)` with :math:`I_1 \le I_2 \le I_3`.  A
moment below ``LINEAR_TOLERANCE * max(I)`` is set to exactly 0 (a linear
body), the rule LAMMPS ``fix rigid`` uses.  The axes' signs, and their choice
within a plane or space of equal moments, are taken from the atoms
(:func:`principal_frames`), so a body measured again gets the same frame.

Atoms of mass 0 (virtual sites, such as the M site of TIP4P water) belong to
a body like any other atom: they are placed at :math:`X_b + R(q_b)\, d_i`
every step and the force on them enters the body's force and torque, but
they add nothing to its mass, inertia, momenta or degrees of freedom.
"""

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from rigidmd.core import quaternion as quat
from rigidmd.core._numba import pack_model

__all__ = ["BodyModel", "BodyGeometry", "LINEAR_TOLERANCE", "FRAME_TOLERANCE", "measure",
           "principal_frames", "inertia_tensors", "safe_inverse"]

#: Relative threshold below which a principal moment counts as zero.
LINEAR_TOLERANCE = 1e-7


def safe_inverse(moments):
    r""":math:`1/I` componentwise, 0 where :math:`I = 0` (the axis of a linear body).

    Parameters
    ----------
    moments : numpy.ndarray, shape (..., 3)
        Principal moments (amu Å²).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        amu⁻¹ Å⁻².
    """
    moments = np.asarray(moments, dtype=float)
    positive = moments > 0
    return np.where(positive, 1.0 / np.where(positive, moments, 1.0), 0.0)


def describe_atoms(indices, limit=6):
    """``"[i, j, ...]"``: a short list of atom indices for messages."""
    indices = [int(i) for i in indices]
    text = ", ".join(str(i) for i in indices[:limit])
    return f"[{text}{', ...' if len(indices) > limit else ''}]"


@dataclass(frozen=True, eq=False)
class BodyModel:
    """What never changes during a run: the bodies' make-up and inertia.

    Body atoms are stored grouped by body: ``order[bounds[b]:bounds[b + 1]]``
    are the atom indices of body ``b``.

    Attributes
    ----------
    n_atoms : int
        Number of atoms in the system.
    order : numpy.ndarray of int, shape (n_body_atoms,)
        Atom index of each body atom, grouped by body.
    starts : numpy.ndarray of int, shape (n_bodies,)
        Offset of each body's first atom in ``order``.
    atom_body : numpy.ndarray of int, shape (n_body_atoms,)
        Body of each entry of ``order``.
    atom_masses : numpy.ndarray, shape (n_body_atoms,)
        Masses of the body atoms (amu), in ``order``.
    mass : numpy.ndarray, shape (n_bodies,)
        Body masses (amu).
    moments : numpy.ndarray, shape (n_bodies, 3)
        Principal moments of inertia, ascending (amu Å²); 0 marks the axis of
        a linear body.
    body_coordinates : numpy.ndarray, shape (n_body_atoms, 3)
        Body-frame coordinates :math:`d_i` (Å), in ``order``.
    free : numpy.ndarray of int, shape (n_free,)
        Indices of the atoms that move as point particles.
    free_masses : numpy.ndarray, shape (n_free,)
        Their masses (amu).
    bounds : numpy.ndarray of int, shape (n_bodies + 1,)
        ``starts`` with ``len(order)`` appended.
    inv_mass : numpy.ndarray, shape (n_bodies,)
        :math:`1/M` (amu⁻¹).
    inv_moments : numpy.ndarray, shape (n_bodies, 3)
        :math:`1/I_k`, 0 about a zero-moment axis (:func:`safe_inverse`).
    linear : numpy.ndarray of bool, shape (n_bodies,)
        Bodies with one zero moment.
    radius : float
        The largest distance of a body atom from its centre of mass (Å), 0
        without bodies: no body is wider than twice this in any direction.
    packed : tuple of numpy.ndarray
        The model as the fused kernel takes it (:func:`rigidmd.core._numba.pack_model`).

    One model serves every part of a dynamics (link, record, evaluator, step
    context, coupling view): they hold the same object, and a restore
    replaces its contents in place (:meth:`update_from`), so none can keep
    an old model.
    """

    #: The fields a checkpoint stores (the others are derived from them).
    STORED: ClassVar[tuple] = ("order", "starts", "atom_body", "atom_masses", "mass", "moments",
                               "body_coordinates", "free", "free_masses")

    n_atoms: int
    order: np.ndarray
    starts: np.ndarray
    atom_body: np.ndarray
    atom_masses: np.ndarray
    mass: np.ndarray
    moments: np.ndarray
    body_coordinates: np.ndarray
    free: np.ndarray
    free_masses: np.ndarray
    bounds: np.ndarray = field(init=False, repr=False)
    inv_mass: np.ndarray = field(init=False, repr=False)
    inv_moments: np.ndarray = field(init=False, repr=False)
    linear: np.ndarray = field(init=False, repr=False)
    radius: float = field(init=False, repr=False)
    packed: tuple = field(init=False, repr=False)

    def __post_init__(self):
        derived = {
            "bounds": np.append(self.starts, len(self.order)).astype(np.int64),
            "inv_mass": 1.0 / self.mass if len(self.mass) else np.zeros(0),
            "inv_moments": safe_inverse(self.moments),
            "linear": self.moments[:, 0] == 0.0,
        }
        for name, value in derived.items():
            object.__setattr__(self, name, value)
        for name in ("order", "starts", "atom_body", "atom_masses", "mass", "moments",
                     "body_coordinates", "free", "free_masses", *derived):
            getattr(self, name).flags.writeable = False
        coordinates = self.body_coordinates
        object.__setattr__(self, "radius", float(np.sqrt(np.max(np.sum(
            coordinates * coordinates, axis=1)))) if len(coordinates) else 0.0)
        object.__setattr__(self, "packed", pack_model(
            self.inv_mass, self.inv_moments, self.body_coordinates, self.atom_masses,
            self.bounds, self.order))

    def update_from(self, other: "BodyModel") -> None:
        """Take every field of ``other`` (a checkpoint's model of the same atoms), in place.

        Every holder of this model sees the new one at once.  Refuses a model
        of another number of atoms, bodies or free atoms (ValueError), before
        changing anything.
        """
        if (other.n_atoms, other.n_bodies, other.n_free) != (self.n_atoms, self.n_bodies,
                                                             self.n_free):
            raise ValueError(f"the stored body model has {other.n_atoms} atoms, "
                             f"{other.n_bodies} bodies and {other.n_free} free atoms; these "
                             f"atoms have {self.n_atoms}, {self.n_bodies} and {self.n_free}")
        for name in self.__dataclass_fields__:
            object.__setattr__(self, name, getattr(other, name))

    @property
    def n_bodies(self):
        """Number of rigid bodies."""
        return len(self.mass)

    @property
    def n_free(self):
        """Number of point particles (atoms in no body)."""
        return len(self.free)

    @property
    def translational_dof(self):
        """Centre-of-mass and point-particle degrees of freedom: 3 each."""
        return 3 * (self.n_bodies + self.n_free)

    @property
    def rotational_dof(self):
        """Rotational degrees of freedom: 3 per body, 2 per linear body."""
        return int(np.count_nonzero(self.moments))

    @property
    def degrees_of_freedom(self):
        """All degrees of freedom: 6 per body, 5 per linear body, 3 per point particle.

        No centre-of-mass correction (as everywhere in ASE; LAMMPS subtracts 3).
        """
        return self.translational_dof + self.rotational_dof

    def atoms_of(self, b):
        """Atom indices of body ``b``."""
        return self.order[self.bounds[b]:self.bounds[b + 1]]


@dataclass(frozen=True, eq=False)
class BodyGeometry:
    """A :class:`BodyModel` and the pose of its bodies in one configuration.

    Attributes
    ----------
    model : BodyModel
    com : numpy.ndarray, shape (n_bodies, 3)
        Centres of mass (Å), from unwrapped atom positions.
    quaternions : numpy.ndarray, shape (n_bodies, 4)
        Orientations ``(w, x, y, z)``: ``R(q)`` maps body to lab frame.
    """

    model: BodyModel
    com: np.ndarray
    quaternions: np.ndarray


def inertia_tensors(r, m, starts):
    r"""Inertia tensors :math:`\sum_i m_i (|r_i|^2 \mathbb{1} - r_i r_i^\mathsf{T})`.

    Parameters
    ----------
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Positions relative to each body's centre of mass (Å), grouped by body.
    m : numpy.ndarray, shape (n_body_atoms,)
        Atom masses (amu).
    starts : numpy.ndarray of int, shape (n_bodies,)

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3, 3)
        amu Å².
    """
    outer = m[:, None, None] * r[:, :, None] * r[:, None, :]
    sq = np.trace(outer, axis1=1, axis2=2)
    per_atom = sq[:, None, None] * np.eye(3) - outer
    return np.add.reduceat(per_atom, starts, axis=0)


#: Relative length below which an atom counts as lying on a plane or axis of its
#: body when the frame's signs are taken from the atoms (of the body's largest
#: atom distance from its centre of mass).
FRAME_TOLERANCE = 1e-6


def _first_atom(mask, starts):
    """Per body, the index of its first atom where ``mask`` holds, ``len(mask)`` if none."""
    index = np.where(mask, np.arange(len(mask)), len(mask))
    return np.minimum.reduceat(index, starts)


def _unit(v):
    """``v`` normalised along its last axis (a zero vector stays zero)."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def _from_atoms(vectors, eps, starts, fallback):
    """Per body, the direction of its first atom vector longer than ``eps``, else ``fallback``."""
    first = _first_atom(np.linalg.norm(vectors, axis=1) > eps, starts)
    found = first < len(vectors)
    picked = _unit(vectors[np.minimum(first, len(vectors) - 1)])
    return np.where(found[:, None], picked, fallback), found


def _signed(axis, r, eps, starts, atom_body):
    """``axis`` (per body) turned so that its body's first atom off the plane normal to it
    has a positive coordinate along it; unchanged where every atom lies in that plane."""
    d = np.einsum("ni,ni->n", r, axis[atom_body])
    first = _first_atom(np.abs(d) > eps, starts)
    found = first < len(d)
    sign = np.where(found & (d[np.minimum(first, len(d) - 1)] < 0), -1.0, 1.0)
    return axis * sign[:, None], found


def _in_plane(r, normal, atom_body):
    """Each atom vector with its component along its body's ``normal`` removed."""
    n = normal[atom_body]
    return r - np.einsum("ni,ni->n", r, n)[:, None] * n


def principal_frames(r, m, starts, atom_body):
    r"""Principal moments and right-handed principal axes, taken from the atoms.

    LAPACK's eigenvectors are defined only up to the sign of each axis, and
    only up to a rotation within the plane (or space) of equal moments; which
    one it returns depends on the last bits of the tensor, so the same body
    measured twice (rigidly moved, or on another machine) could get another
    frame.  Here each choice is made by the atoms, in their order:

    * a principal axis of its own moment points so that the first atom off
      the plane normal to it has a positive coordinate along it;
    * two equal moments (a symmetric top, a linear body) are an eigenplane:
      its first axis points to the first atom off the unique axis; the second
      follows from the right hand, or, when every atom lies in the plane (a
      planar oblate top), from the first atom off the first axis;
    * three equal moments (a spherical top): the first axis points to the
      first atom off the centre of mass, the second to the first atom off
      that axis;
    * the remaining axis completes a right-handed frame; a linear body, whose
      atoms fix no direction across its axis, takes the lab axis least
      aligned with its own.  Its frame therefore turns with the lab, not
      with the body: a whole system rotated in the lab gives its linear bodies
      other axes across their own, and NO_SQUISH's free-rotor splitting
      (rotations about the two axes in turn) is not invariant under that
      choice, so such a rotated run differs from the original by the
      integrator's own O(dt²) error (4 CO₂, 300 fs at 1 fs: 1e-6 Å; a fourth
      of it at each halving of the step), where other bodies agree to roundoff.

    Moments within ``LINEAR_TOLERANCE`` of the largest of each other count
    as equal and are replaced by their mean, so the frame chosen in their
    eigenspace diagonalises the inertia tensor to that tolerance.

    Parameters
    ----------
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Atom positions relative to their body's centre of mass (Å), grouped by body.
    m : numpy.ndarray, shape (n_body_atoms,)
        Atom masses (amu).
    starts, atom_body : numpy.ndarray of int
        Body layout, as in :class:`BodyModel`.

    Returns
    -------
    moments : numpy.ndarray, shape (n_bodies, 3)
        Ascending principal moments (amu Å²).
    axes : numpy.ndarray, shape (n_bodies, 3, 3)
        Rotation matrices whose columns are the principal axes (determinant +1).
    """
    moments, eig = np.linalg.eigh(inertia_tensors(r, m, starts))
    tol = LINEAR_TOLERANCE * moments[:, 2]
    low = moments[:, 1] - moments[:, 0] <= tol     # I1 = I2
    high = moments[:, 2] - moments[:, 1] <= tol    # I2 = I3 (a linear body too)
    sphere, oblate, prolate = low & high, low & ~high, high & ~low
    size = np.sqrt(np.maximum.reduceat(np.einsum("ni,ni->n", r, r), starts))
    eps = (FRAME_TOLERANCE * size)[atom_body]
    out = eig.copy()

    # An axis of its own moment: its sign from the atoms.
    a0, _ = _signed(eig[:, :, 0], r, eps, starts, atom_body)
    a1, _ = _signed(eig[:, :, 1], r, eps, starts, atom_body)
    a2, a2_found = _signed(eig[:, :, 2], r, eps, starts, atom_body)
    out[:, :, 0], out[:, :, 1] = a0, a1
    out[:, :, 2] = np.cross(a0, a1)

    # I2 = I3 (prolate top, linear body): the unique axis a0, the plane's first axis
    # towards the first atom off a0 (a linear body: the lab axis least along a0).
    lab = np.eye(3)[np.argmin(np.abs(a0), axis=1)]
    across = _unit(lab - np.einsum("ni,ni->n", lab, a0)[:, None] * a0)
    e1, _ = _from_atoms(_in_plane(r, a0, atom_body), eps, starts, across)
    frame = np.stack([a0, e1, np.cross(a0, e1)], axis=2)
    out[prolate] = frame[prolate]

    # I1 = I2 (oblate top): the unique axis a2, the plane's first axis towards the first
    # atom off a2; the second from the right hand, or, a planar top, from its atoms.
    planar = ~a2_found
    flat = _in_plane(r, a2, atom_body)
    e0, _ = _from_atoms(flat, eps, starts, eig[:, :, 0])
    e1 = np.cross(a2, e0)
    e1_atoms, _ = _from_atoms(_in_plane(flat, e0, atom_body), eps, starts, e1)
    e1 = np.where(planar[:, None], e1_atoms, e1)
    frame = np.stack([e0, e1, np.cross(e0, e1)], axis=2)
    out[oblate] = frame[oblate]

    # I1 = I2 = I3: the first atom off the centre, then the first atom off that axis.
    e0, _ = _from_atoms(r, eps, starts, eig[:, :, 0])
    e1, _ = _from_atoms(_in_plane(r, e0, atom_body), eps, starts, eig[:, :, 1])
    frame = np.stack([e0, e1, np.cross(e0, e1)], axis=2)
    out[sphere] = frame[sphere]

    moments = moments.copy()
    mean01 = 0.5 * (moments[:, 0] + moments[:, 1])
    mean12 = 0.5 * (moments[:, 1] + moments[:, 2])
    mean = moments.mean(axis=1)
    moments[oblate, :2] = mean01[oblate, None]
    moments[prolate, 1:] = mean12[prolate, None]
    moments[sphere] = mean[sphere, None]
    return moments, out


def _refuse_off_axis_sites(d, m, moments, mass, order, atom_body):
    """Refuse an atom off the axis of a linear body.

    A linear body has no orientation about its axis (no moment there), so an
    atom off the axis would have no defined place and the axial part of its
    torque would be dropped.  A body is linear when its smallest moment is
    below ``LINEAR_TOLERANCE`` of its largest, which a massless site, or an
    atom of tiny mass, far from the axis does not prevent; so every atom is
    checked by distance.  "Off" uses the same tolerance: a squared distance
    from the axis above ``LINEAR_TOLERANCE`` times the body's largest moment
    per unit mass (3e-4 Å for CO2).
    """
    linear = moments[:, 0] == 0.0
    if not np.any(linear):
        return
    scale = LINEAR_TOLERANCE * moments[:, 2] / mass
    off = linear[atom_body] & (d[:, 1] ** 2 + d[:, 2] ** 2 > scale[atom_body])
    if np.any(off):
        i = int(np.flatnonzero(off)[0])
        b = int(atom_body[i])
        what = "massless" if m[i] == 0 else f"of mass {m[i]:.3g} amu"
        raise ValueError(
            f"atom {int(order[i])} is {what} and {np.hypot(d[i, 1], d[i, 2]):.3g} Å off the "
            f"axis of the linear body {b} (atoms {describe_atoms(order[atom_body == b])}): "
            "a linear body has no orientation about its axis to carry it"
        )


def measure(order, starts, atom_body, free, masses, x):
    """Build the model of given bodies from one configuration.

    Parameters
    ----------
    order, starts, atom_body : numpy.ndarray of int
        Body layout, as in :class:`BodyModel`.
    free : numpy.ndarray of int, shape (n_free,)
        Indices of the free atoms.
    masses : numpy.ndarray, shape (n_atoms,)
        Atom masses (amu), already checked finite, positive or 0 in a body
        (:func:`rigidmd.core.bodies.check_masses`).
    x : numpy.ndarray, shape (n_body_atoms, 3)
        Unwrapped positions of the body atoms (Å), in ``order``.

    Returns
    -------
    BodyGeometry

    Raises
    ------
    ValueError
        A body whose mass sits at one point (it has no orientation); a
        massless atom off the axis of a linear body.
    """
    m = masses[order]
    n_bodies = len(starts)
    if n_bodies == 0:
        model = BodyModel(
            n_atoms=len(masses), order=order, starts=starts, atom_body=atom_body,
            atom_masses=m, mass=np.zeros(0), moments=np.zeros((0, 3)),
            body_coordinates=np.zeros((0, 3)), free=free, free_masses=masses[free])
        return BodyGeometry(model, np.zeros((0, 3)), np.zeros((0, 4)))
    mass = np.add.reduceat(m, starts)
    com = np.add.reduceat(m[:, None] * x, starts) / mass[:, None]
    r = x - com[atom_body]
    moments, axes = principal_frames(r, m, starts, atom_body)
    imax = moments[:, 2]
    point = ~(imax > 0)
    if np.any(point):
        b = int(np.flatnonzero(point)[0])
        raise ValueError(
            f"body {b} (atoms {describe_atoms(order[atom_body == b])}) has all its "
            "mass at one point: it has no orientation"
        )
    moments = np.where(moments < LINEAR_TOLERANCE * imax[:, None], 0.0, moments)
    d = np.einsum("nji,nj->ni", axes[atom_body], r)
    _refuse_off_axis_sites(d, m, moments, mass, order, atom_body)
    model = BodyModel(
        n_atoms=len(masses), order=order, starts=starts, atom_body=atom_body, atom_masses=m,
        mass=mass, moments=moments, body_coordinates=d, free=free, free_masses=masses[free])
    return BodyGeometry(model, com, quat.from_matrix(axes))
