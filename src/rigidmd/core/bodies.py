r"""Which atoms form which rigid body, and making periodic bodies whole.

A :class:`RigidBodies` object partitions the atoms of a system: every atom
belongs to at most one body.  Atoms in no body, and bodies of a single atom,
move as point particles.  :meth:`RigidBodies.geometry` then measures, for a
configuration, the time-invariant :class:`~rigidmd.core.model.BodyModel` (masses,
principal moments and axes, body-frame coordinates) and each body's centre of
mass and orientation (see :mod:`rigidmd.core.model` for the conventions).
"""

import warnings

import numpy as np

from rigidmd.core.model import LINEAR_TOLERANCE, BodyGeometry, describe_atoms, measure
from rigidmd.core.neighbours import tree_pairs

__all__ = ["RigidBodies", "BodyGeometry", "LINEAR_TOLERANCE", "unwrap_bodies", "cell_widths"]

_RULES = ("mol-id", "tags", "connectivity")


class RigidBodies:
    """A partition of a system's atoms into rigid bodies.

    Build one with a classmethod that names the rule (:meth:`from_mol_id`,
    :meth:`from_tags`, :meth:`from_body_ids`, :meth:`from_index_lists`,
    :meth:`from_connectivity`) or let :meth:`resolve` pick the rule from a
    specification.  The rule used is kept in :attr:`rule`.

    Parameters
    ----------
    body_ids : array_like of int, shape (n_atoms,)
        Body label of every atom.  Atoms sharing a label ``>= 0`` form one
        body; a negative label marks an atom that belongs to no body.  Labels
        need not be contiguous.  A label held by a single atom makes that atom
        a point particle.
    rule : str
        Human-readable name of the rule that produced the labels.

    Attributes
    ----------
    body_ids : numpy.ndarray of int, shape (n_atoms,)
        Normalised labels: bodies of two or more atoms are numbered
        ``0 .. n_bodies - 1`` in order of their smallest original label; point
        particles are ``-1``.
    n_bodies : int
        Number of bodies with two or more atoms.
    rule : str
    """

    def __init__(self, body_ids, rule="body-ids"):
        ids = np.asarray(body_ids)
        if ids.ndim != 1:
            raise ValueError(f"body ids must be one-dimensional, got shape {ids.shape}")
        if ids.size and not np.issubdtype(ids.dtype, np.integer):
            if np.issubdtype(ids.dtype, np.floating) and np.all(ids == np.round(ids)):
                ids = ids.astype(np.int64)
            else:
                raise TypeError(
                    f"body ids must be integers, got dtype {ids.dtype}"
                )
        ids = ids.astype(np.int64)
        labels, inverse, counts = np.unique(
            np.where(ids < 0, -1, ids), return_inverse=True, return_counts=True
        )
        keep = (labels >= 0) & (counts >= 2)
        new_label = np.full(len(labels), -1, dtype=np.int64)
        new_label[keep] = np.arange(int(keep.sum()))
        self.body_ids = new_label[inverse] if ids.size else ids
        self.n_bodies = int(keep.sum())
        self.rule = rule

    # ------------------------------------------------------------ builders
    @classmethod
    def from_body_ids(cls, body_ids, natoms=None):
        """One label per atom; negative labels are atoms in no body.

        Parameters
        ----------
        body_ids : array_like of int, shape (n_atoms,)
        natoms : int, optional
            Expected number of atoms; a mismatch raises ``ValueError``.
        """
        ids = np.asarray(body_ids)
        if natoms is not None and ids.shape != (natoms,):
            raise ValueError(
                f"bodies: expected one body id per atom ({natoms}), got shape {ids.shape}"
            )
        return cls(ids, rule="body-ids")

    @classmethod
    def from_index_lists(cls, lists, natoms):
        """Each list holds the atom indices of one body; unlisted atoms are free.

        Raises ``ValueError`` for an empty list, an index out of range, or an
        atom listed in two bodies.
        """
        ids = np.full(natoms, -1, dtype=np.int64)
        for b, members in enumerate(lists):
            members = np.asarray(members)
            if members.ndim != 1 or members.size == 0:
                raise ValueError(f"bodies: body {b} is empty or not a flat list of indices")
            if not np.issubdtype(members.dtype, np.integer):
                raise TypeError(
                    f"bodies: body {b} holds non-integer indices ({members.dtype})"
                )
            bad = members[(members < 0) | (members >= natoms)]
            if bad.size:
                raise ValueError(
                    f"bodies: body {b} names atom {int(bad[0])}, "
                    f"but there are only {natoms} atoms"
                )
            uniq, cnt = np.unique(members, return_counts=True)
            if np.any(cnt > 1):
                raise ValueError(
                    f"bodies: body {b} lists atom {int(uniq[cnt > 1][0])} twice"
                )
            taken = members[ids[members] >= 0]
            if taken.size:
                a = int(taken[0])
                raise ValueError(
                    f"bodies: atom {a} is in both body {int(ids[a])} and body {b}"
                )
            ids[members] = b
        return cls(ids, rule="index-lists")

    @classmethod
    def from_mol_id(cls, atoms):
        """Atoms with the same ``mol-id`` (as ASE's ``lammps-data`` reader sets) form a body."""
        if "mol-id" not in atoms.arrays:
            raise ValueError(
                "bodies='mol-id' but the atoms have no 'mol-id' array "
                "(read a LAMMPS data file with atom_style full/molecular, or set it)"
            )
        return cls(atoms.arrays["mol-id"], rule="mol-id")

    @classmethod
    def from_tags(cls, atoms):
        """Atoms with the same tag form a body; negative tags are free atoms."""
        return cls(atoms.get_tags(), rule="tags")

    @classmethod
    def from_connectivity(cls, atoms, mult=1.0):
        """Covalently connected atoms form a body.

        Two atoms are bonded when their distance (minimum image in periodic
        directions) is below the sum of their natural cutoffs
        (:func:`ase.neighborlist.natural_cutoffs`, covalent radii times
        ``mult``).  Each connected component is a body; isolated atoms are
        point particles.
        """
        from ase.data import covalent_radii
        from scipy import sparse
        from scipy.sparse.csgraph import connected_components

        n = len(atoms)
        if n == 0:
            return cls(np.zeros(0, dtype=np.int64), rule="connectivity")
        # ASE's natural_cutoffs and NeighborList, whose skin (0.3 Å) is added to every radius:
        # bonded below r_i + r_j + 0.6 Å.
        radii = mult * covalent_radii[atoms.numbers] + 0.3
        i, j = _close_pairs(atoms, radii)
        graph = sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        return cls(labels, rule="connectivity")

    def warn_merged(self, atoms, unique_formulas=False):
        """Warn when connectivity probably joined or split molecules (:func:`warn_merged`)."""
        warn_merged(self, atoms, unique_formulas)

    def warn_unbonded(self, atoms):
        """Warn when a body holds atoms that no chain of covalent bonds joins.

        Used for the default rule: ASE fills a missing ``mol-id`` with 0 when
        Atoms are added together, so appended ions would silently become one
        body.  Bonds are ASE's natural cutoffs (minimum image).
        """
        if self.n_bodies == 0:
            return
        piece = RigidBodies.from_connectivity(atoms).body_ids
        piece = np.where(piece < 0, -1 - np.arange(len(piece)), piece)
        inside = self.body_ids >= 0
        pairs = np.unique(np.stack([self.body_ids[inside], piece[inside]], axis=1), axis=0)
        pieces = np.bincount(pairs[:, 0], minlength=self.n_bodies)
        if pieces.max() > 1:
            b = int(np.argmax(pieces > 1))
            warnings.warn(
                f"bodies by {self.rule} (the default rule): body {b} "
                f"(atoms {describe_atoms(self.atoms_of(b))}) falls into {int(pieces[b])} "
                "pieces that no covalent bond joins (ASE fills a missing mol-id with 0 when "
                "Atoms are added); give the bodies explicitly (bodies='mol-id', 'tags', "
                "'connectivity' or a list) if that is wrong",
                stacklevel=4,
            )

    @classmethod
    def resolve(cls, atoms, spec=None):
        """Turn a user specification into a :class:`RigidBodies`.

        Parameters
        ----------
        atoms : ase.Atoms
        spec : None, str, RigidBodies, array_like of int, or list of lists
            ``None`` uses the ``mol-id`` array when the atoms have one (what
            ASE's ``lammps-data`` reader sets), else the tags when they are not
            all equal (what rigidmd stores in every trajectory frame), else
            covalent connectivity, with a warning when that probably joined
            or split molecules; ``"mol-id"``, ``"tags"`` or
            ``"connectivity"`` name a rule; a :class:`RigidBodies` is used as
            is; a flat integer sequence of length ``len(atoms)`` gives a body
            id per atom; a sequence of sequences gives the atom indices of
            each body.
        """
        n = len(atoms)
        if spec is None:
            tags = atoms.get_tags()
            if "mol-id" in atoms.arrays:
                bodies = cls.from_mol_id(atoms)
                bodies.warn_unbonded(atoms)
            elif n and np.any(tags != tags[0]):
                bodies = cls.from_tags(atoms)
                bodies.warn_unbonded(atoms)
            else:
                bodies = cls.from_connectivity(atoms)
                bodies.warn_merged(atoms, unique_formulas=True)
        elif isinstance(spec, str) and spec == "connectivity":
            bodies = cls.from_connectivity(atoms)
            bodies.warn_merged(atoms)
        elif isinstance(spec, RigidBodies):
            bodies = spec
        elif isinstance(spec, str):
            if spec == "mol-id":
                bodies = cls.from_mol_id(atoms)
            elif spec == "tags":
                tags = atoms.get_tags()
                if len(tags) > 1 and not np.any(tags):  # asked for: ASE's default, no tags
                    raise ValueError(
                        f"bodies='tags' but every atom has tag 0 (no tags set), which would "
                        f"make all {len(tags)} atoms one rigid body; set one tag per "
                        "molecule, or use bodies='connectivity'")
                bodies = cls.from_tags(atoms)
            else:
                raise ValueError(
                    f"bodies: unknown rule {spec!r}; expected one of {', '.join(_RULES)}, "
                    "a per-atom body-id array or a list of index lists"
                )
        elif hasattr(spec, "__len__") and len(spec) == 0:
            bodies = cls.from_index_lists([], n)  # an empty list of bodies: every atom free
        else:
            try:
                arr = np.asarray(spec)
                ragged = False
            except ValueError:
                ragged = True
            if not ragged and arr.ndim == 1 and arr.dtype != object:
                bodies = cls.from_body_ids(arr, natoms=n)
                if n > 1 and np.array_equal(arr, np.arange(n)):
                    # one atom per body, each its own index: the index list of one body?
                    warnings.warn(f"bodies: [0, 1, ..., {n - 1}] is read as one body id per "
                                  f"atom, {n} single-atom bodies (free atoms); for one body "
                                  f"of these atoms give [[0, 1, ..., {n - 1}]]", stacklevel=3)
            elif not ragged and arr.ndim == 2 and arr.dtype != object:
                bodies = cls.from_index_lists(list(arr), n)
            else:
                bodies = cls.from_index_lists(list(spec), n)
        if len(bodies.body_ids) != n:
            raise ValueError(
                f"bodies: the definition covers {len(bodies.body_ids)} atoms, "
                f"the system has {n}"
            )
        return bodies

    # ------------------------------------------------------------ indexing
    @property
    def free_indices(self):
        """Indices of the atoms that move as point particles, shape (n_free,)."""
        return np.flatnonzero(self.body_ids < 0)

    @property
    def body_atom_order(self):
        """Atom indices of all body atoms, grouped by body (stable), shape (n_body_atoms,)."""
        members = np.flatnonzero(self.body_ids >= 0)
        return members[np.argsort(self.body_ids[members], kind="stable")]

    def atoms_of(self, b):
        """Atom indices of body ``b``."""
        return np.flatnonzero(self.body_ids == b)

    def __len__(self):
        return self.n_bodies

    def __repr__(self):
        return (
            f"RigidBodies(n_bodies={self.n_bodies}, n_free={len(self.free_indices)}, "
            f"rule={self.rule!r})"
        )

    # ------------------------------------------------------------ geometry
    def _layout(self):
        order = self.body_atom_order
        counts = np.bincount(self.body_ids[order], minlength=self.n_bodies)
        starts = (np.cumsum(counts) - counts).astype(np.int64)
        return order, starts, np.repeat(np.arange(self.n_bodies), counts)

    def whole_positions(self, atoms):
        """Atom positions with every body made whole (minimum image from its first atom).

        Free atoms keep their positions.  See :func:`unwrap_bodies`.

        Returns
        -------
        numpy.ndarray, shape (n_atoms, 3)
            Å.
        """
        order, starts, atom_body = self._layout()
        positions = atoms.positions.copy()
        positions[order] = unwrap_bodies(atoms, order, starts, atom_body)
        return positions

    def geometry(self, atoms):
        """Measure every body in the configuration of ``atoms``.

        Molecules split across a periodic boundary are made whole by taking
        each atom at its minimum image from the body's first atom.

        Parameters
        ----------
        atoms : ase.Atoms

        Returns
        -------
        rigidmd.core.model.BodyGeometry
            The :class:`~rigidmd.core.model.BodyModel` and the bodies' centres of
            mass and orientations in this configuration.

        Raises
        ------
        ValueError
            An atom with negative or non-finite mass, or massless outside a
            body; a body without mass, or whose mass sits at one point, or a
            linear body with a massless atom off its axis (see
            :func:`check_masses`); a body larger than half the cell in a
            periodic direction.
        """
        if len(atoms) != len(self.body_ids):
            raise ValueError(
                f"bodies cover {len(self.body_ids)} atoms, the system has {len(atoms)}"
            )
        masses = atoms.get_masses()
        order, starts, atom_body = self._layout()
        check_masses(masses, atoms.get_chemical_symbols(), self.free_indices, order, starts)
        x = unwrap_bodies(atoms, order, starts, atom_body)
        return measure(order, starts, atom_body, self.free_indices, masses, x)


