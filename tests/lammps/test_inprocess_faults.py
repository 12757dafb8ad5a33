"""Faults of the LAMMPS calculator found from outside (issue 22), each held by a test.

The periodic liquid is ``tests/data/water_box_27.traj`` (27 TIP3P waters in a
9.3 Å box) with ``lj/cut/coul/long 4.5`` and PPPM_27 at 1e-5, as in
``lammps/test_calculator.py``.
"""

import subprocess
import sys
import warnings

import numpy as np
import pytest
from ase import units
from ase.calculators.calculator import Calculator, all_changes
from ase.io import write
from helpers import PPPM_27, lammps_instances, water_box_27

import rigidmd.lammps.inprocess as lammps_calculator
from rigidmd import RigidBodies, RigidNPT, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core.checkpoint import save_checkpoint
from rigidmd.lammps import LAMMPSCalculator
from rigidmd.lammps.engine import reduce_tilt
from rigidmd.run.restart import load_checkpoint
from rigidmd.systems import water_box
from rigidmd.water import water_model

pytestmark = pytest.mark.lammps


class FreshLAMMPS(Calculator):
    """A new LAMMPSCalculator at every call, with given k-space parameters: the reference
    for one instance that follows a moving cell (same interactions, nothing carried over)."""

    implemented_properties = ["energy", "free_energy", "forces", "stress"]

    def __init__(self, kspace_parameters):
        super().__init__()
        self.kspace_parameters = kspace_parameters

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        atoms = self.atoms.copy()
        atoms.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=self.kspace_parameters)
        self.results = {name: atoms.calc.get_property(name, atoms)
                        for name in self.implemented_properties}


def npt_run(atoms, couple, steps=40):
    dyn = RigidNPT(atoms, units.fs, 300, units.bar, 50 * units.fs, 200 * units.fs,
                   couple=couple, bodies="tags")
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=1)
    dyn.run(steps)
    return np.array(energies)


@pytest.mark.parametrize(("couple", "rotated"), [("tri", False), ("tri", True),
                                               ("aniso", True)])
def test_a_moving_cell_keeps_one_instance_and_its_kspace_parameters(monkeypatch, couple,
                                                                     rotated):
    """couple="tri" shears the cell (an orthogonal one becomes triclinic; a rotated one
    turns LAMMPS's frame at every step, as "aniso" does on a rotated cell).  Before: a
    new LAMMPS at every step (41 in 40), each choosing its own k-space parameters, and
    a conserved energy spanning 1.4-3.3 eV over 100 steps.  Now one instance, and each
    step's conserved energy equals that of a run with a fresh LAMMPS at every step
    given the first cell's parameters: measured at most 1.1e-13 eV apart over 40 steps (each
    case); bound 1e-9 eV, room for roundoff grown by chaos on other CPUs.  The
    conserved energy spans 0.024-0.032 eV over 40 steps, as in couple="iso" runs (0.03 eV
    over 100 steps; the 4.5 Å cut-off is abrupt); bound 0.1 eV."""
    atoms = water_box_27(300)
    if rotated:
        rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
        rotation *= np.sign(np.linalg.det(rotation))
        atoms.set_cell(atoms.cell.array @ rotation.T)
        atoms.positions = atoms.positions @ rotation.T
        atoms.set_momenta(atoms.get_momenta() @ rotation.T)
    reference = atoms.copy()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    count = lammps_instances(monkeypatch, lammps_calculator)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the step-size advice of a hot, small box
        energies = npt_run(atoms, couple)
    assert count() == 1
    if not rotated:
        assert abs(atoms.cell.array[1, 0]) + abs(atoms.cell.array[0, 1]) > 1e-3  # it sheared
    reference.calc = FreshLAMMPS(atoms.calc.kspace_parameters)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = npt_run(reference, couple)
    np.testing.assert_allclose(energies, expected, rtol=0, atol=1e-9)
    assert np.ptp(energies) < 0.1, np.ptp(energies)


