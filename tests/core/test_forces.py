"""Calculator calls for a rigid system (rigidmd.core.forces): forces reduced to bodies,
properties computed together, non-finite results named."""

import numpy as np
import pytest
from ase import units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P
from helpers import CoulombLJ, mixture

from rigidmd import RigidVerlet
from rigidmd.core import operators as ops
from rigidmd.core.forces import NonFiniteForceError, calculate_together
from rigidmd.systems import water_cluster


class Counting(TIP3P):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.calls = []

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        self.calls.append(tuple(properties))
        super().calculate(atoms, properties, system_changes)


def test_properties_are_computed_in_one_call():
    atoms = water_cluster(3, seed=1)
    calc = atoms.calc = Counting()
    assert calculate_together(calc, atoms, ["forces", "energy"])
    assert len(calc.calls) == 1
    assert calculate_together(calc, atoms, ["energy"])  # cached: no call
    assert len(calc.calls) == 1
    atoms.positions[0, 0] += 0.1
    calculate_together(calc, atoms, ["forces"])
    assert len(calc.calls) == 2
    assert not calculate_together(object(), atoms, ["forces"])  # not an ASE calculator


def test_the_record_holds_the_reduced_forces():
    atoms = mixture()
    dyn = RigidVerlet(atoms, 1 * units.fs, backend="numpy")
    dyn.run(1)
    forces = CoulombLJ().get_forces(atoms)
    record, model = dyn.record, dyn.model
    F, tau = ops.reduce_forces(forces, record.r, model)
    assert np.allclose(record.F, F, atol=1e-10) and np.allclose(record.tau, tau, atol=1e-10)
    assert np.allclose(record.f, forces[model.free], atol=1e-12)


class Poisoned(Calculator):
    implemented_properties = ["energy", "forces"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        forces = np.zeros((len(atoms), 3))
        forces[4, 2] = np.inf
        self.results = {"energy": 0.0, "forces": forces}


def test_a_non_finite_force_names_its_atom():
    atoms = water_cluster(2, seed=1)
    atoms.calc = Poisoned()
    with pytest.raises(NonFiniteForceError, match=r"calculator returned non-finite forces on "
                                                  r"atom\(s\) \[4\] after step 0; the atoms "
                                                  r"are left at step 0"):
        RigidVerlet(atoms, 1 * units.fs).run(1)
    assert issubclass(NonFiniteForceError, ValueError)