def warn_merged(bodies, atoms, unique_formulas=False):
    """Warn when connectivity probably joined or split the molecules of ``bodies``.

    A body whose composition is a multiple of another body's (two waters
    that came within covalent reach, say) is reported; with
    ``unique_formulas`` (the default rule) so is a body whose formula no
    other body has while other formulas repeat (a CO2 joined to a water
    among CO2 and water molecules, or a water split by a stretched bond).
    """
    if bodies.n_bodies < 2:
        return
    inside = bodies.body_ids >= 0
    elements, element_index = np.unique(atoms.numbers[inside], return_inverse=True)
    counts = np.zeros((bodies.n_bodies, len(elements)), dtype=np.int64)
    np.add.at(counts, (bodies.body_ids[inside], element_index), 1)
    formulas, first, repeats = np.unique(counts, axis=0, return_index=True,
                                         return_counts=True)
    advice = ("Give the bodies explicitly (bodies='mol-id', 'tags' or a list) if that is "
              "wrong")
    for i, big in enumerate(formulas):
        for small in formulas:
            ratio = big.sum() // max(small.sum(), 1)
            if ratio >= 2 and np.array_equal(big, ratio * small):
                b = int(first[i])
                warnings.warn(
                    f"bodies by connectivity: body {b} "
                    f"(atoms {describe_atoms(bodies.atoms_of(b))}) "
                    f"has {ratio} times the atoms of another body; molecules that came "
                    f"within covalent reach were joined. {advice}",
                    stacklevel=5,
                )
                return
    if unique_formulas and repeats.max() >= 2 and np.any(repeats == 1):
        i = int(np.flatnonzero(repeats == 1)[0])
        b = int(first[i])
        formula = atoms[bodies.atoms_of(b)].get_chemical_formula()
        warnings.warn(
            f"bodies by connectivity: body {b} (atoms {describe_atoms(bodies.atoms_of(b))}) "
            f"is the only {formula} among {bodies.n_bodies} bodies whose other formulas "
            f"repeat; molecules may have been joined or split by the covalent cutoffs. "
            f"{advice}",
            stacklevel=5,
        )


