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


def test_a_model_may_be_given_by_its_name():
    """``water_system(box, "tip4pew", 4.0)`` and ``water_topology("tip4pew", ...)`` failed
    with an AttributeError; the builders take a name, and so do these."""
    atoms = water_box(2, seed=1, model="tip4pew")
    top = water_topology("tip4pew", 2, np.eye(3) * 20.0)
    assert [a.name for a in top.atoms()] == ["O", "H1", "H2", "M"] * 2
    by_name = water_system(atoms, "TIP4P-Ew", 2.5, parameters="rigidmd")[1]
    by_model = water_system(atoms, water_model("tip4pew"), 2.5, parameters="rigidmd")[1]
    assert openmm.XmlSerializer.serialize(by_name) == openmm.XmlSerializer.serialize(by_model)
    with pytest.raises(ValueError, match="^unknown water model 'tip5p'"):
        water_system(atoms, "tip5p", 2.5)


def test_counts_and_cutoffs_are_checked_in_one_line():
    """``water_topology(model, 2.9, cell)`` built 2 residues and -1 none; a cut-off given as
    a string failed on a comparison with a bare TypeError."""
    model = water_model("tip3p")
    assert water_topology(model, 0, np.eye(3) * 20.0).getNumAtoms() == 0
    for n in (2.9, -1):
        with pytest.raises(ValueError, match=f"^rigidmd.openmm: n_molecules must be a whole "
                                             f"number >= 0, got {n}$"):
            water_topology(model, n, np.eye(3) * 20.0)
    atoms = water_box(2, seed=1)
    with pytest.raises(TypeError, match="^rigidmd.openmm: cutoff must be a finite number > 0 "
                                        "Å, got '2.5'$"):
        water_system(atoms, model, "2.5")
    with pytest.raises(ValueError, match="^rigidmd.openmm: cutoff must be a finite number > 0 "
                                         "Å, got -1.0$"):
        water_system(atoms, model, -1.0)


def test_the_cell_check_is_openmms():
    """The check let through 1e-12 relative: a cell with a_y = 1e-14 Å or b_x 1e-13 above
    a_x/2 passed it and OpenMM then refused it ("First periodic box vector must be
    parallel to x", "must be in reduced form").  OpenMM compares exactly; so does the
    check now, and a tilt of exactly half a length, which OpenMM takes, passes."""
    atoms = water_box(3, seed=1)
    tip3p = water_model("tip3p")
    length = atoms.cell[0, 0]
    for cell in ([[length, 1e-14, 0], [0, length, 0], [0, 0, length]],
                 [[length, 0, 0], [length / 2 * (1 + 1e-13), length, 0], [0, 0, length]]):
        bent = atoms.copy()
        bent.set_cell(cell)
        with pytest.raises(ValueError, match="OpenMM takes a cell in its reduced form"):
            water_system(bent, tip3p, 4.0)
    half = atoms.copy()
    half.set_cell([[length, 0, 0], [length / 2, length, 0], [-length / 2, length / 2, length]])
    _, system = water_system(half, tip3p, 3.0)
    openmm.Context(system, openmm.VerletIntegrator(1e-3),
                   openmm.Platform.getPlatformByName("Reference"))
