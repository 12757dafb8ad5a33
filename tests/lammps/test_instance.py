"""A LAMMPS instance set up for the atoms (rigidmd.lammps.instance)."""

import pytest
from helpers import PPPM_27, water_box_27

from rigidmd.lammps import LAMMPSCalculator, LammpsError
from rigidmd.lammps.instance import _encode, chosen_kspace

pytestmark = pytest.mark.lammps

PPPM_LOG = """PPPM initialization ...
  G vector (1/distance) = 0.2868
  grid = 9 9 9
  stencil order = 5
  estimated absolute RMS force accuracy = 1e-05
"""
EWALD_LOG = """Ewald initialization ...
  G vector (1/distance) = 0.31
  kxmax kymax kzmax  = 5 5 6
"""


def test_the_kspace_parameters_lammps_chose_are_read_from_its_log():
    assert chosen_kspace(PPPM_LOG) == "kspace_modify gewald 0.2868 mesh 9 9 9 order 5"
    assert chosen_kspace(EWALD_LOG) == "kspace_modify gewald 0.31 kmax/ewald 5 5 6"
    assert chosen_kspace("Neighbor list info ...") is None


def test_image_flags_are_packed_as_lammps_packs_them():
    assert _encode((0, 0, 0)) == 512 | (512 << 10) | (512 << 20)
    assert _encode((-1, 2, 0)) == 511 | (514 << 10) | (512 << 20)


def test_an_instance_is_set_up_once_and_closes_on_a_failed_command():
    atoms = water_box_27()
    calc = atoms.calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1, "H": 2})
    atoms.get_forces()
    instance = calc._instance
    assert instance.lmp is not None and instance.arrays is not None
    assert calc.kspace_parameters.startswith("kspace_modify gewald ")
    atoms.positions[0] += 0.01
    atoms.get_forces()
    assert calc._instance is instance  # the same atoms: the same instance
    with pytest.raises(LammpsError, match="LAMMPS command 'no_such_command' failed"):
        instance.execute(["no_such_command"])
    assert instance.lmp is None and instance.signature is None
    instance.close()  # idempotent
    assert instance.lmp is None
    atoms.positions[0] -= 0.01
    atoms.get_forces()  # a closed instance is replaced by a new one
    assert calc._instance is not instance and calc._instance.lmp is not None
