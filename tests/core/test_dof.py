"""Degrees of freedom for ASE, and the kinetic energy of atoms with virtual sites
(rigidmd.core.dof)."""

import copy

import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.tip3p import TIP3P
from ase.constraints import FixCom

from rigidmd import RigidVerlet
from rigidmd.core.dof import RigidBodyDOF, kinetic_energy, temperature
from rigidmd.systems import water_cluster


def test_the_dynamics_leaves_six_degrees_of_freedom_per_water():
    atoms = water_cluster(4, seed=1)
    atoms.calc = TIP3P()
    RigidVerlet(atoms, 1 * units.fs)
    (dof,) = [c for c in atoms.constraints if isinstance(c, RigidBodyDOF)]
    assert dof.get_removed_dof(atoms) == 3 * 12 - 6 * 4
    assert list(dof.body_ids) == [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4]
    atoms.set_momenta(np.random.default_rng(0).normal(size=(12, 3)))
    assert atoms.get_temperature() == pytest.approx(temperature(atoms))
    assert temperature(atoms) == pytest.approx(2 * kinetic_energy(atoms) / (24 * units.kB))


@pytest.mark.parametrize("fixcm", [False, True])
def test_repeated_atoms_count_each_copys_bodies_and_one_held_centre(fixcm):
    """``atoms.repeat`` failed (AttributeError: the marker had no ``repeat``); the repeated
    system now counts 6 per water of every copy, less 3 once when the momentum is held.
    Atoms extended since the marking (``atoms + other``) read 186.8 K for 233.5 K (the old
    count): refused now, in one line."""
    from rigidmd import RigidBussi, rigid_maxwell_boltzmann, rigid_temperature

    atoms = water_cluster(4, seed=1)
    atoms.calc = TIP3P()
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0), stationary=fixcm)
    if fixcm:
        RigidBussi(atoms, 1 * units.fs, temperature_K=300, taut=100 * units.fs)
    else:
        RigidVerlet(atoms, 1 * units.fs)
    held = 3 if fixcm else 0
    assert atoms.get_number_of_degrees_of_freedom() == 24 - held
    atoms.set_cell([20.0, 20.0, 20.0])
    big = atoms.repeat((2, 1, 3))
    assert big.get_number_of_degrees_of_freedom() == 6 * 24 - held
    (marker,) = [c for c in big.constraints if isinstance(c, RigidBodyDOF)]
    assert list(marker.body_ids) == list(np.repeat(np.arange(1, 25), 3))
    bodies = [list(range(3 * i, 3 * i + 3)) for i in range(24)]
    kinetic = kinetic_energy(big)
    assert big.get_temperature() == pytest.approx(2 * kinetic / ((144 - held) * units.kB))
    if not fixcm:
        assert big.get_temperature() == pytest.approx(rigid_temperature(big, bodies=bodies))
    doubled = atoms + atoms.copy()
    with pytest.raises(ValueError, match=r"RigidBodyDOF: these 24 atoms are not the 12 a "
                                         r"rigid dynamics marked \(extended since\?\)"):
        doubled.get_temperature()


def test_it_never_moves_anything_and_copies_cheaply():
    dof = RigidBodyDOF(5, [1, 1, -1])
    atoms = Atoms("H3", positions=np.eye(3))
    arrays = [np.ones((3, 3)) for _ in range(3)]
    dof.adjust_positions(atoms, arrays[0])
    dof.adjust_momenta(atoms, arrays[1])
    dof.adjust_forces(atoms, arrays[2])
    assert all(np.array_equal(a, np.ones((3, 3))) for a in arrays)
    clone = copy.deepcopy(dof)
    assert clone is not dof and clone.removed_dof == 5
    assert list(clone.body_ids) == [1, 1, -1]
    assert repr(clone) == "RigidBodyDOF(removed_dof=5)"
    with pytest.raises(NotImplementedError):
        dof.index_shuffle(atoms, [0])
    assert RigidBodyDOF(0).body_ids is None


def test_a_massless_site_carries_no_kinetic_energy():
    atoms = Atoms("OHHX", positions=np.zeros((4, 3)), masses=[16.0, 1.0, 1.0, 0.0])
    atoms.set_momenta([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 2.0], [0, 0, 0]], apply_constraint=False)
    assert kinetic_energy(atoms) == pytest.approx(0.5 * (1 / 16 + 1 + 4))
    plain = Atoms("OH", positions=np.zeros((2, 3)), momenta=[[1.0, 2, 3], [0, 0, 1.0]])
    assert kinetic_energy(plain) == plain.get_kinetic_energy()  # ASE's arithmetic, to the bit
    plain.constraints = [FixCom()]
    assert temperature(plain) == pytest.approx(2 * kinetic_energy(plain) / (3 * units.kB))