def check_masses(masses, symbols, free, order, starts):
    """Refuse masses that no rigid-body dynamics can move.

    Every atom needs a finite mass, positive or 0.  A massless atom (a virtual
    site such as the M site of TIP4P water) must belong to a body, which
    places it rigidly and takes the force on it into its own force and
    torque; a body needs some mass.

    An atom of ASE's dummy element X (Z = 0), the element rigidmd gives every
    virtual site (:data:`rigidmd.water.M_SYMBOL`), must be massless, wherever
    the atoms come from: ASE gives X a mass of 1 amu when a file stores no
    masses (PDB, plain XYZ), which would move M as an atom and make four-site
    water 5.5 % too dense.

    Parameters
    ----------
    masses : numpy.ndarray, shape (n_atoms,)
        amu.
    symbols : sequence of str
        Chemical symbols, for the messages.
    free : numpy.ndarray of int
        Atoms in no body.
    order, starts : numpy.ndarray of int
        Body layout, as in :class:`~rigidmd.core.model.BodyModel`.

    Raises
    ------
    ValueError
        Naming the first atom or body at fault.
    """
    bad = np.flatnonzero(~(masses >= 0) | ~np.isfinite(masses))
    if bad.size:
        a = int(bad[0])
        raise ValueError(
            f"atom {a} ({symbols[a]}) has mass {float(masses[a])!r} amu; every atom needs "
            "a finite mass, positive (or 0 for a virtual site inside a rigid body)"
        )
    sites = np.flatnonzero((np.asarray(symbols) == "X") & (masses != 0))
    if sites.size:
        a = int(sites[0])
        raise ValueError(
            f"atom {a} (X) has mass {float(masses[a]):g} amu, but X (Z = 0) is a massless "
            "virtual site, such as the M of four-site water "
            f"({sites.size} X atoms have mass); give them mass 0 (atoms.set_masses), or keep "
            "the structure in a format that stores masses (.traj, extended XYZ): PDB and XYZ "
            "files have none, and ASE gives X 1 amu; a particle with mass needs another element")
    massless = free[masses[free] == 0]
    if massless.size:
        a = int(massless[0])
        raise ValueError(
            f"atom {a} ({symbols[a]}) has mass 0 and belongs to no rigid body: a massless "
            "atom (a virtual site) must ride in a body with atoms of positive mass"
        )
    if len(starts):
        body_mass = np.add.reduceat(masses[order], starts)
        empty = np.flatnonzero(~(body_mass > 0))
        if empty.size:
            b = int(empty[0])
            stop = starts[b + 1] if b + 1 < len(starts) else len(order)
            raise ValueError(
                f"body {b} (atoms {describe_atoms(order[starts[b]:stop])}) has no mass: "
                "a body of massless atoms (virtual sites only) cannot move"
            )