def test_any_cell_change_equals_a_fresh_lammps_with_the_same_kspace_parameters(monkeypatch):
    """Large jumps of the cell in one instance: an orthogonal box tilted past LAMMPS's
    old tilt limits (it becomes triclinic), the tilt reversed, the whole system turned.
    Each call equals a fresh LAMMPS given the first cell's k-space parameters: measured
    2e-16 relative in energy, 2e-16 in forces and 1.3e-15 in stress (relative to the
    largest component; the largest tilt squeezes molecules to +1900 eV); bounds 1e-9.
    Before the fix, a tilt or a turn started a new LAMMPS, which chose other parameters
    (energies 1e-3-1 eV apart); a change of the tilt by 2 box lengths lost atoms (the
    previous image flags kept)."""
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    count = lammps_instances(monkeypatch, lammps_calculator)
    atoms.get_potential_energy()
    parameters = atoms.calc.kspace_parameters
    lengths = atoms.cell.lengths()
    turn = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))[0]
    turn *= np.sign(np.linalg.det(turn))
    for shear, rotation in ((0.3, None), (1.3, None), (-0.8, None), (-0.8, turn), (0.2, turn)):
        cell = np.diag(lengths)
        cell[1, 0], cell[2, 0], cell[2, 1] = shear * lengths[0], -0.4 * shear * lengths[0], \
            0.7 * shear * lengths[1]
        if rotation is not None:
            cell = cell @ rotation.T
        atoms.set_cell(cell, scale_atoms=True)
        fresh = atoms.copy()
        fresh.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=parameters)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # LAMMPS: "Triclinic box skew is large"
            energy, forces, stress = (fresh.get_potential_energy(), fresh.get_forces(),
                                      fresh.get_stress())
        assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-9, abs=0)
        np.testing.assert_allclose(atoms.get_forces(), forces, rtol=0,
                                   atol=1e-9 * np.abs(forces).max())
        np.testing.assert_allclose(atoms.get_stress(), stress, rtol=0,
                                   atol=1e-9 * np.abs(stress).max())
    assert count() == 5 + 1  # the fresh ones, and one for atoms


@pytest.mark.parametrize("boxes", [2, 5, 25])
def test_a_large_tilt_gives_the_numbers_of_the_same_lattice_in_its_reduced_basis(boxes):
    """The lattice of the orthogonal box given with b = (boxes L, L, 0): before the fix LAMMPS
    took that basis as it was, and PPPM's mesh followed it, so the energy was off by 0.088 eV
    at 2 L, 3.2 eV at 5 L and 6.9 eV at 25 L; now the basis is reduced first (as the engine
    does), and energy, forces and stress (turned back to the user's frame) equal those of
    the orthogonal box, which is the reduced basis.  Measured: equal to the last bit; turned
    into another frame, forces and stress 7e-14, 1.4e-13 and 6e-13 relative to the largest
    (2, 5 and 25 L: the turn's roundoff grows with the tilt), energy 7e-16.  Bounds: 1e-13
    (the engine's), turned 1e-11."""
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    energy, forces, stress = (atoms.get_potential_energy(), atoms.get_forces(),
                              atoms.get_stress())
    parameters = atoms.calc.kspace_parameters
    length = atoms.cell.array[0, 0]
    turn = np.linalg.qr(np.random.default_rng(7).normal(size=(3, 3)))[0]
    turn *= np.sign(np.linalg.det(turn))
    for rotation in (None, turn):
        cell = atoms.cell.array.copy()
        cell[1, 0] = boxes * length
        sheared = atoms.copy()  # the same positions, the same lattice
        sheared.set_cell(cell if rotation is None else cell @ rotation.T)
        if rotation is not None:
            sheared.positions = sheared.positions @ rotation.T
        sheared.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=parameters)
        assert sheared.get_potential_energy() == pytest.approx(energy, rel=1e-13, abs=0)
        back, bound = (np.eye(3), 1e-13) if rotation is None else (rotation, 1e-11)
        np.testing.assert_allclose(sheared.get_forces() @ back, forces, rtol=0,
                                   atol=bound * np.abs(forces).max())
        full = back.T @ sheared.get_stress(voigt=False) @ back
        np.testing.assert_allclose(full, atoms.get_stress(voigt=False), rtol=0,
                                   atol=bound * np.abs(stress).max())


