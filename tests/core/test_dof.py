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