def cell_widths(cell):
    """Distances between opposite faces of the cell (Å), shape (3,): the k-th is across vector k."""
    cell = np.asarray(cell, dtype=float)
    volume = abs(np.linalg.det(cell))
    return volume / np.linalg.norm(np.cross(cell[[1, 2, 0]], cell[[2, 0, 1]]), axis=1)


def _refuse_long_body(atoms_of_body, b, k, fraction, cell, why):
    """Raise the error for body ``b`` spanning ``fraction`` of the cell's width along vector k."""
    width = cell_widths(cell)[k]
    raise ValueError(
        f"body {b} (atoms {describe_atoms(atoms_of_body)}) spans {fraction * width:.3f} Å "
        f"across cell vector {k}, more than half the periodic cell's width there "
        f"({width:.3f} Å): {why}")


def _bonded_bodies_moved(raw, unwrapped, numbers, atom_body):
    """Bodies that the minimum image would change although their atoms as given are bonded.

    A body whose atoms, as given, form one covalently bonded piece (ASE's
    natural cutoffs, no periodicity) is whole already; if the minimum image
    moves one of its atoms, the body is longer than half the cell and would
    be folded.  Only bodies the minimum image changes are examined.

    Returns
    -------
    numpy.ndarray of int
        Body indices, ascending.
    """
    moved = np.unique(atom_body[np.any(np.abs(unwrapped - raw) > 1e-9, axis=1)])
    if len(moved) == 0:
        return moved
    from ase.data import covalent_radii
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pick = np.flatnonzero(np.isin(atom_body, moved))  # grouped by body (``order``)
    x, body, radius = raw[pick], atom_body[pick], covalent_radii[numbers[pick]]
    # Every pair within a body, without a per-body loop: atom a, the l-th of its body of
    # n atoms starting at s, pairs with s + l + 1, ..., s + n - 1.
    _, first, size = np.unique(body, return_index=True, return_counts=True)
    local = np.arange(len(pick)) - np.repeat(first, size)
    partners = np.repeat(size, size) - local - 1
    i = np.repeat(np.arange(len(pick)), partners)
    offset = np.arange(len(i)) - np.repeat(np.cumsum(partners) - partners, partners)
    j = i + 1 + offset
    # Covalent radii with a 25 % margin over ASE's natural cutoffs: a stretched bond of a
    # body given whole still counts as bonded.
    bonded = np.linalg.norm(x[i] - x[j], axis=1) < 1.25 * (radius[i] + radius[j])
    graph = coo_matrix((np.ones(bonded.sum()), (i[bonded], j[bonded])),
                       shape=(len(pick), len(pick)))
    _, label = connected_components(graph, directed=False)
    pairs = np.unique(np.stack([body, label], axis=1), axis=0)
    pieces = np.bincount(np.searchsorted(moved, pairs[:, 0]), minlength=len(moved))
    return moved[pieces == 1]