def test_a_cell_sheared_through_several_flips_in_one_instance_equals_its_reduced_basis():
    """One instance follows a shear of b from 0.3 L to 2.7 L and back to -1.6 L (the
    reduced basis flips at each half box): each call equals a fresh LAMMPS given the
    reduced basis of the same lattice (the positions scaled with the cell).  Measured
    (relative; forces and stress to the largest component): energy 1.9e-16, forces 2e-16,
    stress 2.6e-15; bounds 1e-13."""
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    atoms.get_potential_energy()
    parameters = atoms.calc.kspace_parameters
    length, lengths = atoms.cell.array[0, 0], atoms.cell.lengths()
    for shear in (0.3, 0.6, 1.4, 2.7, 0.45, -0.55, -1.6):
        cell = np.diag(lengths)
        cell[1, 0], cell[2, 0], cell[2, 1] = shear * length, 0.3 * shear * length, \
            -0.7 * shear * length
        atoms.set_cell(cell, scale_atoms=True)
        reduced = atoms.copy()
        reduced.set_cell(reduce_tilt(cell)[0])
        tilts = reduced.cell.array[[1, 2, 2], [0, 0, 1]]
        assert np.abs(tilts).max() <= 0.5 * length + 1e-12
        reduced.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=parameters)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (LAMMPS: "Triclinic box skew is large")
            energy, forces, stress = (reduced.get_potential_energy(), reduced.get_forces(),
                                      reduced.get_stress())
            got = atoms.get_potential_energy(), atoms.get_forces(), atoms.get_stress()
        assert got[0] == pytest.approx(energy, rel=1e-13, abs=0), shear
        np.testing.assert_allclose(got[1], forces, rtol=0, atol=1e-13 * np.abs(forces).max())
        np.testing.assert_allclose(got[2], stress, rtol=0, atol=1e-13 * np.abs(stress).max())


def test_an_npt_run_continues_with_the_kspace_parameters_it_had(tmp_path):
    """Before: the continued run chose new k-space parameters at the checkpoint's cell
    and its potential and conserved energies jumped (7.7e-4 eV here after 30 steps at
    5 kbar; 0.7-1.2 eV in longer runs).  Now the checkpoint holds them and the
    continuation equals the uninterrupted run: measured identical; bound 1e-9 eV."""
    atoms = water_box_27(300)
    atoms.calc = LAMMPSCalculator(PPPM_27)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dyn = RigidNPT(atoms, units.fs, 300, 5000 * units.bar, 50 * units.fs,
                       100 * units.fs, couple="aniso", bodies="tags")
        dyn.run(30)
        save_checkpoint(dyn, tmp_path / "c.npz")
        first = atoms.calc.kspace_parameters
        energies = []
        dyn.attach(lambda: energies.append(atoms.get_potential_energy()), interval=5)
        dyn.run(20)
        again = load_checkpoint(tmp_path / "c.npz", LAMMPSCalculator(PPPM_27))
        assert again.atoms.calc.kspace_parameters == first
        resumed = []
        again.attach(lambda: resumed.append(again.atoms.get_potential_energy()), interval=5)
        again.run(20)
    fresh = water_box_27()
    fresh.set_cell(again.atoms.cell)
    fresh.positions = again.atoms.positions
    fresh.calc = LAMMPSCalculator(PPPM_27)
    assert fresh.calc.kspace_parameters is None
    fresh.get_potential_energy()
    assert fresh.calc.kspace_parameters != first  # a new choice at the moved cell
    np.testing.assert_allclose(resumed, energies, rtol=0, atol=1e-9)


def test_kspace_parameters_are_a_checked_public_setting():
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    energy = atoms.get_potential_energy()
    state = atoms.calc.get_checkpoint_state()
    assert state["kspace_parameters"].startswith("kspace_modify gewald ")
    other = atoms.copy()
    other.calc = LAMMPSCalculator(PPPM_27)
    other.calc.set_checkpoint_state(state)
    assert other.get_potential_energy() == energy
    # Other atoms get parameters of their own, unless they were given.
    smaller = atoms[:-3]
    smaller.calc = atoms.calc
    smaller.get_potential_energy()
    assert atoms.calc.kspace_parameters.startswith("kspace_modify gewald ")
    assert atoms.calc.kspace_parameters != state["kspace_parameters"]
    smaller.calc = other.calc
    smaller.get_potential_energy()
    assert other.calc.kspace_parameters == state["kspace_parameters"]
    with pytest.raises(ValueError, match="kspace_parameters must be one 'kspace_modify gewald"):
        LAMMPSCalculator(PPPM_27, kspace_parameters="kspace_style ewald 1e-4")
    with pytest.raises(ValueError, match="unknown checkpoint state 'gewald'"):
        other.calc.set_checkpoint_state({"gewald": 0.3})


