"""The bodies' make-up and inertia, one object for every part (rigidmd.core.model)."""

import numpy as np
import pytest
from ase import units
from helpers import mixture

from rigidmd import RigidVerlet
from rigidmd.core.model import inertia_tensors, measure, safe_inverse


def test_the_model_of_a_mixture():
    """4 CO2 (linear), 4 waters and 2 neon atoms: 6 + 5 degrees of freedom and 3 per atom."""
    atoms = mixture()
    model = RigidVerlet(atoms, 1 * units.fs).model
    assert (model.n_atoms, model.n_bodies, model.n_free) == (26, 8, 2)
    assert model.translational_dof == 3 * 10
    assert model.rotational_dof == 4 * 2 + 4 * 3
    assert model.degrees_of_freedom == 50
    assert model.linear.sum() == 4 and np.all(model.moments[model.linear, 0] == 0)
    assert np.all(model.inv_moments[model.linear, 0] == 0)  # no inverse of a zero moment
    masses = atoms.get_masses()
    for b in range(model.n_bodies):
        assert model.mass[b] == pytest.approx(masses[model.atoms_of(b)].sum())
    assert np.array_equal(model.free, [24, 25])
    assert model.radius == pytest.approx(np.linalg.norm(model.body_coordinates, axis=1).max())
    with pytest.raises(ValueError, match="read-only"):
        model.mass[0] = 1.0


def test_update_from_replaces_the_contents_in_place():
    first = RigidVerlet(mixture(seed=3), 1 * units.fs).model
    second = RigidVerlet(mixture(seed=4), 1 * units.fs).model
    first.update_from(second)
    assert first.body_coordinates is second.body_coordinates
    water = RigidVerlet(mixture(seed=3)[:9], 1 * units.fs).model
    with pytest.raises(ValueError, match="the stored body model has 9 atoms, 3 bodies and 0 "
                                         "free atoms; these atoms have 26, 8 and 2"):
        first.update_from(water)


def test_inertia_and_a_body_without_orientation():
    r = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    (tensor,) = inertia_tensors(r, np.array([2.0, 2.0]), np.array([0]))
    assert np.allclose(tensor, np.diag([0.0, 4.0, 4.0]))
    assert np.array_equal(safe_inverse(np.array([[0.0, 2.0, 4.0]])), [[0.0, 0.5, 0.25]])
    with pytest.raises(ValueError):  # all its mass at one point
        measure(np.array([0, 1]), np.array([0]), np.array([0, 0]), np.array([], dtype=int),
                np.array([1.0, 1.0]), np.zeros((2, 3)))
    geometry = measure(np.array([], dtype=int), np.array([], dtype=int),
                       np.array([], dtype=int), np.array([0]), np.array([4.0]),
                       np.zeros((0, 3)))
    assert geometry.model.n_bodies == 0 and geometry.model.n_free == 1
