"""The LAMMPS helpers themselves: data files, single-point energies, errors."""

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from ase.io import read

from rigidmd import RigidBodies
from rigidmd.lammps import (
    lammps_energy_forces,
    load_lammps,
    run_rigid_reference,
    tip3p_charges,
    tip3p_pair_commands,
    write_data,
)
from rigidmd.systems import water_box, water_cluster

pytestmark = pytest.mark.lammps


def test_load_lammps_has_the_rigid_package():
    lmp = load_lammps()
    try:
        assert lmp.version() >= 20240829
        for style in ("rigid", "rigid/nve", "rigid/nve/small"):
            assert lmp.has_style("fix", style)
    finally:
        lmp.close()


def test_energy_and_forces_match_ase_tip3p():
    atoms = water_cluster(8, seed=2)
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    energy, forces = lammps_energy_forces(atoms, body_ids, tip3p_pair_commands(40.0),
                                          charges=tip3p_charges(atoms))
    atoms.calc = TIP3P(rc=40.0)
    # With ASE's constants (the default) both sum the same terms: measured 4e-15.
    assert energy == pytest.approx(atoms.get_potential_energy(), abs=1e-10)
    np.testing.assert_allclose(forces, atoms.get_forces(), atol=1e-10)


def test_periodic_data_file_keeps_molecules_whole(tmp_path):
    atoms = water_box(3, seed=4, whole=False)  # wrapped: molecules straddle the faces
    atoms.set_velocities(np.random.default_rng(0).normal(size=(81, 3)) * 0.01)
    rigid = RigidBodies.resolve(atoms, "mol-id")
    data = write_data(atoms, rigid.body_ids, tmp_path / "box.data", charges=tip3p_charges(atoms),
                      ase_constants=False)
    back = read(tmp_path / "box.data", format="lammps-data", atom_style="full", units="metal")
    np.testing.assert_array_equal(back.arrays["mol-id"], rigid.body_ids + 1)
    # ASE's reader converts g/mol and Å/ps with its own constants (2.6e-10 off
    # for masses); the file itself holds our values to all digits.
    np.testing.assert_allclose(back.get_masses(), atoms.get_masses(), rtol=1e-9)
    np.testing.assert_allclose(back.get_velocities(), atoms.get_velocities(), rtol=1e-8)
    # ASE's reader applies the image flags: the molecules come back whole.
    np.testing.assert_allclose(back.positions, rigid.whole_positions(atoms), atol=1e-12)
    # In the file itself every atom is inside the box.
    rows = (tmp_path / "box.data").read_text().split("Atoms # full")[1].split("Velocities")[0]
    xyz = np.array([[float(v) for v in row.split()[4:7]] for row in rows.strip().splitlines()])
    assert np.all((xyz >= 0) & (xyz < 9.3))
    assert data.boundary == "p p p"


def test_reference_run_refuses_bad_input():
    atoms = water_cluster(2)
    with pytest.raises(ValueError, match="fix must be one of"):
        run_rigid_reference(atoms, [0, 0, 0, 1, 1, 1], tip3p_pair_commands(), units.fs, 1,
                            fix="rigid/xyz", charges=tip3p_charges(atoms))
    with pytest.raises(ValueError, match="does not match the couplings, which need rigid/nve"):
        run_rigid_reference(atoms, [0, 0, 0, 1, 1, 1], tip3p_pair_commands(), units.fs, 1,
                            fix="rigid/nvt", charges=tip3p_charges(atoms))
    with pytest.raises(ValueError, match="temperature_K and tdamp go together"):
        run_rigid_reference(atoms, [0, 0, 0, 1, 1, 1], tip3p_pair_commands(), units.fs, 1,
                            fix="rigid/nvt", charges=tip3p_charges(atoms), temperature_K=300)
    with pytest.raises(ValueError, match="one atom"):
        run_rigid_reference(atoms, [0, 0, 0, 1, 1, 2], tip3p_pair_commands(), units.fs, 1,
                            charges=tip3p_charges(atoms))
    with pytest.raises(ValueError, match="body_ids must have shape"):
        write_data(atoms, [0, 0, 0], "never.data")
