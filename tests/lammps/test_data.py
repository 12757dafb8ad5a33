"""LAMMPS data files of rigid bodies (rigidmd.lammps.data).

Energies of the files written here against ASE are in ``test_reference.py``."""

import numpy as np
import pytest
from ase import Atoms

from rigidmd.lammps.data import (
    MASSLESS_SITE_MASS,
    atom_types_of,
    check_body_ids,
    write_data,
)
from rigidmd.systems import water_cluster


def test_body_ids_are_checked():
    atoms = Atoms("H3", positions=np.zeros((3, 3)))
    assert check_body_ids(atoms, [0, 0, -1]).dtype == np.int64
    assert check_body_ids(atoms, np.array([0.0, 1.0, -1.0])).tolist() == [0, 1, -1]
    with pytest.raises(ValueError, match=r"body_ids must have shape \(3,\), got \(2,\)"):
        check_body_ids(atoms, [0, 0])
    with pytest.raises(ValueError, match="body_ids must be integers"):
        check_body_ids(atoms, [0, 0.5, 1])
    with pytest.raises(ValueError, match="body_ids must be >= -1"):
        check_body_ids(atoms, [0, -2, 1])


def test_one_type_per_label_and_mass():
    atoms = Atoms("OHHOHX", positions=np.zeros((6, 3)),
                  masses=[16.0, 1.0, 1.0, 16.0, 2.0, 0.0])
    labels, masses, types = atom_types_of(atoms)
    assert labels == {"O": 1, "H_1": 2, "H_2": 3, "X": 4}
    assert masses.tolist() == [16.0, 1.0, 2.0, MASSLESS_SITE_MASS]
    assert types.tolist() == [1, 2, 2, 1, 3, 4]
    labels, _, _ = atom_types_of(atoms, ["Ow", "Hw", "Hw", "Oc", "Hd", "M"])
    assert list(labels) == ["Ow", "Hw", "Oc", "Hd", "M"]
    with pytest.raises(ValueError, match=r"type_labels must have one label per atom \(6\), "
                                         "got 2"):
        atom_types_of(atoms, ["a", "b"])


def test_a_cluster_file(tmp_path):
    atoms = water_cluster(2, seed=1)
    atoms.append("Ne")
    atoms.positions[-1] = [8.0, 0.0, 0.0]
    charges = np.r_[np.tile([-0.834, 0.417, 0.417], 2), 0.0]
    data = write_data(atoms, [0, 0, 0, 1, 1, 1, -1], tmp_path / "w.data", charges, margin=10.0)
    assert data.boundary == "f f f" and data.n_body_ids == 2
    assert data.molecule_ids.tolist() == [1, 1, 1, 2, 2, 2, 3]
    assert data.types == {"O": 1, "H": 2, "Ne": 3}
    assert np.allclose(data.charges, charges * data.charge_factor)
    text = data.path.read_text()
    assert "7 atoms" in text and "3 atom types" in text and "Atom Type Labels" in text
    lo = atoms.positions.min(axis=0) - 10.0
    assert f"{lo[0]:.17g}"[:8] in text  # the box: the atoms plus the margin
