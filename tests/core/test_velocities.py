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


def _four_site_cluster():
    from rigidmd.systems import water_cluster

    atoms = water_cluster(8, model="tip4p2005", seed=2)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    return atoms


def test_ase_stationary_zeroes_four_site_water_and_rigid_stationary_does_not():
    from ase.md.velocitydistribution import Stationary

    from rigidmd import kinetic_energy, rigid_stationary

    # ASE's Stationary reads a 0/0 temperature on the massless M and zeroes
    # every momentum: the reason rigidmd has its own.
    broken = _four_site_cluster()
    with np.errstate(invalid="ignore"):
        Stationary(broken)
    assert not np.any(broken.get_momenta())

    atoms = _four_site_cluster()
    kinetic0 = kinetic_energy(atoms)
    total0 = atoms.get_momenta().sum(axis=0)
    assert np.linalg.norm(total0) > 1e-3  # something to remove
    rigid_stationary(atoms)
    assert np.abs(atoms.get_momenta().sum(axis=0)).max() < 1e-13
    assert kinetic_energy(atoms) == pytest.approx(kinetic0, rel=1e-13)
    assert not np.any(atoms.get_momenta()[atoms.get_masses() == 0])
    dyn = RigidVerlet(atoms, units.fs)
    assert abs(dyn.removed_kinetic_energy) < 1e-13  # still rigid


def test_rigid_zero_rotation_on_four_site_water():
    from rigidmd import kinetic_energy, rigid_stationary, rigid_zero_rotation

    atoms = _four_site_cluster()
    kinetic0 = kinetic_energy(atoms)
    rigid_stationary(atoms)
    rigid_zero_rotation(atoms)
    p = atoms.get_momenta()
    r = atoms.get_positions() - atoms.get_center_of_mass()
    assert np.abs(np.cross(r, p).sum(axis=0)).max() < 1e-12
    assert np.abs(p.sum(axis=0)).max() < 1e-13  # the rotation removed no momentum
    assert kinetic_energy(atoms) == pytest.approx(kinetic0, rel=1e-13)
    dyn = RigidVerlet(atoms, units.fs)
    assert abs(dyn.removed_kinetic_energy) < 1e-13
    # Without preserve_temperature the kinetic energy drops by what was removed.
    atoms = _four_site_cluster()
    rigid_zero_rotation(atoms, preserve_temperature=False)
    assert kinetic_energy(atoms) < kinetic0


def test_ase_stationary_between_steps_on_four_site_water_is_reported():
    """ASE's Stationary zeroes a four-site system's momenta: the dynamics says so."""
    from ase.md.velocitydistribution import Stationary
    from helpers import CoulombLJ, water_parameters

    from rigidmd.water import WATER_MODELS

    atoms = _four_site_cluster()
    atoms.calc = CoulombLJ(parameters=water_parameters(WATER_MODELS["tip4p2005"]))
    dyn = RigidVerlet(atoms, units.fs)
    dyn.run(2)
    with np.errstate(invalid="ignore"):
        Stationary(atoms)
    with pytest.warns(UserWarning, match="rigidmd.rigid_stationary"):
        dyn.run(1)


def test_a_stationary_draw_has_no_total_momentum_and_its_kinetic_energy():
    """A draw carries a thermal drift (0.32 Å/ps for 216 waters, which a thermostat with
    fixcm=True then kept for the whole run); ``stationary=True`` zeroes it, as LAMMPS's
    ``velocity create ... mom yes``, and keeps the draw's temperature counted over the
    N_f - 3 degrees of freedom left (it kept the kinetic energy, so a thermostat holding
    the momentum started 8 waters 6.7 % hot: 339 K for 300 over 400 draws of 4 waters)."""
    from rigidmd import kinetic_energy
    from rigidmd.systems import water_cluster

    drifting, still = (water_cluster(8, model="tip4p2005", seed=2) for _ in range(2))
    rigid_maxwell_boltzmann(drifting, 300, rng=np.random.default_rng(5))
    rigid_maxwell_boltzmann(still, 300, rng=np.random.default_rng(5), stationary=True)
    masses = drifting.get_masses()
    drift = np.linalg.norm(drifting.get_momenta().sum(axis=0)) / masses.sum()
    assert drift > 1e-3  # Å per ASE time unit: a thermal drift, ~ sqrt(kT / M)
    np.testing.assert_allclose(still.get_momenta().sum(axis=0), 0, atol=1e-12)
    assert kinetic_energy(still) == pytest.approx(kinetic_energy(drifting) * 45 / 48,
                                                  rel=1e-12)  # 8 waters: N_f = 48
    dyn = RigidVerlet(still, units.fs)
    assert abs(dyn.removed_kinetic_energy) < 1e-12  # still rigid
    # Under a thermostat holding the momentum the start reads the drawn temperature.
    from rigidmd import RigidBussi, temperature

    drawn = 2 * kinetic_energy(drifting) / (48 * units.kB)
    bussi = RigidBussi(still, units.fs, temperature_K=300, taut=100 * units.fs)
    assert bussi.holds_momentum and temperature(still) == pytest.approx(drawn, rel=1e-12)