def test_a_refused_call_leaves_the_instance_and_its_kspace_parameters():
    """Other atoms that cannot be given to LAMMPS (an element without a type, a flat
    cell) were refused only after the running instance was closed and the k-space
    parameters pinned for the first atoms forgotten: the next call at those atoms, at a
    later cell (as in an NPT run), set LAMMPS up anew with parameters chosen for that
    cell, 2.165 eV off.  Now they are refused first, and the calculator is as it was
    (measured: the energy after equal to the last bit; asserted equal)."""
    atoms = water_box_27()
    calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1, "H": 2})
    atoms.calc = calc
    atoms.get_potential_energy()
    parameters = calc.kspace_parameters
    atoms.set_cell(atoms.cell * 1.08, scale_atoms=True)  # a barostat's later cell
    energy = atoms.get_potential_energy()
    instance = calc._instance
    sodium = atoms.copy()
    sodium[0].symbol = "Na"
    flat = atoms[:-3]
    flat.cell[2] = flat.cell[0]
    for other, message in ((sodium, "element Na has no LAMMPS type in atom_types"),
                           (flat, "the cell has zero volume")):
        with pytest.raises(ValueError, match=f"^LAMMPSCalculator: {message}"):
            calc.get_potential_energy(other)
        assert calc._instance is instance and calc.kspace_parameters == parameters
    assert calc.get_potential_energy(atoms) == energy


def test_given_molecule_ids_win_over_the_atoms_tags_and_are_checked():
    """``molecule_ids=`` was ignored without a word when the atoms carried tags or a
    ``mol-id`` array (27 waters, every atom its own molecule: -156.23 eV, the tags'
    molecules, against -248.10 eV meant), and never checked: ``[1, 2]`` on 81 atoms was
    taken.  An explicit argument now wins; one ID per atom, else one line naming it."""
    atoms = water_box_27()
    assert atoms.get_tags().any()
    alone = np.arange(1, len(atoms) + 1)  # every atom its own molecule: nothing excluded
    untagged = atoms.copy()
    untagged.set_tags(0)
    untagged.calc = LAMMPSCalculator(PPPM_27, molecule_ids=alone)
    meant = untagged.get_potential_energy()
    for carried in ("tags", "mol-id"):
        a = atoms.copy()
        if carried == "mol-id":
            a.arrays["mol-id"] = a.get_tags()
            a.set_tags(0)
        a.calc = LAMMPSCalculator(PPPM_27, molecule_ids=alone)
        assert a.get_potential_energy() == meant, carried  # (measured: to the last bit)
    atoms.calc = LAMMPSCalculator(PPPM_27, molecule_ids=[1, 2])
    with pytest.raises(ValueError, match=r"^LAMMPSCalculator: molecule_ids has shape \(2,\), "
                                         r"the atoms are 81$"):
        atoms.get_potential_energy()
    for bad in ([[1, 2, 3]], [1.5, 2.0], ["1", "2"], [True, False]):
        with pytest.raises(ValueError, match=r"^LAMMPSCalculator: molecule_ids must be one "
                                             r"whole number per atom, got an array of shape"):
            LAMMPSCalculator(PPPM_27, molecule_ids=bad)


def test_numeric_arguments_name_themselves():
    """``skin="abc"`` raised Python's bare "could not convert string to float"."""
    with pytest.raises(TypeError, match=r"^LAMMPSCalculator: skin must be a finite number "
                                        r">= 0 \(Å\), got 'abc'$"):
        LAMMPSCalculator(PPPM_27, skin="abc")
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match=r"^LAMMPSCalculator: skin must be a finite"):
            LAMMPSCalculator(PPPM_27, skin=bad)
    with pytest.raises(ValueError, match=r"^LAMMPSCalculator: threads must be a positive"):
        LAMMPSCalculator(PPPM_27, threads="2")
    assert LAMMPSCalculator(PPPM_27, skin=np.float32(1.5)).skin == 1.5