def unwrap_bodies(atoms, order, starts, atom_body):
    """Positions of the body atoms with every body made whole.

    Each atom is placed at its minimum image from its body's first atom (in
    ``order``).  Non-periodic systems are returned unchanged.

    Returns
    -------
    numpy.ndarray, shape (n_body_atoms, 3)
        Unwrapped positions (Å), in ``order``.

    Raises
    ------
    ValueError
        If a body reaches more than half the cell's width in a periodic
        direction, where the minimum image is ambiguous.
    """
    from ase.geometry import find_mic

    x = atoms.positions[order]
    pbc = atoms.pbc
    if not pbc.any() or len(order) == 0:
        return x
    cell = atoms.cell.complete()
    anchor = x[starts][atom_body]
    d, _ = find_mic(x - anchor, cell, pbc)
    folded = _bonded_bodies_moved(x, anchor + d, atoms.numbers[order], atom_body)
    if len(folded):
        b = int(folded[0])
        raw = np.linalg.solve(cell.T, x[atom_body == b].T).T
        extent = np.where(pbc, raw.max(axis=0) - raw.min(axis=0), 0.0)
        k = int(np.argmax(extent))
        _refuse_long_body(order[atom_body == b], b, k, extent[k], cell,
                          "the minimum image would fold it (its atoms as given are bonded); "
                          "enlarge the cell")
    x = anchor + d
    # Extent of each body along each periodic direction, in fractions of the
    # cell's width there: the minimum image is unambiguous only below 1/2.
    frac = np.linalg.solve(cell.T, x.T).T
    extent = np.maximum.reduceat(frac, starts) - np.minimum.reduceat(frac, starts)
    extent[:, ~pbc] = 0.0
    b, k = np.unravel_index(np.argmax(extent), extent.shape)
    if extent[b, k] >= 0.5:
        _refuse_long_body(order[atom_body == b], int(b), int(k), extent[b, k], cell,
                          "cannot make it whole by minimum image")
    return x


