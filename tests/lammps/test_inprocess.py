"""rigidmd's LAMMPS calculator against native LAMMPS, and what it refuses.

The periodic liquid is ``tests/data/water_box_27.traj`` (27 TIP3P waters in a
9.3 Å box) with ``lj/cut/coul/long 4.5`` and PPPM_27 at 1e-5; native LAMMPS runs
``run 0`` of the same data file with ``neigh_modify exclude molecule/intra all``.
"""

import warnings

import numpy as np
import pytest
from ase import units
from helpers import PPPM_27, water_box_27, waters
from hypothesis_or_skip import given, settings, st

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.lammps import (
    LAMMPSCalculator,
    LammpsError,
    lammps_energy_forces,
    run_rigid_reference,
    tip3p_charges,
    tip3p_pair_commands,
)

pytestmark = pytest.mark.lammps


def native(atoms, commands=PPPM_27, **kwargs):
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    return lammps_energy_forces(atoms, body_ids,
                                list(commands) + ["neigh_modify exclude molecule/intra all"],
                                ase_constants=False, stress=atoms.pbc.all(), **kwargs)


def pinned(calc):
    """The commands with the k-space parameters ``calc`` fixed for its first cell.

    LAMMPSCalculator keeps them for later cells (as a native NPT run does); a fresh
    native LAMMPS at a later cell would choose them anew, and at the first cell the
    Ewald parameter it chose exactly is fixed as LAMMPS prints it (8 digits, 5e-7 eV
    on these 27 waters).
    """
    assert calc.kspace_parameters.startswith("kspace_modify gewald ")
    return PPPM_27 + [calc.kspace_parameters]


def assert_native(atoms):
    atoms.get_potential_energy()
    energy, forces, stress = native(atoms, pinned(atoms.calc))
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-9)
    np.testing.assert_allclose(atoms.get_forces(), forces, rtol=0, atol=1e-7)
    np.testing.assert_allclose(atoms.get_stress(), stress, rtol=0,
                               atol=1e-8 * np.abs(stress).max())


def test_energy_forces_and_stress_equal_native_lammps():
    """Measured: energy equal to the last bit, forces 1e-15 eV/Å, stress 1e-15 relative;
    after moves, a 1 % scaling of the cell and a triclinic tilt, the same."""
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    assert_native(atoms)
    rng = np.random.default_rng(0)
    for _ in range(3):  # moved atoms, some across the faces: no new set-up
        atoms.positions += rng.normal(scale=0.05, size=atoms.positions.shape)
        assert_native(atoms)
    atoms.set_cell(atoms.cell * 1.01, scale_atoms=True)
    assert_native(atoms)
    cell = atoms.cell.array.copy()
    cell[1, 0] += 0.6
    cell[2, 1] -= 0.4
    atoms.set_cell(cell, scale_atoms=True)
    assert_native(atoms)
    atoms.set_cell(atoms.cell * 0.995, scale_atoms=True)  # a triclinic cell changes
    assert_native(atoms)


def test_a_cell_not_in_lammps_form_is_rotated():
    """A cell whose first vector is not along x: rotated into LAMMPS's frame and back."""
    atoms = water_box_27()
    reference = atoms.copy()
    reference.calc = LAMMPSCalculator(PPPM_27)
    rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    rotation *= np.sign(np.linalg.det(rotation))
    atoms.set_cell(atoms.cell.array @ rotation.T)
    atoms.positions = atoms.positions @ rotation.T
    atoms.calc = LAMMPSCalculator(PPPM_27)
    assert atoms.get_potential_energy() == pytest.approx(reference.get_potential_energy(),
                                                         rel=1e-10)
    np.testing.assert_allclose(atoms.get_forces(), reference.get_forces() @ rotation.T,
                               atol=1e-9)
    stress = atoms.get_stress(voigt=False)
    np.testing.assert_allclose(stress, rotation @ reference.get_stress(voigt=False) @ rotation.T,
                               atol=1e-10)


def test_a_cluster_equals_native_lammps():
    atoms = waters(8)
    atoms.set_initial_charges(tip3p_charges(atoms))
    commands = tip3p_pair_commands(40.0)[:-1]  # without the exclusion: the calculator's job
    atoms.calc = LAMMPSCalculator(commands, atom_types={"O": 1, "H": 2})
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    energy, forces = lammps_energy_forces(atoms, body_ids, tip3p_pair_commands(40.0),
                                          ase_constants=False)
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-12)
    np.testing.assert_allclose(atoms.get_forces(), forces, atol=1e-12)
    with pytest.raises(Exception, match="stress"):
        atoms.get_stress()


