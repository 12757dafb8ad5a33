"""A cell change through the rigidmd_box LAMMPS plugin, and the set-up run it replaces.

The periodic liquid is ``tests/data/water_box_27.traj`` (27 TIP3P waters in a
9.3 Å box) with ``lj/cut/coul/long 4.5`` and PPPM_27 at 1e-5, as in
``lammps/test_calculator.py``.  With the plugin a new cell costs what it costs
LAMMPS's own barostats (the new box and ``KSpace::setup()``, no ``lmp->init()``);
without it, ``change_box`` and a set-up run.  Both must give what a fresh LAMMPS
at that cell gives with the same k-space parameters.
"""

import warnings

import numpy as np
import pytest
from ase import units
from helpers import PPPM_27, water_box_27

import rigidmd.lammps.boxplugin as boxplugin
from rigidmd import RigidCRescale, RigidNPT, rigid_maxwell_boltzmann
from rigidmd.lammps import LAMMPSCalculator
from rigidmd.lammps.instance import LammpsInstance

pytestmark = pytest.mark.lammps


@pytest.fixture
def commands(monkeypatch):
    """The LAMMPS commands every LAMMPSCalculator runs from now on (a list, appended to)."""
    seen = []
    original = LammpsInstance.execute

    def recording(self, cmds):
        seen.extend(cmds)
        return original(self, cmds)

    monkeypatch.setattr(LammpsInstance, "execute", recording)
    return seen


def break_the_plugin(monkeypatch, tmp_path):
    """From now on the plugin cannot be built (an empty cache, a failing compiler)."""
    def failing(*args):
        raise boxplugin.BoxPluginUnavailable("building the plugin failed (c++: test)")

    monkeypatch.setenv("RIGIDMD_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(boxplugin, "_compile", failing)
    monkeypatch.setattr(boxplugin, "_FOUND", {})
    monkeypatch.setattr(boxplugin, "_WARNED", [])


def fresh(atoms, parameters):
    """Energy, forces and stress of a new LAMMPSCalculator at ``atoms``' cell."""
    a = atoms.copy()
    a.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=parameters)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LAMMPS: "Triclinic box skew is large"
        return a.get_potential_energy(), a.get_forces(), a.get_stress()


def cell_changes(atoms):
    """Cell changes in a row, each with a label: iso, aniso, a tilt, triclinic changes."""
    rng = np.random.default_rng(7)
    for scale in (1.03, 0.97, 1.02, 0.96, 1.25, 0.8):  # the last two re-neighbour
        atoms.set_cell(atoms.cell * scale, scale_atoms=True)
        yield f"iso {scale}"
    for scales in ((1.03, 0.98, 1.01), (0.97, 1.02, 1.0)):
        atoms.set_cell(atoms.cell * np.array(scales)[:, None], scale_atoms=True)
        atoms.positions += rng.normal(scale=0.05, size=atoms.positions.shape)
        yield f"aniso {scales}"
    cell = atoms.cell.array.copy()
    cell[1, 0] += 0.6
    cell[2, 1] -= 0.4
    atoms.set_cell(cell, scale_atoms=True)
    yield "tilted (the box becomes triclinic)"
    for scale, tilt in ((1.02, 0.3), (0.97, -0.5), (1.04, 0.2)):
        cell = atoms.cell.array * scale
        cell[2, 0] += tilt
        atoms.set_cell(cell, scale_atoms=True)
        yield f"triclinic {scale}, xz {tilt:+}"


