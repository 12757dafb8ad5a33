"""LAMMPS types and molecules of the atoms (rigidmd.lammps.atomtypes)."""

import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidVerlet
from rigidmd.lammps.atomtypes import (
    check_molecule_ids,
    lammps_molecule_ids,
    lammps_types,
    molecules_of,
)
from rigidmd.lammps.data import MASSLESS_SITE_MASS
from rigidmd.systems import water_cluster


def test_types_masses_and_labels():
    atoms = Atoms("OHHX", positions=np.zeros((4, 3)), masses=[16.0, 1.0, 2.0, 0.0])
    types, masses, labels = lammps_types(atoms, None)
    assert types.tolist() == [1, 2, 2, 3]
    assert masses == {1: 16.0, 2: 2.0, 3: MASSLESS_SITE_MASS}  # the largest; never 0
    assert labels == {1: "O", 2: "H", 3: "X"}
    types, masses, _ = lammps_types(atoms, {"H": 1, "O": 2, "X": 4})
    assert types.tolist() == [2, 1, 1, 4] and masses[3] == MASSLESS_SITE_MASS
    with pytest.raises(ValueError, match="element X has no LAMMPS type in atom_types"):
        lammps_types(atoms, {"O": 1, "H": 2})


def test_molecules_come_from_the_bodies_first():
    atoms = water_cluster(3, seed=1)
    assert molecules_of(atoms, None, None)[1] == "mol-id array"
    del atoms.arrays["mol-id"]
    assert molecules_of(atoms, None, None)[:2] == (None, None)
    ids = np.repeat([5, 6, 7], 3)
    molecules, source, _ = molecules_of(atoms, ids, None)
    assert source == "molecule_ids" and molecules.tolist() == ids.tolist()
    with pytest.raises(ValueError, match=r"molecule_ids has shape \(4,\), the atoms are 9"):
        molecules_of(atoms, np.ones(4, dtype=int), None)
    atoms.calc = TIP3P()
    RigidVerlet(atoms, 1 * units.fs, bodies="connectivity")
    molecules, source, checked = molecules_of(atoms, ids, None)
    assert source == "bodies" and molecules.tolist() == np.repeat([1, 2, 3], 3).tolist()
    assert checked is not None
    assert molecules_of(atoms, ids, checked)[2] == checked  # checked once
    atoms.arrays["mol-id"] = np.array([1, 1, 1, 1, 2, 2, 3, 3, 3])
    with pytest.raises(ValueError, match="mol-id array put atoms 2 and 3 in one molecule"):
        molecules_of(atoms, None, None)


def test_atoms_in_no_molecule_get_their_own_id():
    assert lammps_molecule_ids(None, 3).tolist() == [1, 2, 3]
    assert lammps_molecule_ids(np.array([2, 2, 0, -1, 1]), 5).tolist() == [2, 2, 3, 4, 1]


def test_given_molecule_ids_win_over_the_mol_id_array_and_tags():
    """An explicit ``molecule_ids`` was used only when the atoms carried neither a
    ``mol-id`` array nor tags, and its shape was then never checked."""
    atoms = water_cluster(3, seed=1)
    atoms.set_tags(np.repeat([1, 2, 3], 3))
    assert "mol-id" in atoms.arrays
    alone = check_molecule_ids(range(1, 10))
    molecules, source, _ = molecules_of(atoms, alone, None)
    assert source == "molecule_ids" and molecules.tolist() == list(range(1, 10))
    with pytest.raises(ValueError, match=r"^LAMMPSCalculator: molecule_ids has shape \(2,\), "
                                         r"the atoms are 9$"):
        molecules_of(atoms, check_molecule_ids([1, 2]), None)
    assert check_molecule_ids(None) is None
    assert check_molecule_ids([1.0, 2.0]).dtype == np.int64
    with pytest.raises(ValueError, match=r"^LAMMPSEngine: molecule_ids must be one whole "
                                         r"number per atom, got an array of shape \(1, 2\)"):
        check_molecule_ids([[1, 2]], "LAMMPSEngine")
    # In a rigid dynamics the bodies stay the molecules: given IDs must group alike.
    atoms.calc = TIP3P()
    RigidVerlet(atoms, 1 * units.fs, bodies="connectivity")
    with pytest.raises(ValueError, match="molecule_ids split a rigid body"):
        molecules_of(atoms, alone, None)