def test_molecules_come_from_mol_id_tags_argument_or_bodies():
    atoms = water_box_27()
    tags = atoms.get_tags()
    probe = atoms.copy()
    probe.calc = LAMMPSCalculator(PPPM_27)
    probe.get_potential_energy()
    energy = native(atoms, pinned(probe.calc))[0]
    for source in ("tags", "mol-id", "argument", "bodies"):
        a = atoms.copy()
        a.set_tags(0)
        kwargs = {}
        if source == "tags":
            a.set_tags(tags)
        elif source == "mol-id":
            a.arrays["mol-id"] = tags
        elif source == "argument":
            kwargs["molecule_ids"] = tags
        a.calc = LAMMPSCalculator(PPPM_27, **kwargs)
        if source == "bodies":
            RigidVerlet(a, units.fs, bodies=RigidBodies.from_body_ids(tags - 1))
        assert a.get_potential_energy() == pytest.approx(energy, rel=1e-9), source
    # Without molecules nothing is excluded, and the calculator says so.
    a = atoms.copy()
    a.set_tags(0)
    a.calc = LAMMPSCalculator(PPPM_27)
    with pytest.warns(UserWarning, match="no pair is excluded"):
        assert a.get_potential_energy() != pytest.approx(energy, rel=1e-3)


def test_bad_input_is_refused_before_lammps_starts():
    atoms = water_box_27()
    with pytest.raises(ValueError, match="need a pair_style"):
        LAMMPSCalculator(["pair_coeff * * 0 1"])
    a = atoms.copy()
    a.set_initial_charges(np.zeros(len(a)))
    a.calc = LAMMPSCalculator(PPPM_27)
    with pytest.raises(ValueError, match="Coulomb interactions but the atoms have no charges"):
        a.get_forces()
    a = atoms.copy()
    a.calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1})
    with pytest.raises(ValueError, match="element H has no LAMMPS type"):
        a.get_forces()


def test_lammps_errors_carry_lammps_message_and_the_calculator_recovers():
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27[:-1] + ["kspace_style pppm 1e-5", "pair_coeff 7 7 1 1"])
    with pytest.raises(LammpsError, match="pair_coeff 7 7 1 1.* failed: ERROR"):
        atoms.get_forces()
    atoms.calc = calc = LAMMPSCalculator(PPPM_27)
    good = atoms.get_forces().copy()
    # An atom ten cell vectors away is the same system: shifted back before LAMMPS sees it
    # (LAMMPS wraps by one box and lost it before).  Measured 1.8e-14 eV/Å from the forces
    # in place (its position carries 93 Å x 1e-16 of roundoff); bound 1e-12.
    atoms.positions[0] += 10 * atoms.cell.lengths()
    np.testing.assert_allclose(atoms.get_forces(), good, rtol=0, atol=1e-12)
    atoms.positions = water_box_27().positions
    # A changed number of atoms: a new instance, no error.
    atoms.calc = calc
    smaller = atoms[:-3]
    smaller.calc = calc
    assert np.isfinite(smaller.get_potential_energy())


def test_rigid_verlet_follows_native_fix_rigid_nve_small_with_pppm():
    """The same standard as the cluster validation: a roundoff-level gap grown by chaos."""
    atoms = water_box_27()
    atoms.positions = RigidBodies.resolve(atoms, "tags").whole_positions(atoms)
    rigid_maxwell_boltzmann(atoms, 300, bodies="tags", rng=np.random.default_rng(3))
    body_ids = RigidBodies.resolve(atoms, "tags").body_ids
    probe = atoms.copy()
    probe.calc = LAMMPSCalculator(PPPM_27, ase_constants=True)
    probe.get_potential_energy()
    reference = run_rigid_reference(
        atoms, body_ids, pinned(probe.calc) + ["neigh_modify exclude molecule/intra all"],
        units.fs, 500,
        every=100, fix="rigid/nve/small", charges=atoms.get_initial_charges())
    a = atoms.copy()
    # ASE's constants on both sides (rigidmd integrates in ASE units).
    a.calc = LAMMPSCalculator(PPPM_27, ase_constants=True)
    dyn = RigidVerlet(a, units.fs, bodies="tags")
    positions = []
    dyn.attach(lambda: positions.append(a.positions.copy()), interval=100)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dyn.run(500)
    gap = np.abs(np.array(positions) - reference.positions).max(axis=(1, 2))
    # Measured: 1.8e-14 Å at step 100, 5.2e-13 Å at step 500, energies within
    # 6e-14 eV (the ASE-TIP3P clusters: 4e-14 and 1e-10 Å); bounds leave 1e3 for
    # the chaos on other CPUs.
    assert gap[1] < 1e-11
    assert gap[5] < 1e-9