@pytest.mark.parametrize("tags", ["all-one", "layers", "split"])
def test_tags_that_group_atoms_unlike_the_bodies_are_refused(tags):
    """Before: all tags 1 excluded every intermolecular pair, and layer tags (as ASE's
    slab builders set) the pairs within a layer, silently: on these 27 waters -154.0 and
    -167.5 eV against -156.2 eV."""
    atoms = water_box_27(300)
    bodies = RigidBodies.resolve(atoms, "tags")
    if tags == "all-one":
        atoms.set_tags(1)
        message = r"the atoms. tags put atoms 2 and 3 in one molecule but they are in different"
    elif tags == "layers":  # ASE's slab builders tag atoms by layer
        atoms.set_tags(1 + (atoms.positions[:, 2] // 3.1).astype(int).clip(0, 2))
        message = "the atoms' tags put atoms .* in one molecule but they are in different rigid"
    else:
        atoms.set_tags(np.arange(1, len(atoms) + 1))
        message = "the atoms' tags split a rigid body: atoms 0 and 1 are in one body"
    atoms.calc = LAMMPSCalculator(PPPM_27)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the dynamics says it keeps the tags
        with pytest.raises(ValueError, match=message):
            RigidVerlet(atoms, units.fs, bodies=bodies).run(1)


def test_the_bodies_are_the_molecules_of_a_rigid_dynamics():
    """Tags of the bodies' grouping (other numbers), or none: the energy of the bodies."""
    atoms = water_box_27(300)
    bodies = RigidBodies.resolve(atoms, "tags")
    atoms.calc = LAMMPSCalculator(PPPM_27)
    energy = atoms.get_potential_energy()
    for tags in (100 + 7 * atoms.get_tags(), np.zeros(len(atoms), int)):
        a = atoms.copy()
        a.set_tags(tags)
        a.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=atoms.calc.kspace_parameters)
        RigidVerlet(a, units.fs, bodies=bodies)
        assert a.get_potential_energy() == pytest.approx(energy, rel=1e-12, abs=0)


def test_a_non_finite_position_or_cell_is_refused_before_lammps_sees_it(monkeypatch):
    """Before: a new instance given a NaN position hung at 100 % CPU, deaf to Ctrl-C."""
    atoms = water_box_27()
    atoms.positions[5, 1] = np.nan
    atoms.calc = LAMMPSCalculator(PPPM_27)

    def refuse(*args, **kwargs):  # before the fix LAMMPS started here, and hung
        raise AssertionError("LAMMPS was started with a non-finite position or cell")

    monkeypatch.setattr(lammps_calculator, "load_lammps", refuse)
    with pytest.raises(ValueError, match=r"atom 5 has a non-finite position \[.*nan.*\] \(Å\) "
                                         "given to LAMMPSCalculator"):
        atoms.get_forces()
    atoms = water_box_27()
    atoms.cell[2, 2] = np.inf
    atoms.calc = LAMMPSCalculator(PPPM_27)
    with pytest.raises(ValueError, match="cell vector 2 has a non-finite cell"):
        atoms.get_forces()


def test_net_charge_with_kspace_and_lammps_warnings_are_said():
    """Before: -11 e with PPPM_27 ran without a word, and every LAMMPS warning was hidden."""
    atoms = water_box_27()
    charges = atoms.get_initial_charges()
    charges[0] -= 11
    atoms.set_initial_charges(charges)
    atoms.calc = LAMMPSCalculator(PPPM_27)
    with pytest.warns(UserWarning, match="net charge of -11 e and the commands have a "
                                         "kspace_style"):
        atoms.get_potential_energy()
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27 + ["comm_modify cutoff 1.0"])
    with pytest.warns(UserWarning, match="LAMMPS warns: Communication cutoff adjusted to 6.5$"):
        atoms.get_potential_energy()
    # The warnings a rigid-water set-up always gets (no integrator fix, exclusions with
    # k-space) are not passed on: a neutral liquid says nothing.
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        atoms.get_potential_energy()