def test_cell_changes_equal_a_fresh_lammps_with_the_same_kspace_parameters(commands):
    """Grown and shrunk by a few % (and by 25 %, past the skin: LAMMPS re-neighbours),
    anisotropically with moved atoms, tilted, and triclinic cells changed, one after
    another in one instance: each call equals a fresh LAMMPS at that cell given the first
    cell's k-space parameters.  Measured: iso changes equal to the last bit (forces 4e-16
    relative to the largest after the 25 % growth), aniso and triclinic 1.8e-16 relative
    in energy, 7.5e-15 in forces and 2.2e-15 in stress (relative to the largest
    component); bounds 1e-9 as in the calculator's other tests.  Only the tilt of an
    orthogonal box and the first change (which takes the plugin's fix in) run a set-up;
    every other change is one ``rigidmd_box`` command, and its stress (asked alone) one
    ``rigidmd_tally`` of the virial compute, without the energy.  Without ``KSpace::setup()`` in
    the plugin the same comparison is off by 3e-5 to 3e-3 relative in energy and 4-12 %
    in forces."""
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    atoms.get_potential_energy()
    parameters = atoms.calc.kspace_parameters
    assert not any("rigidmd/box" in c or "rigidmd_box" in c for c in commands)  # not yet
    for k, label in enumerate(cell_changes(atoms)):
        del commands[:]
        energy, forces, stress = fresh(atoms, parameters)
        del commands[:]
        assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-9, abs=0), label
        np.testing.assert_allclose(atoms.get_forces(), forces, rtol=0,
                                   atol=1e-9 * np.abs(forces).max(), err_msg=label)
        np.testing.assert_allclose(atoms.get_stress(), stress, rtol=0,
                                   atol=1e-9 * np.abs(stress).max(), err_msg=label)
        boxes = [c for c in commands if c.startswith("rigidmd_box ")]
        setups = [c for c in commands if c.startswith(("change_box", "run 0 pre yes"))]
        # (white box) the box the calculator keeps instead of reading it back is LAMMPS's
        box = atoms.calc._instance.box
        lo, hi, xy, yz, xz, _, _ = box.lmp.extract_box()
        lengths = np.array(hi) - np.array(lo)
        np.testing.assert_array_equal(box.lammps_cell(), [[lengths[0], 0, 0],
                                                          [xy, lengths[1], 0],
                                                          [xz, yz, lengths[2]]], label)
        if k == 0:  # the first new cell: a set-up takes the plugin's fix in
            assert "fix rmd_box all rigidmd/box" in commands and not boxes, commands
            assert "run 0 pre yes post no" in setups
        elif label.startswith("tilted"):
            assert not boxes and "change_box all triclinic" in setups, label
        else:  # and the stress alone (asked after the energy) tallies only the virial
            assert len(boxes) == 1 and not setups, (label, commands)
            assert "rigidmd_tally rmd_pressure" in " ".join(commands), (label, commands)


def test_a_rotated_cell_that_stays_sends_no_new_box(commands):
    """A cell that is not lower triangular (rotated into LAMMPS's frame at every cell):
    after it changed through the plugin, calls at the same cell send LAMMPS nothing but the
    step (the calculator compares the atoms' cell with the one it gave LAMMPS, in the
    atoms' frame).  A regression kept LAMMPS's box there instead: every call at an unchanged
    rotated cell re-sent the box and re-set PPPM (0.97 against 0.55 ms a call, 27 waters)."""
    from ase.build import rotate

    atoms = water_box_27()
    rotate(atoms, [1, 0, 0], [np.cos(0.3), np.sin(0.3), 0], [0, 0, 1], [0, 0, 1],
           rotate_cell=True)
    assert atoms.cell.array[0, 1] != 0  # not lower triangular
    atoms.calc = LAMMPSCalculator(PPPM_27)
    atoms.get_forces()
    for scale in (1.02, 1.01):  # the first change takes the plugin in, the second uses it
        atoms.set_cell(atoms.cell * scale, scale_atoms=True)
        atoms.get_forces()
    assert any(c.startswith("rigidmd_box ") for c in commands)
    del commands[:]
    for _ in range(3):
        atoms.positions += 0.001
        atoms.get_forces()
    assert not [c for c in commands if c.startswith(("rigidmd_box", "change_box"))], commands


def test_without_the_plugin_a_cell_change_runs_a_set_up_with_the_same_numbers(
        monkeypatch, tmp_path, commands):
    """The fallback (no compiler, a failed build or load): ``change_box`` and a set-up
    run, said once in one line with the reason.  The numbers equal the plugin's route
    through the same cell changes (measured: energy equal to the last bit or 1.9e-16
    relative, forces 7.5e-15, stress 2.2e-15 relative to the largest; bounds 1e-9)."""
    atoms = water_box_27()
    fallback = atoms.copy()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    atoms.get_potential_energy()
    results = [(atoms.cell.array.copy(), atoms.positions.copy(), atoms.get_potential_energy(),
                atoms.get_forces(), atoms.get_stress()) for _ in cell_changes(atoms)]
    break_the_plugin(monkeypatch, tmp_path)
    del commands[:]
    fallback.calc = LAMMPSCalculator(PPPM_27)
    fallback.get_potential_energy()
    assert "fix rmd_box all rigidmd/box" not in commands
    for k, (cell, positions, energy, forces, stress) in enumerate(results):
        fallback.set_cell(cell)
        fallback.positions = positions
        if k == 0:
            with pytest.warns(UserWarning) as said:
                fallback.get_potential_energy()
            assert [str(w.message) for w in said] == [
                "LAMMPSCalculator: no rigidmd_box LAMMPS plugin (building the plugin failed "
                "(c++: test)); each cell change runs LAMMPS's whole set-up (slower under a "
                "barostat)"]
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # said once only
            assert fallback.get_potential_energy() == pytest.approx(energy, rel=1e-9, abs=0)
        np.testing.assert_allclose(fallback.get_forces(), forces, rtol=0,
                                   atol=1e-9 * np.abs(forces).max())
        np.testing.assert_allclose(fallback.get_stress(), stress, rtol=0,
                                   atol=1e-9 * np.abs(stress).max())
    assert sum(c.startswith("change_box all x final") for c in commands) == len(results)
    assert not any(c.startswith("rigidmd_box") for c in commands)