def molecule_ids(body_ids) -> np.ndarray:
    """The one encoding of bodies as integers outside rigidmd: body ``b`` is ``b + 1``, -1 none.

    Used for the tags of every trajectory frame and by :class:`rigidmd.core.dof.RigidBodyDOF`
    (the molecule IDs of LAMMPS data files and of
    :class:`rigidmd.lammps.LAMMPSCalculator`, which read IDs <= 0 as "no molecule").
    """
    body_ids = np.asarray(body_ids)
    return np.where(body_ids >= 0, body_ids + 1, -1)


def same_partition(a, b) -> bool:
    """Whether two labellings of the atoms group them the same way (labels may differ)."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def store_bodies_in_tags(atoms, body_ids) -> None:
    """Tags = :func:`molecule_ids`: every ``.traj`` frame carries the bodies.

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
    atoms.set_tags(molecule_ids(body_ids))


def body_radii(model) -> np.ndarray:
    """Largest distance of each body's atoms from its centre of mass (Å), shape (n_bodies,)."""
    if model.n_bodies == 0:
        return np.zeros(0)
    d = model.body_coordinates
    return np.sqrt(np.maximum.reduceat(np.sum(d * d, axis=1), model.starts))


def body_too_wide(model, cell, pbc):
    r"""The one rule for "a body spans half the cell": the first body that breaks it, or None.

    A body of radius :math:`R_b` (its largest atom distance from its centre
    of mass) fits a cell when :math:`2R_b < w_k/2` for every periodic
    direction ``k``, :math:`w_k` the distance between the cell's opposite
    faces (:func:`cell_widths`).  The rule does not depend on the body's
    orientation (a body that fits stays fitting as it turns) and bounds the
    body's extent along every cell vector below one half, where the minimum
    image is unambiguous.  The MD barostats (:class:`rigidmd.core.forces.ForceEvaluator`),
    the Monte Carlo barostat and cell relaxation all use it.

    Parameters
    ----------
    model : rigidmd.core.model.BodyModel
    cell : numpy.ndarray, shape (3, 3)
    pbc : array_like of bool, shape (3,)

    Returns
    -------
    tuple or None
        ``(b, k, span, width)``: the body, the cell vector across which it
        does not fit, its span :math:`2R_b` and the width (Å).
    """
    pbc = np.asarray(pbc, dtype=bool)
    if not pbc.any() or model.n_bodies == 0:
        return None
    widths = np.where(pbc, cell_widths(cell), np.inf)
    k = int(np.argmin(widths))
    if 4.0 * model.radius < widths[k]:
        return None
    spans = 2.0 * body_radii(model)
    b = int(np.argmax(spans))
    return b, k, float(spans[b]), float(widths[k])


