"""What :class:`~rigidmd.lammps.LAMMPSCalculator` tells LAMMPS about each atom: type and molecule.

Molecules (for ``neigh_modify exclude molecule/intra all``) are the bodies of
the rigid dynamics the atoms are in (a ``mol-id`` array, tags or
``molecule_ids`` that group the atoms otherwise are refused); outside a
dynamics they come from ``molecule_ids`` when the calculator was given them
(an explicit argument wins over what the atoms carry), else from the ``mol-id``
array, else from non-zero tags.  Masses never enter a force call: atoms of one
element share a type whatever their masses (H and D).
"""

import numpy as np

from rigidmd.lammps.data import MASSLESS_SITE_MASS

__all__ = ["check_molecule_ids", "lammps_molecule_ids", "lammps_types", "molecules_of"]


def lammps_types(atoms, atom_types):
    """LAMMPS type of each atom, the mass of each type and the label of each type.

    Parameters
    ----------
    atoms : ase.Atoms
    atom_types : dict of str to int or None
        Type of each element; None: the elements numbered 1, 2, ... in order of
        first appearance.

    Returns
    -------
    types : numpy.ndarray of int64, shape (n_atoms,)
    type_mass : dict of int to float
        Mass (amu) of each type 1 ... max: the largest mass of its atoms, or
        :data:`~rigidmd.lammps.data.MASSLESS_SITE_MASS` (LAMMPS refuses 0).
    labels : dict of int to str
        The element of each type.
    """
    symbols = atoms.get_chemical_symbols()
    if atom_types is None:
        table = {s: i + 1 for i, s in enumerate(dict.fromkeys(symbols))}
    else:
        table = atom_types
        missing = sorted(set(symbols) - set(table))
        if missing:
            raise ValueError(f"LAMMPSCalculator: element {missing[0]} has no LAMMPS type in "
                             f"atom_types {table}")
    types = np.array([table[s] for s in symbols], dtype=np.int64)
    # Masses never enter a force call (LAMMPS's per-type mass is only stored): atoms
    # of one type may differ in mass (H and D, 16O and 18O).  LAMMPS refuses a mass of
    # 0 (a virtual site), so a type gets the largest mass of its atoms, or a tiny one.
    masses = atoms.get_masses()
    largest = np.zeros(max(table.values()) + 1)
    np.maximum.at(largest, types, masses)
    type_mass = {t: float(largest[t]) if largest[t] > 0 else MASSLESS_SITE_MASS
                 for t in range(1, len(largest))}
    labels = {t: s for s, t in table.items()}
    return types, type_mass, labels


def check_molecule_ids(molecule_ids, owner="LAMMPSCalculator"):
    """A calculator's ``molecule_ids`` argument as an int64 array, or None.

    Refused in one ``ValueError`` naming ``owner`` (the class): anything but one
    whole number per atom (a 1-D sequence of integers, or of floats with whole
    values; not booleans or text).  Its length is checked against the atoms at
    each call, by :func:`molecules_of`.
    """
    if molecule_ids is None:
        return None
    ids = np.asarray(molecule_ids)
    whole = ids.ndim == 1 and (
        np.issubdtype(ids.dtype, np.integer)
        or (np.issubdtype(ids.dtype, np.floating) and bool(np.all(np.isfinite(ids)))
            and bool(np.all(ids == np.round(ids)))))
    if not whole:
        raise ValueError(f"{owner}: molecule_ids must be one whole number per atom, got an "
                         f"array of shape {ids.shape} and dtype {ids.dtype}")
    ids = ids.astype(np.int64)
    ids.flags.writeable = False
    return ids


