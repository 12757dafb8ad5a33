"""Ready-made systems: waters, CO2, mixtures, ice (rigidmd.systems.builders)."""

import numpy as np
import pytest
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidBodies
from rigidmd.systems import (
    R_CO,
    co2_molecule,
    co2_water_mixture,
    ice_ih,
    random_quaternions,
    water_box,
    water_cluster,
    water_molecule,
)
from rigidmd.water import water_model


def test_molecules():
    water = water_molecule("tip4p2005")
    assert water.get_chemical_symbols() == ["O", "H", "H", "X"]
    assert np.allclose(water.positions[0], 0.0) and np.allclose(water.positions[:, 2], 0.0)
    co2 = co2_molecule()
    assert co2.get_chemical_formula() == "CO2"
    assert np.allclose(np.linalg.norm(co2.positions[1:], axis=1), R_CO)


def test_random_quaternions_are_unit_and_uniform(rng):
    q = random_quaternions(20000, rng)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    # Uniform on the sphere S3: each component has mean 0 and variance 1/4 (error ~0.004).
    assert np.allclose(q.mean(axis=0), 0.0, atol=0.02)
    assert np.allclose((q * q).mean(axis=0), 0.25, atol=0.01)


def test_a_cluster_is_hydrogen_bonded_and_repeatable():
    atoms = water_cluster(8, seed=1)
    assert len(atoms) == 24 and not atoms.pbc.any()
    assert atoms.arrays["mol-id"].tolist() == np.repeat(np.arange(1, 9), 3).tolist()
    assert np.array_equal(water_cluster(8, seed=1).positions, atoms.positions)
    atoms.calc = TIP3P(rc=40)
    # Best-of-64 orientations: hydrogen-bonded (measured -0.234 eV per water; random
    # orientations are about zero or above).
    assert atoms.get_potential_energy() / 8 < -0.15


def test_a_box_is_whole_or_wrapped_at_liquid_density():
    box = water_box(3, seed=2)
    assert len(box) == 81 and box.pbc.all()
    density = box.get_masses().sum() * 1.66054 / box.get_volume()
    assert density == pytest.approx(1.0, abs=0.01)
    water_model("tip3p").check(box)  # every molecule whole, in the model's geometry
    wrapped = water_box(3, seed=2, whole=False)
    assert np.all(wrapped.get_scaled_positions(wrap=False) >= 0.0)
    assert np.all(wrapped.get_scaled_positions(wrap=False) < 1.0)


def test_a_mixture_and_ice():
    mix = co2_water_mixture(3, 5, seed=1, box=True)
    assert mix.get_chemical_formula(mode="all").count("C") == 3 and mix.pbc.all()
    bodies = RigidBodies.resolve(mix)
    assert bodies.n_bodies == 8
    ice = ice_ih((2, 1, 1), seed=0)
    assert len(ice) == 16 * 4 and ice.pbc.all()
    oxygens = ice.positions[ice.numbers == 8]
    assert len(oxygens) == 16
    model = water_model("tip4p2005")
    dipole = model.charges(16) @ RigidBodies.resolve(ice).whole_positions(ice)
    assert np.linalg.norm(dipole) < 1e-10  # zero net dipole (measured 4e-15 e Å)