@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_npt_through_the_plugin_follows_the_set_up_route(kind, monkeypatch, tmp_path,
                                                          commands):
    """RigidNPT (MTK, iso) and RigidCRescale (every step), 30 steps of 27 waters at
    300 K, the cell moving at every step: through the plugin and through ``change_box``
    and a set-up run (the fallback) the trajectories agree to roundoff (measured, both:
    cells equal, positions 1.8e-15 Å apart, conserved energies 2.8e-14 eV; bound 1e-11,
    room for roundoff grown by chaos on other CPUs)."""
    atoms = water_box_27()
    rigid_maxwell_boltzmann(atoms, 300, bodies="tags", rng=np.random.default_rng(5))
    probe = atoms.copy()
    probe.calc = LAMMPSCalculator(PPPM_27)
    probe.get_potential_energy()
    runs = []
    for plugin in (True, False):
        if not plugin:
            break_the_plugin(monkeypatch, tmp_path)
        del commands[:]
        a = atoms.copy()
        a.calc = LAMMPSCalculator(PPPM_27, kspace_parameters=probe.calc.kspace_parameters)
        if kind == "mtk":
            dyn = RigidNPT(a, units.fs, 300, 1.01325 * units.bar, 50 * units.fs,
                           200 * units.fs, bodies="tags")
        else:
            dyn = RigidCRescale(a, units.fs, 300, 1.01325 * units.bar, 50 * units.fs,
                                200 * units.fs, 4.5e-5 / units.bar, bodies="tags",
                                rng=np.random.default_rng(1))
        energies = []
        dyn.attach(lambda d=dyn, e=energies: e.append(d.get_conserved_energy()), interval=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the step-size advice of a hot, small box
            dyn.run(30)
        boxes = sum(c.startswith("rigidmd_box ") for c in commands)
        assert boxes == (29 if plugin else 0), boxes  # the first change: a set-up
        runs.append((a.positions.copy(), a.cell.array.copy(), np.array(energies)))
    assert np.abs(runs[0][1] - atoms.cell.array).max() > 1e-4  # the cell moved
    for k in range(3):
        np.testing.assert_allclose(runs[0][k], runs[1][k], rtol=0, atol=1e-11)


def test_the_plugin_is_built_once_into_a_writable_cache(monkeypatch, tmp_path):
    """Built into the first writable cache directory, named by a hash of the source and
    the LAMMPS library, and found there the next time (no compiler run); a cache that
    cannot be written (here: a file where the directory should be) falls back to the
    temporary directory."""
    blocked = tmp_path / "not-a-directory"
    blocked.write_text("")
    monkeypatch.delenv("RIGIDMD_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    monkeypatch.setattr(boxplugin.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    built = boxplugin._build()
    assert built.parent.parent == tmp_path / "tmp" and built.name.startswith("rigidmd_box-")
    assert boxplugin.plugin_source().is_file()

    def no_compiler(*args):
        raise AssertionError("built again")

    monkeypatch.setattr(boxplugin, "_compile", no_compiler)
    assert boxplugin._build() == built
    monkeypatch.setenv("RIGIDMD_LAMMPS_PLUGIN", "0")
    with pytest.raises(boxplugin.BoxPluginUnavailable, match="RIGIDMD_LAMMPS_PLUGIN"):
        boxplugin._build()


@pytest.mark.parametrize("plugin", [True, False])
def test_a_stress_without_the_energy_in_a_fixed_cell(plugin, commands, monkeypatch, tmp_path):
    """A fixed cell asked for the stress alone (as a Green-Kubo recorder asks): with the
    plugin one ``rigidmd_tally`` of the virial compute and no box fix; without it the
    library's tally of every compute.  Either way the stress, and then the energy of the
    same positions, equal a fresh LAMMPS's (measured: equal to the last bit; bound 1e-9
    relative as above)."""
    if not plugin:
        break_the_plugin(monkeypatch, tmp_path)
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(PPPM_27)
    atoms.get_forces()
    parameters = atoms.calc.kspace_parameters
    atoms.positions += np.random.default_rng(3).normal(scale=0.02, size=atoms.positions.shape)
    del commands[:]
    stress = atoms.get_stress()
    tallies = [c.split()[:2] for c in commands if c.startswith("rigidmd_tally")]
    assert tallies == ([["rigidmd_tally", "rmd_pressure"]] if plugin else []), commands
    assert not any("rigidmd/box" in c or "rigidmd_box" in c for c in commands)
    energy, _, fresh_stress = fresh(atoms, parameters)
    np.testing.assert_allclose(stress, fresh_stress, rtol=0,
                               atol=1e-9 * np.abs(fresh_stress).max())
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-9, abs=0)


def test_two_live_instances_both_take_the_plugin(commands):
    """The styles go into each LAMMPS instance's own maps: a second instance alive beside
    the first gets them too (LAMMPS's ``plugin load`` refused it: "must unload existing
    rigidmd/box plugin first", and that calculator fell back to full set-ups)."""
    pair = [water_box_27(), water_box_27()]
    for atoms in pair:
        atoms.calc = LAMMPSCalculator(PPPM_27)
        atoms.get_potential_energy()
    for scale in (1.02, 1.03):
        for atoms in pair:
            atoms.set_cell(atoms.cell * scale, scale_atoms=True)
            del commands[:]
            atoms.get_potential_energy()
            if scale == 1.03:  # after the first new cell (the set-up that takes the fix in)
                assert [c.split()[0] for c in commands] == ["rigidmd_box", "run"], commands
    assert pair[0].get_potential_energy() == pair[1].get_potential_energy()


#: TIP3P with damped shifted-force Coulomb (no k-space) for the 27-water box.
DSF_27 = ["pair_style lj/cut/coul/dsf 0.2 4.5", "pair_coeff * * 0.0 1.0",
          "pair_coeff O O 0.0065956819 3.15061"]


@pytest.mark.parametrize("interactions", ["dsf", "pppm"])
def test_a_cell_shrunk_with_the_atoms_left_in_place_equals_a_fresh_lammps(interactions,
                                                                           commands):
    """A later cell change with no atom moving (``set_cell(..., scale_atoms=False)``)
    goes through ``rigidmd_box``, and LAMMPS's neighbour check, which looks only at atom
    displacements, kept its lists: a cell shrunk by 15 % (the box's far corner 2.4 Å
    away, past the 2 Å skin) gave DSF energies 0.020 eV and forces 0.043 eV/Å off a
    fresh LAMMPS, and PPPM died ("Out of range atoms - cannot compute PPPM").  The step
    now re-neighbours when the box has moved by more than half the skin since the last
    build.  (A triclinic box hid the fault: LAMMPS's round trip through its lamda
    coordinates at a build moves its positions by roundoff, which its check counts once
    the corners have moved past the skin.)  Measured (DSF, PPPM): energy to 2.2e-16 relative,
    forces to 2.1e-16 relative to the largest, stress to 6.3e-16 relative; bounds 1e-9 as
    above."""
    interaction_commands = DSF_27 if interactions == "dsf" else PPPM_27
    atoms = water_box_27()
    atoms.calc = LAMMPSCalculator(interaction_commands)
    atoms.get_potential_energy()
    cell = atoms.cell.array.copy()
    atoms.set_cell(cell * 1.005, scale_atoms=False)  # the set-up that takes the fix in
    atoms.get_potential_energy()
    atoms.set_cell(cell * 0.85, scale_atoms=False)
    del commands[:]
    energy, forces, stress = atoms.get_potential_energy(), atoms.get_forces(), atoms.get_stress()
    assert commands[0].startswith("rigidmd_box ") and not any(
        c.startswith(("change_box", "run 0")) for c in commands), commands
    parameters = atoms.calc.kspace_parameters
    reference = atoms.copy()
    reference.calc = LAMMPSCalculator(interaction_commands + ([parameters] if parameters else []))
    assert energy == pytest.approx(reference.get_potential_energy(), rel=1e-9, abs=0)
    np.testing.assert_allclose(forces, reference.get_forces(), rtol=0,
                               atol=1e-9 * np.abs(forces).max())
    np.testing.assert_allclose(stress, reference.get_stress(), rtol=0,
                               atol=1e-9 * np.abs(stress).max())