def test_npt_conserved_energy_with_pppm_and_a_moving_cell():
    """The k-space parameters stay those of the first cell, so the energy is continuous.

    64 TIP4P/2005 waters (explicit M), PPPM_27 1e-5, tail corrections, C-rescale moving the
    cell every 1 fs step for 400 steps just after a quench.  Measured: the conserved
    energy spans 0.054 eV, as NVE from the same start (0.052 eV); with the parameters
    chosen anew at each cell (a full LAMMPS set-up) it spanned 18 eV.  Bound 0.1 eV.
    """
    from rigidmd import RigidCRescale, RigidLangevin
    from rigidmd.systems import water_box
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    atoms = water_box(4, seed=2, model="tip4p2005")
    atoms.set_initial_charges(model.charges(64))
    atoms.calc = LAMMPSCalculator(model.lammps_commands(6.0, "pppm", 1e-5, tail=True),
                                  atom_types={"O": 1, "H": 2, "X": 3})
    RigidLangevin(atoms, 0.5 * units.fs, temperature_K=300, friction=0.05 / units.fs,
                  rng=np.random.default_rng(1), fixcm=False).run(300)
    volume = atoms.get_volume()
    dyn = RigidCRescale(atoms, units.fs, 300, units.bar, taut=100 * units.fs,
                        taup=500 * units.fs, compressibility_au=4.5e-5 / units.bar,
                        rng=np.random.default_rng(5))
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=5)
    dyn.run(400)
    assert abs(atoms.get_volume() / volume - 1) > 1e-3  # the cell did move
    assert atoms.calc.kspace_parameters.startswith("kspace_modify gewald ")
    assert np.ptp(energies) < 0.1, np.ptp(energies)


def test_check_state_finds_what_ases_comparison_finds(monkeypatch):
    """The calculator's own check_state (a faster comparison) against ASE's compare_atoms:
    the same changes for moved atoms (by 1e-3 Å and by roundoff below the 1e-15
    tolerance), a new cell, pbc, charges, elements, a new array, an atom moved to an
    infinity and fewer atoms."""
    import ase.calculators.calculator as ase_calculator
    from ase.calculators.calculator import compare_atoms

    from rigidmd.core.checks import changed_properties

    atoms = water_box_27()
    calc = LAMMPSCalculator(PPPM_27)
    calc.atoms = atoms.copy()

    def changed(edit):
        a = atoms.copy()
        edit(a)
        fast = changed_properties(calc.atoms, a, 1e-15)
        assert fast is None or sorted(fast) == sorted(calc.check_state(a))
        return sorted(calc.check_state(a)), sorted(compare_atoms(calc.atoms, a))

    edits = [lambda a: None,
             lambda a: a.positions.__setitem__((3, 1), a.positions[3, 1] + 1e-3),
             lambda a: a.positions.__setitem__((3, 1), a.positions[3, 1] * (1 + 2e-16)),
             lambda a: a.set_cell(a.cell * 1.01),
             lambda a: a.set_pbc([True, False, True]),
             lambda a: a.set_initial_charges(-a.get_initial_charges()),
             lambda a: a.numbers.__setitem__(0, 8 if a.numbers[0] != 8 else 1),
             lambda a: a.set_initial_magnetic_moments(np.ones(len(a))),
             lambda a: a.positions.__setitem__((3, 1), np.inf),  # (stale forces before)
             lambda a: a.pop()]
    found = [changed(edit) for edit in edits]
    for mine, ases in found:
        assert mine == ases
    a = atoms.copy()  # for atoms alike the calculator does not ask ASE
    a.positions[0, 0] += 0.1
    monkeypatch.setattr(ase_calculator, "compare_atoms", None)
    assert calc.check_state(a) == ["positions"]
    monkeypatch.undo()
    a.pop()
    assert changed_properties(calc.atoms, a, 1e-15) is None
    assert [mine for mine, _ in found[:4]] == [[], ["positions"], [], ["cell"]]


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12),
       edit=st.sampled_from(["same", "roundoff", "moved", "inf", "-inf", "nan", "inf both",
                             "inf both, roundoff"]))
