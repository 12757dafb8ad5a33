"""OpenMM's topology and system of rigidmd's waters (rigidmd.openmm).

Energies and forces against rigidmd's own water models are in
``tests/physics/test_water_openmm.py``; here what the module builds and refuses."""

import numpy as np
import pytest

openmm = pytest.importorskip("openmm", reason="needs OpenMM (the test extra has it)")

from rigidmd.openmm import (  # noqa: E402
    FORCE_FIELD_FILES,
    real_atom_forces,
    water_system,
    water_topology,
)
from rigidmd.systems import water_box  # noqa: E402
from rigidmd.water import water_model  # noqa: E402

pytestmark = pytest.mark.openmm


def test_the_topology_has_the_models_sites():
    model = water_model("tip4pew")
    top = water_topology(model, 2, np.eye(3) * 20.0)
    assert [a.name for a in top.atoms()] == ["O", "H1", "H2", "M"] * 2
    assert top.getNumBonds() == 4
    box = top.getPeriodicBoxVectors()
    assert box[0][0].value_in_unit(openmm.unit.nanometer) == pytest.approx(2.0)


def test_a_system_with_rigidmds_parameters_and_force_groups():
    atoms = water_box(2, seed=1, model="tip4pew")
    model = water_model("tip4pew")
    top, system = water_system(atoms, model, 2.5, parameters="rigidmd")
    assert system.getNumParticles() == len(atoms) == 32
    nonbonded = next(f for f in system.getForces() if isinstance(f, openmm.NonbondedForce))
    assert nonbonded.getForceGroup() == 1
    assert all(f.getForceGroup() == 0 for f in system.getForces()
               if not isinstance(f, openmm.NonbondedForce))
    charge, sigma, epsilon = nonbonded.getParticleParameters(0)
    assert charge.value_in_unit(openmm.unit.elementary_charge) == pytest.approx(
        model.charges(1)[0])
    assert sigma.value_in_unit(openmm.unit.nanometer) == pytest.approx(model.sigma / 10)
    forces = real_atom_forces(system, np.ones((32, 3)))
    assert np.array_equal(forces[3::4], np.zeros((8, 3)))  # the M sites
    assert np.array_equal(forces[0::4], np.ones((8, 3)))


def test_what_openmm_cannot_take_is_refused():
    atoms = water_box(2, seed=1)
    tip3p = water_model("tip3p")
    assert set(FORCE_FIELD_FILES) == {"tip3p", "spce", "tip4pew", "opc"}
    with pytest.raises(ValueError, match="OpenMM ships no file for tip4p2005"):
        water_system(water_box(2, model="tip4p2005"), water_model("tip4p2005"), 2.5)
    with pytest.raises(ValueError, match="parameters must be 'file' or 'rigidmd', got 'x'"):
        water_system(atoms, tip3p, 2.5, parameters="x")
    with pytest.raises(ValueError, match=r"cutoff 4.0 Å must be positive and at most half the "
                                         r"cell's smallest width \(3.100 Å\)"):
        water_system(atoms, tip3p, 4.0)
    with pytest.raises(ValueError, match="molecule .* is split across the cell boundary"):
        water_system(water_box(2, seed=1, whole=False), tip3p, 2.5)
    skewed = atoms.copy()
    skewed.set_cell([[6.2, 0, 0], [4.0, 6.2, 0], [0, 0, 6.2]])
    with pytest.raises(ValueError, match="OpenMM takes a cell in its reduced form"):
        water_system(skewed, tip3p, 2.5)
    cluster = atoms.copy()
    cluster.pbc = False
    with pytest.raises(ValueError, match="the atoms need a periodic cell"):
        water_system(cluster, tip3p, 2.5)