def test_isotopes_share_a_type_and_give_the_forces_of_the_light_system():
    """Before: "give atoms of different masses different types", which atom_types keyed
    by element cannot do.  Masses never enter LAMMPS's forces: a D2O/H2O/H2(18)O mixture
    gets the forces of the all-H2O box, bit for bit, and runs."""
    light = water_box_27()
    light.calc = LAMMPSCalculator(PPPM_27)
    mixed = light.copy()
    masses = mixed.get_masses()
    masses[1:30:3] = masses[2:30:3] = 2.014  # D2O: the first ten waters
    masses[60::3] = 17.999  # 18O: the last seven
    mixed.set_masses(masses)
    rigid_maxwell_boltzmann(mixed, 300, bodies="tags", rng=np.random.default_rng(3))
    mixed.calc = LAMMPSCalculator(PPPM_27)
    np.testing.assert_array_equal(mixed.get_forces(), light.get_forces())
    assert mixed.get_potential_energy() == light.get_potential_energy()
    dyn = RigidVerlet(mixed, units.fs, bodies="tags")
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the step-size advice of a hot, small box
        dyn.run(20)
    assert np.ptp(energies) < 0.05, np.ptp(energies)


def test_a_massive_m_site_is_refused_by_the_water_model():
    """A TIP4P/2005 box read from PDB or XYZ gets ASE's 1 amu for M, which then moved as
    an atom (density 1.056 instead of 1.001 g/cm³)."""
    model = water_model("tip4p2005")
    atoms = water_box(2, seed=1, model="tip4p2005")
    model.check(atoms)
    heavy = atoms.copy()
    heavy.set_masses(None)  # what a PDB or XYZ file gives: ASE's defaults, X 1 amu
    with pytest.raises(ValueError, match=r"tip4p2005: atom 3 \(X, the M site of molecule 0\) "
                                         r"has mass 1 amu but M is massless; give the M"):
        model.check(heavy)
    massless_h = atoms.copy()
    masses = massless_h.get_masses()
    masses[5] = 0.0
    massless_h.set_masses(masses)
    with pytest.raises(ValueError, match=r"atom 5 \(H\) has mass 0 amu; O and H need"):
        model.check(massless_h)
    deuterated = atoms.copy()
    masses = deuterated.get_masses()
    masses[1::4] = masses[2::4] = 2.014
    deuterated.set_masses(masses)
    model.check(deuterated)  # isotopes are masses like any other


def rigidmd_cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "rigidmd.run.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


BOX = """
structure: {builtin: water_box, n_side: 2, model: tip4p2005}
calculator: {name: lammps, water_model: {name: tip4p2005, cutoff: 20, kspace: pppm}}
velocities: {temperature: 300 K, seed: 1}
timestep: 1 fs
steps: 20
outputs: {directory: out, trajectory: md.traj, interval: 10}
"""


def test_a_lammps_error_is_one_line_of_the_command(tmp_path):
    """Before: a 20 Å cut-off in a 6 Å box ended ``rigidmd run`` with a traceback."""
    (tmp_path / "w.yaml").write_text(BOX)
    result = rigidmd_cli("run", "w.yaml", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("rigidmd: error: LAMMPS command 'run 0 pre yes post no' "
                                    "failed: ERROR on proc 0: Neighbor list overflow")
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def test_a_four_site_structure_without_masses_is_refused_by_the_configuration(tmp_path):
    """A PDB file of a TIP4P/2005 box: ASE gives M 1 amu, and it moved as an atom."""
    write(tmp_path / "box.pdb", water_box(2, seed=1, model="tip4p2005"))
    config = BOX.replace("{builtin: water_box, n_side: 2, model: tip4p2005}", "box.pdb")
    config = config.replace("cutoff: 20", "cutoff: 3")
    (tmp_path / "w.yaml").write_text(config)
    result = rigidmd_cli("run", "w.yaml", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    # Refused by the rule for every source of atoms (a massive X is never a virtual site),
    # before the water model's own check would name the molecule.
    assert result.stderr.startswith("rigidmd: error: atom 3 (X) has mass 1 amu, but X (Z = 0) "
                                    "is a massless virtual site")
    assert result.stderr.count("\n") == 1
