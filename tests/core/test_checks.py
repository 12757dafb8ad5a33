"""Checks a step relies on: time step, finite values, constraints, the calculator's cache
(rigidmd.core.checks)."""

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms, FixCom

from rigidmd.core.checks import (
    changed_properties,
    check_constraints,
    check_finite,
    check_massless_momenta,
    check_timestep,
    copy_atoms,
    real_number,
)
from rigidmd.core.dof import RigidBodyDOF


def test_time_steps():
    assert check_timestep(2) == 2.0 and isinstance(check_timestep(2), float)
    for bad in (0, -1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="timestep must be positive and finite"):
            check_timestep(bad)
    with pytest.raises(TypeError, match="timestep must be a number of ASE time units"):
        check_timestep("1 fs")


def test_one_number_rule_for_every_argument():
    """Bools and text are refused though ``float`` takes them; numpy scalars, 0-d arrays
    and fractions are read; the bound is each caller's."""
    from fractions import Fraction

    for good, value in ((3, 3.0), (np.float32(0.5), 0.5), (np.array(2.0), 2.0),
                        (Fraction(1, 4), 0.25), (-np.inf, -np.inf)):
        assert real_number("x", good, "a number") == value
    for bad in (True, np.bool_(False), "1e-6", b"1", None, [1.0], np.ones(2)):
        with pytest.raises(TypeError, match=r"^friction must be a number per ASE time unit, "
                                            r"got "):
            real_number("friction", bad, "a number per ASE time unit")
    for bad in (True, "2"):
        with pytest.raises(TypeError, match="^timestep must be a number of ASE time units"):
            check_timestep(bad)


def test_the_first_non_finite_atom_is_named():
    check_finite(np.ones((4, 3)), "force", "eV/Å")
    values = np.ones((4, 3))
    values[2, 1] = np.nan
    values[3, 0] = np.inf
    with pytest.raises(ValueError, match=r"atom 2 has a non-finite force \[1.0, nan, 1.0\] "
                                         r"\(eV/Å\) after step 5; 2 in all"):
        check_finite(values, "force", "eV/Å", "after step 5")
    with pytest.raises(ValueError, match=r"^cell vector 0 has a non-finite cell"):
        check_finite(np.full((3, 3), np.inf), "cell", "Å")


def test_a_massless_atom_with_momentum_is_refused():
    atoms = Atoms("OX", positions=np.zeros((2, 3)), masses=[16.0, 0.0])
    check_massless_momenta(atoms)
    atoms.arrays["momenta"] = np.array([[0.0, 0, 0], [0.0, 0.5, 0]])
    with pytest.raises(ValueError, match=r"atom 1 \(X\) has mass 0 but momentum \[0.0, 0.5, "
                                         r"0.0\] .* at the start: a massless atom"):
        check_massless_momenta(atoms, "at the start")


def test_only_fixcom_is_honoured():
    atoms = Atoms("H2", positions=np.zeros((2, 3)))
    assert check_constraints(atoms) is False
    atoms.constraints = [RigidBodyDOF(0), FixCom()]
    assert check_constraints(atoms) is True
    atoms.constraints = [FixAtoms(indices=[0])]
    with pytest.raises(ValueError, match="rigid-body dynamics cannot honour other ASE "
                                         "constraints"):
        check_constraints(atoms)


def test_changed_properties_and_copies_agree_with_ase():
    from ase.calculators.calculator import compare_atoms

    rng = np.random.default_rng(0)
    atoms = Atoms("H4", positions=rng.normal(size=(4, 3)), cell=np.eye(3) * 5, pbc=True)
    old = atoms.copy()
    assert changed_properties(old, atoms) == compare_atoms(old, atoms) == []
    atoms.positions[1, 2] += 1e-9
    atoms.cell[0, 0] += 1.0
    assert sorted(changed_properties(old, atoms)) == sorted(compare_atoms(old, atoms))
    kept = copy_atoms(atoms, old)
    assert kept is old and np.array_equal(kept.positions, atoms.positions)
    assert changed_properties(kept, atoms) == []
    other = Atoms("H5", positions=np.zeros((5, 3)))
    fresh = copy_atoms(other, old)
    assert fresh is not old and len(fresh) == 5
