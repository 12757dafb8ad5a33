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


@pytest.mark.parametrize("build, error, message", [
    (lambda: water_box(0), ValueError, "water_box: n_side must be a whole number >= 1, got 0"),
    (lambda: water_box(-2), ValueError, "water_box: n_side must be a whole number >= 1, got -2"),
    (lambda: water_box(2.5), ValueError, "water_box: n_side must be a whole number >= 1, got 2.5"),
    (lambda: water_box("2"), TypeError, "water_box: n_side must be a whole number >= 1"),
    (lambda: water_box(2, spacing=0), ValueError,
     "water_box: spacing must be a finite number > 0 Å, got 0"),
    (lambda: water_box(2, spacing=-3.1), ValueError,
     "water_box: spacing must be a finite number > 0 Å, got -3.1"),
    (lambda: water_box(2, spacing=float("inf")), ValueError, "water_box: spacing must be"),
    (lambda: water_box(2, jitter=-0.1), ValueError,
     "water_box: jitter must be a finite number >= 0 Å, got -0.1"),
    (lambda: water_cluster(0), ValueError,
     "water_cluster: n_molecules must be a whole number >= 1, got 0"),
    (lambda: water_cluster(-3), ValueError, "water_cluster: n_molecules must be a whole number"),
    (lambda: water_cluster(4.5), ValueError,
     "water_cluster: n_molecules must be a whole number >= 1, got 4.5"),
    (lambda: water_cluster(4, tries=0), ValueError,
     "water_cluster: tries must be a whole number >= 1, got 0"),
    (lambda: water_cluster(4, spacing=0.0), ValueError,
     "water_cluster: spacing must be a finite number > 0 Å, got 0.0"),
    (lambda: co2_water_mixture(-1, 5), ValueError,
     "co2_water_mixture: n_co2 must be a whole number >= 0, got -1"),
    (lambda: co2_water_mixture(3, -1), ValueError,
     "co2_water_mixture: n_water must be a whole number >= 0, got -1"),
    (lambda: co2_water_mixture(0, 0), ValueError,
     "co2_water_mixture: n_co2 \\+ n_water must be at least 1"),
    (lambda: co2_water_mixture(2.5, 2), ValueError,
     "co2_water_mixture: n_co2 must be a whole number >= 0, got 2.5"),
    (lambda: co2_water_mixture(2, 2, spacing=-1), ValueError,
     "co2_water_mixture: spacing must be a finite number > 0 Å, got -1"),
    (lambda: ice_ih((2, 0, 1)), ValueError, "ice_ih: repeat must be a whole number >= 1, got 0"),
    (lambda: ice_ih((2, 1)), ValueError, "ice_ih: repeat must be three whole numbers >= 1"),
    (lambda: ice_ih((2, 1, 1), a=-4.5), ValueError,
     "ice_ih: a must be a finite number > 0 Å, got -4.5"),
])
def test_the_builders_refuse_bad_counts_and_spacings_in_one_line(build, error, message):
    """A negative count gave fewer molecules (``co2_water_mixture(-1, 5)``: 4 waters), a
    zero spacing 8 molecules at the origin in a zero cell, a negative one a left-handed
    cell; other values failed in NumPy or ASE with unrelated messages."""
    with pytest.raises(error, match=f"^{message}") as err:
        build()
    assert "\n" not in str(err.value)


def test_whole_counts_may_be_floats_or_numpy_integers():
    assert np.array_equal(water_box(2.0, seed=1).positions, water_box(2, seed=1).positions)
    assert np.array_equal(water_cluster(np.int64(3), seed=1).positions,
                          water_cluster(3, seed=1).positions)
    assert co2_water_mixture(0, 2).get_chemical_formula() == "H4O2"
    assert co2_water_mixture(1, 0).get_chemical_formula() == "CO2"


@pytest.mark.parametrize("build", [water_molecule, lambda model: water_box(2, model=model),
                                   lambda model: water_cluster(3, model=model),
                                   lambda model: ice_ih((2, 1, 1), model=model)])
def test_the_builders_take_a_model_or_its_name(build):
    """``water_box(model=water_model("opc"))`` was refused as an unknown water model."""
    by_name, by_model = build("opc"), build(water_model("opc"))
    assert np.array_equal(by_model.positions, by_name.positions)
    assert np.array_equal(by_model.get_masses(), by_name.get_masses())


def test_ice_needs_four_distinct_neighbours_per_oxygen():
    """One repeat along x (4.5 Å) gives each oxygen two bonds to one neighbour (two
    images): (1, 1, 1) has 16 bonds but 12 distinct oxygen pairs, and was built though
    the docstring says it is refused.  Two repeats along x have 32 bonds, 32 pairs."""
    for repeat in ((1, 1, 1), (1, 2, 2), 1):
        with pytest.raises(ValueError, match="^ice_ih: the cell is too small for four "
                                             "distinct neighbours per oxygen"):
            ice_ih(repeat)
    assert len(ice_ih((2, 1, 1), model="tip3p")) == 16 * 3