def molecules_of(atoms, molecule_ids, checked):
    """Molecule ID of each atom (1-based; <= 0: in no molecule) and where they came from.

    The bodies of a rigid dynamics the atoms are in come first: they are the
    molecules.  A ``mol-id`` array, non-zero tags or ``molecule_ids`` that group
    the atoms otherwise are refused (they would exclude pairs between bodies, or
    count pairs inside one).  Without a rigid dynamics: ``molecule_ids`` when
    given (the calculator's explicit argument wins over what the atoms carry),
    else ``mol-id``, else non-zero tags.  Given ``molecule_ids`` must have one ID
    per atom, whatever the atoms carry.

    Parameters
    ----------
    atoms : ase.Atoms
    molecule_ids : numpy.ndarray, shape (n_atoms,), or None
        The calculator's ``molecule_ids`` (see :func:`check_molecule_ids`).
    checked : object
        What the last call returned as ``checked`` (None at first): a grouping
        found to agree is not checked again at every step.

    Returns
    -------
    molecules : numpy.ndarray of int64, shape (n_atoms,), or None
    source : str or None
        ``"bodies"``, ``"mol-id array"``, ``"tags"``, ``"molecule_ids"`` or None.
    checked : object
        To give to the next call.
    """
    n = len(atoms)
    given, source = None, None
    if molecule_ids is not None:  # (the explicit argument, whatever the atoms carry)
        if molecule_ids.shape != (n,):
            raise ValueError(f"LAMMPSCalculator: molecule_ids has shape "
                             f"{molecule_ids.shape}, the atoms are {n}")
        given, source = np.asarray(molecule_ids, dtype=np.int64), "molecule_ids"
    elif "mol-id" in atoms.arrays:
        given, source = np.asarray(atoms.arrays["mol-id"], dtype=np.int64), "mol-id array"
    elif np.any(atoms.get_tags() != 0):
        given, source = np.asarray(atoms.get_tags(), dtype=np.int64), "tags"
    bodies = next((np.asarray(c.body_ids, dtype=np.int64) for c in atoms.constraints
                   if getattr(c, "body_ids", None) is not None), None)
    if bodies is None:
        return given, source, checked
    if bodies.shape != (n,):
        raise ValueError(f"LAMMPSCalculator: the rigid bodies cover {bodies.size} atoms, "
                         f"the atoms are {n}")
    if given is not None:
        key = (bodies.tobytes(), given.tobytes())  # checked once, not at every step
        if key != checked:
            _check_same_grouping(bodies, given, source)
            checked = key
    return bodies, "bodies", checked


def lammps_molecule_ids(molecules, n):
    """The molecule IDs LAMMPS gets: every atom in no molecule (ID <= 0) in one of its own.

    ``molecules``: as :func:`molecules_of` returns (None: every atom its own
    molecule, so that nothing is excluded); ``n``: the number of atoms.
    """
    if molecules is None:
        return np.arange(1, n + 1)
    # LAMMPS excludes pairs of equal molecule IDs: atoms in no molecule (ID <= 0)
    # get IDs of their own.
    molecules = molecules.copy()
    alone = molecules <= 0
    molecules[alone] = molecules.max(initial=0) + 1 + np.arange(int(alone.sum()))
    return molecules


def _distinct(ids):
    """Molecule IDs with every atom in no molecule (ID <= 0) in a group of its own."""
    return np.where(ids > 0, ids, -np.arange(len(ids)))


def _check_same_grouping(bodies, given, source):
    """Refuse molecules (``source``) that merge or split the rigid bodies, naming two atoms.

    ``bodies``: body index + 1 of each atom (0: a free atom); ``given``: the
    molecule IDs read from ``source`` (<= 0: no molecule).
    """
    b, m = _distinct(bodies), _distinct(given)
    pairs = np.unique(np.stack([b, m], axis=1), axis=0)
    if len(pairs) == len(np.unique(b)) == len(np.unique(m)):
        return
    for key, other, verb in ((m, b, "put atoms {i} and {j} in one molecule but they are in "
                              "different rigid bodies"),
                             (b, m, "split a rigid body: atoms {i} and {j} are in one body but "
                              "in different molecules")):
        order = np.lexsort((other, key))
        k, o = key[order], other[order]
        clash = np.flatnonzero((k[1:] == k[:-1]) & (o[1:] != o[:-1]))
        if clash.size:
            i, j = sorted((int(order[clash[0]]), int(order[clash[0] + 1])))
            remedy = {"tags": "atoms.set_tags(0)", "mol-id array": "del atoms.arrays['mol-id']",
                      "molecule_ids": "molecule_ids=None"}[source]
            raise ValueError(
                f"LAMMPSCalculator: the atoms' {source} {verb.format(i=i, j=j)}; in a rigid "
                f"dynamics the bodies are the molecules: remove them ({remedy}) "
                "or make them group the atoms as the bodies do")
