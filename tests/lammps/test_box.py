"""The LAMMPS box of an ASE cell: frame, reduced tilts, region (rigidmd.lammps.box).

Cell changes in a running LAMMPS are in ``test_boxplugin.py``."""

import numpy as np
import pytest

from rigidmd.lammps.box import lammps_box, lower_triangular, reduce_tilt, region_command


def test_a_lower_triangular_cell_is_left_as_it_is():
    cell = np.array([[10.0, 0, 0], [2.0, 9.0, 0], [1.0, -3.0, 8.0]])
    rotation, same = lower_triangular(cell)
    assert rotation is None and same is cell


def test_any_right_handed_cell_is_rotated_into_lammpss_frame(rng):
    cell = rng.normal(size=(3, 3)) + 6 * np.eye(3)
    if np.linalg.det(cell) < 0:
        cell = cell[[1, 0, 2]]
    rotation, lower = lower_triangular(cell)
    assert np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-14)
    assert np.allclose(cell @ rotation, lower, atol=1e-12)
    assert lower[0, 1] == lower[0, 2] == lower[1, 2] == 0.0 and np.all(np.diag(lower) > 0)
    with pytest.raises(ValueError, match="the cell is left-handed"):
        lower_triangular(cell[[1, 0, 2]])


def test_tilts_are_reduced_to_the_same_lattice():
    cell = np.array([[10.0, 0, 0], [23.0, 8.0, 0], [-6.0, 13.0, 9.0]])
    reduced, flips = reduce_tilt(cell)
    assert abs(reduced[1, 0]) <= 5.0 and abs(reduced[2, 0]) <= 5.0 and abs(reduced[2, 1]) <= 4.0
    # The same lattice: an integer unimodular change of basis.
    change = np.linalg.solve(cell.T, reduced.T).T
    assert np.allclose(change, np.rint(change), atol=1e-12)
    assert round(abs(np.linalg.det(change))) == 1
    assert flips == (2, -5, 2)  # c - 2b = (-52, -3, 9), less -5a; b - 2a
    rotation, box, same = lammps_box(np.diag([10.0, 9.0, 8.0]))
    assert rotation is None and same == (0, 0, 0)
    assert lammps_box(cell)[2] == flips


def test_the_region_command():
    assert region_command(np.diag([10.0, 9.0, 8.0])) == (
        "region rmd_box block 0 10 0 9 0 8 units box")
    tilted = np.array([[10.0, 0, 0], [0.5, 9.0, 0], [0.0, -1.25, 8.0]])
    assert region_command(tilted) == "region rmd_box prism 0 10 0 9 0 8 0.5 0 -1.25 units box"
