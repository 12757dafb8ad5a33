"""What a rigid filter hands ASE besides coordinates and forces (rigidmd.relax.facade)."""

import numpy as np
from ase.calculators.tip3p import TIP3P
from ase.io import Trajectory, read

from rigidmd.relax import RigidFilter
from rigidmd.relax.facade import AtomsFacade
from rigidmd.systems import water_box


def test_the_filter_answers_with_the_real_atoms(tmp_path):
    atoms = water_box(2, seed=1)
    atoms.calc = TIP3P(rc=4.0)
    view = RigidFilter(atoms)
    assert isinstance(view, AtomsFacade)
    assert view.calc is atoms.calc and view.get_calculator() is atoms.calc
    assert np.array_equal(view.get_cell(), atoms.get_cell())
    assert np.array_equal(view.get_pbc(), atoms.get_pbc())
    assert view.get_chemical_symbols() == atoms.get_chemical_symbols()
    assert view.has("masses") == atoms.has("masses")
    assert list(view.iterimages()) == [atoms]
    optimizable = view.__ase_optimizable__()
    assert optimizable.ndofs() == 3 * len(view)
    with Trajectory(tmp_path / "r.traj", "w", view) as traj:
        traj.write()
    assert len(read(tmp_path / "r.traj")) == len(atoms)  # the atoms, not the rows