def check_bodies_fit(model, cell, pbc, when=""):
    """Refuse a cell in which a body spans half the cell (the rule of :func:`body_too_wide`).

    Parameters
    ----------
    model : rigidmd.core.model.BodyModel
    cell : numpy.ndarray, shape (3, 3)
    pbc : array_like of bool, shape (3,)
    when : str
        Appended to the message (what changed the cell).

    Raises
    ------
    ValueError
        Naming the body, its atoms, the cell vector and the widths.
    """
    wide = body_too_wide(model, cell, pbc)
    if wide is not None:
        b, k, span, width = wide
        raise ValueError(
            f"body {b} (atoms {describe_atoms(model.atoms_of(b))}) spans {span:.3f} Å (twice "
            f"its largest atom distance from its centre of mass), not less than half the "
            f"periodic cell's width across cell vector {k} ({width:.3f} Å): the minimum image "
            f"is ambiguous{'; ' + when if when else ''}")


def _close_pairs(atoms, radii):
    """Pairs ``(i, j)`` of atoms closer than ``radii[i] + radii[j]`` (minimum image).

    A k-d tree (:func:`rigidmd.core.neighbours.tree_pairs`) where it applies, else
    ASE's ``neighbor_list``.
    """
    from ase.neighborlist import neighbor_list

    found = tree_pairs(atoms.positions, atoms.cell.array, atoms.pbc, 2.0 * float(np.max(radii)))
    if found is None:
        return neighbor_list("ij", atoms, radii, self_interaction=False)
    i, j, shifts = found
    delta = atoms.positions[j] - atoms.positions[i] + shifts @ atoms.cell.array
    close = np.sum(delta * delta, axis=1) < (radii[i] + radii[j]) ** 2
    return i[close], j[close]
