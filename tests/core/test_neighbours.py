"""The k-d tree pair search shared by the connectivity rule and the relaxation preconditioner."""

import numpy as np
from ase.neighborlist import neighbor_list

from rigidmd.core.neighbours import tree_nearest, tree_pairs
from rigidmd.systems import water_box, water_cluster


def test_tree_pairs_and_nearest_are_ase_s_neighbour_list():
    """Pairs (each once, the nearest image) and each point's nearest distance as ASE's
    neighbour list gives them, with points outside the box; None where a k-d tree does not
    apply (a sheared cell, a box under two cut-offs wide)."""
    for atoms in (water_box(3), water_cluster(12)):
        atoms.positions[0, 0] = -1e-17  # wraps to the box's length in floating point
        if atoms.pbc.all():
            atoms.positions[1::4] += atoms.cell.array.sum(axis=0)
        i, j, shifts = tree_pairs(atoms.positions, atoms.cell.array, atoms.pbc, 3.5)
        assert np.all(i < j)
        d = np.linalg.norm(atoms.positions[j] - atoms.positions[i] + shifts @ atoms.cell.array,
                           axis=1)
        ours = sorted(zip(np.r_[i, j], np.r_[j, i], np.round(np.r_[d, d], 9), strict=True))
        theirs = neighbor_list("ijd", atoms, 3.5)
        assert len(ours) == len(theirs[0]) > 0
        assert ours == sorted(zip(*theirs[:2], np.round(theirs[2], 9), strict=True))
        nearest = np.full(len(atoms), np.inf)
        np.minimum.at(nearest, theirs[0], theirs[2])
        np.testing.assert_allclose(
            tree_nearest(atoms.positions, atoms.cell.array, atoms.pbc), nearest, atol=1e-9)
    box = water_box(3)
    assert tree_pairs(box.positions, box.cell.array, box.pbc, box.cell[0, 0] / 2) is None
    sheared = box.cell.array + [[0, 0, 0], [2.0, 0, 0], [0, 0, 0]]
    assert tree_pairs(box.positions, sheared, box.pbc, 3.5) is None
    assert tree_nearest(box.positions, sheared, box.pbc) is None
