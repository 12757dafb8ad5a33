"""NumPy views of a LAMMPS instance's atoms (rigidmd.lammps.atomarrays)."""

import numpy as np
import pytest
from helpers import PPPM_27, water_box_27

from rigidmd.lammps import LAMMPSCalculator

pytestmark = pytest.mark.lammps


@pytest.fixture
def arrays():
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1, "H": 2})
    forces = atoms.get_forces()
    return atoms, forces, atoms.calc._instance.arrays


def test_the_views_are_lammpss_own_arrays(arrays):
    atoms, forces, view = arrays
    assert view.nlocal == len(atoms) == 81
    order = view.order()
    assert sorted(order.tolist()) == list(range(81))
    assert np.array_equal(order, view.view("id") - 1)
    assert view.view("x") is view.view("x")  # kept while LAMMPS's array stays
    out = np.empty((81, 3))
    view.read_forces(out)
    assert np.allclose(out, forces, atol=1e-10)  # a cubic box: LAMMPS's frame is ASE's


def test_image_flags_round_trip(arrays):
    _, _, view = arrays
    images = np.array([[0, 0, 0], [-1, 2, 3], [511, -512, 0]])
    packed = view.pack_images(images)
    saved = view.view("image")[:3].copy()
    view.view("image")[:3] = packed
    assert np.array_equal(view.images()[:3], images)  # both in LAMMPS's order
    view.view("image")[:3] = saved


def test_positions_written_are_read_back_in_lammpss_images(arrays):
    atoms, _, view = arrays
    cell = atoms.cell.array
    shifted = atoms.positions + cell[0] * 3  # three boxes away: shifted back by whole boxes
    view.write_positions(shifted, cell)
    x = view.view("x")
    unwrapped = x + view.images() @ cell
    assert np.allclose(unwrapped[np.argsort(view.order())], shifted, atol=1e-9)