def test_the_compiled_comparison_is_numpys(seed, n, edit):
    """changed_properties' compiled test of a float array (rigidmd.core._numba.equal_or_close)
    says what ``numpy.allclose(a, b, rtol=tol, atol=tol)`` says (and the NumPy path, which
    asks it): for equal arrays, changes below and above the tolerance, an atom moved to an
    infinity (a change: the same forces were returned before), NaNs, and infinities in both
    arrays with roundoff elsewhere."""
    from rigidmd.core import _numba

    rng = np.random.default_rng(seed)
    a = rng.normal(scale=10.0, size=n)
    b = a.copy()
    k = rng.integers(n)
    if edit == "roundoff":
        b[k] *= 1 + 2e-16
    elif edit == "moved":
        b[k] += 1e-3
    elif edit in ("inf", "-inf", "nan"):
        b[k] = {"inf": np.inf, "-inf": -np.inf, "nan": np.nan}[edit]
    elif edit.startswith("inf both"):
        a[k] = b[k] = np.inf
        if edit.endswith("roundoff"):
            b[rng.integers(n)] *= 1 + 2e-16
    tol = 1e-15
    expected = bool(np.allclose(a, b, rtol=tol, atol=tol))
    assert _numba.equal_or_close(a, b, tol) == expected
    if edit in ("moved", "inf", "-inf", "nan"):
        assert not expected


def test_the_calculators_copy_of_the_atoms_is_a_copy():
    """copy_atoms (the calculator's calc.atoms, rewritten in place when it fits) holds what
    Atoms.copy holds: arrays, cell, pbc, info and constraints equal and not shared; a copy
    that no longer fits (an array added, another size) is made anew, and the calculator's
    copy stays its own through a dynamics (its check_state finds no change after a call)."""
    from rigidmd.core.checks import copy_atoms
    from rigidmd.core.dof import RigidBodyDOF

    atoms = water_box_27()
    atoms.info["note"] = "x"
    atoms.set_constraint(RigidBodyDOF(6, np.repeat(np.arange(1, 28), 3)))
    previous = atoms.copy()
    atoms.positions += 0.3
    atoms.set_cell(atoms.cell * 1.01, scale_atoms=False)
    atoms.set_pbc([True, False, True])
    atoms.set_celldisp([0.5, -0.25, 1.0])
    copied = copy_atoms(atoms, previous)
    assert copied is previous
    for name, array in atoms.arrays.items():
        np.testing.assert_array_equal(copied.arrays[name], array)
        assert not np.shares_memory(copied.arrays[name], array)
    np.testing.assert_array_equal(copied.cell.array, atoms.cell.array)
    np.testing.assert_array_equal(copied.pbc, atoms.pbc)
    np.testing.assert_array_equal(copied.get_celldisp(), atoms.get_celldisp())
    assert not np.shares_memory(copied.pbc, atoms.pbc)
    assert copied.info == atoms.info and copied.info is not atoms.info
    (dof,) = copied.constraints
    assert dof is not atoms.constraints[0] and dof.removed_dof == 6
    np.testing.assert_array_equal(dof.body_ids, atoms.constraints[0].body_ids)
    assert not np.shares_memory(dof.body_ids, atoms.constraints[0].body_ids)
    atoms.set_initial_magnetic_moments(np.ones(len(atoms)))  # another array: a new copy
    assert copy_atoms(atoms, previous) is not previous
    assert copy_atoms(atoms[:-3], previous) is not previous  # another size
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    RigidVerlet(atoms, units.fs, bodies="tags").run(2)
    assert atoms.calc.atoms is not atoms and atoms.calc.check_state(atoms) == []


def test_atoms_sorted_by_lammps_at_every_step_keep_their_forces():
    """LAMMPS re-orders its atoms when it sorts them (by default every 1000 steps) and the
    calculator maps them by ID after every step; ``atom_modify sort 1 1.0`` sorts at every
    re-neighbouring step.  A 40-step NVE run (1 fs, 300 K: several re-neighbourings) with
    that sorting equals the run without it.  Measured: positions 1.8e-15 Å apart (sorted
    atoms sum their pairs in another order: roundoff); bound 1e-9 Å.  Forces mapped with
    the order of the step before (no re-reading of the IDs after a step) scramble the run:
    LAMMPS loses 12 of the 81 atoms."""
    start = water_box_27()
    start.positions = RigidBodies.resolve(start, "tags").whole_positions(start)
    rigid_maxwell_boltzmann(start, 300, bodies="tags", rng=np.random.default_rng(5))
    runs = []
    for extra in ([], ["atom_modify sort 1 1.0"]):
        atoms = start.copy()
        atoms.calc = LAMMPSCalculator(PPPM_27 + extra)
        RigidVerlet(atoms, units.fs, bodies="tags").run(40)
        runs.append(atoms.positions.copy())
    np.testing.assert_allclose(runs[1], runs[0], rtol=0, atol=1e-9)
