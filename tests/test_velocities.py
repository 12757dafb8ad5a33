import numpy as np
import pytest
from ase import Atoms, units

from rigidmd import RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.systems import co2_water_mixture


def test_rigid_maxwell_boltzmann_is_rigid_and_equipartitioned():
    atoms = co2_water_mixture(20, 20, seed=1)
    neon = Atoms("Ne10", positions=np.arange(30).reshape(10, 3) + 50.0)
    neon.arrays["mol-id"] = np.full(10, -1)  # negative: atoms in no body
    atoms += neon
    temperatures = {"trans": [], "rot_linear": [], "rot_water": []}
    rng = np.random.default_rng(7)
    draws = 200
    for _ in range(draws):
        rigid_maxwell_boltzmann(atoms, 300, bodies="mol-id", rng=rng)
        dyn = RigidVerlet(atoms, units.fs, bodies="mol-id")
        assert abs(dyn.removed_kinetic_energy) < 1e-12  # already rigid
        lin = dyn.model.linear
        rot = dyn.rotational_kinetic_energies
        temperatures["trans"].append(
            2 * dyn.get_translational_kinetic_energy() / (3 * (40 + 10) * units.kB))
        temperatures["rot_linear"].append(2 * rot[lin].sum() / (2 * 20 * units.kB))
        temperatures["rot_water"].append(2 * rot[~lin].sum() / (3 * 20 * units.kB))
    dof = {"trans": 150, "rot_linear": 40, "rot_water": 60}
    for name, values in temperatures.items():
        # The mean of a chi-squared temperature over draws * dof degrees of
        # freedom has relative standard deviation sqrt(2 / (draws * dof)):
        # 1.6 % for the CO2 rotations.  Four of those.
        sigma = np.sqrt(2 / (draws * dof[name]))
        assert np.mean(values) == pytest.approx(300, rel=4 * sigma), name


def test_bad_temperature():
    atoms = co2_water_mixture(1, 1)
    with pytest.raises(ValueError, match="temperature_K"):
        rigid_maxwell_boltzmann(atoms, -5, bodies="mol-id")
