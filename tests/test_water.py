"""Massless virtual sites in rigid bodies, and the four-site water models."""

import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.tip4p import TIP4P
from helpers import CoulombLJ, water_parameters

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core.dof import kinetic_energy, temperature
from rigidmd.systems import water_box, water_cluster
from rigidmd.water import WATER_MODELS, water_model

TIP4P_MODEL = WATER_MODELS["tip4p"]


def with_m_sites(three_site, model=TIP4P_MODEL):
    """Explicit four-site copy of a three-site water system: M placed as ASE's TIP4P does."""
    x = three_site.positions.reshape(-1, 3, 3)
    bisector = 0.5 * (x[:, 1] + x[:, 2]) - x[:, 0]
    m_site = x[:, 0] + model.d_om * bisector / np.linalg.norm(bisector, axis=1)[:, None]
    n = len(x)
    atoms = Atoms("OH2X" * n, positions=np.concatenate([x, m_site[:, None]], axis=1)
                  .reshape(-1, 3), cell=three_site.cell, pbc=three_site.pbc)
    atoms.set_masses(np.tile(model.masses(), n))
    atoms.arrays["mol-id"] = np.repeat(np.arange(1, n + 1), 4)
    p = np.zeros((n, 4, 3))
    p[:, :3] = three_site.get_momenta().reshape(-1, 3, 3)
    atoms.set_momenta(p.reshape(-1, 3), apply_constraint=False)
    return atoms


@pytest.fixture(scope="module")
def tip4p_pair():
    """Eight TIP4P waters at 300 K: three-site (ASE's TIP4P) and explicit four-site."""
    three = water_cluster(8, seed=4)
    rigid_maxwell_boltzmann(three, 300.0, rng=np.random.default_rng(2))
    return three, with_m_sites(three)


def test_explicit_m_site_follows_ase_tip4p(tip4p_pair):
    """Explicit M (massless, plain LJ + Coulomb) and ASE's implicit M give one trajectory.

    ASE's TIP4P adds M, computes the same pair sum and moves M's force onto O, H, H
    with the same total force and torque; with a cut-off beyond the cluster (rc = 40 Å)
    the energies agree to roundoff.  Measured, largest O/H deviation at 1 fs: 3e-14 Å
    after 200 steps, 2.5e-13 after 400, 4e-12 after 600, 2e-10 after 800: a factor
    of about 10 per 200 fs, the Lyapunov growth of roundoff (the two calculators sum
    in different orders) in a liquid-like cluster.  1e-9 Å after 500 steps is 100×
    the measured value.
    """
    three, four = (a.copy() for a in tip4p_pair)
    three.calc = TIP4P(rc=40.0)
    four.calc = CoulombLJ(parameters=water_parameters(TIP4P_MODEL))
    three.set_momenta(tip4p_pair[0].get_momenta(), apply_constraint=False)
    four.set_momenta(tip4p_pair[1].get_momenta(), apply_constraint=False)
    e3, e4 = three.get_potential_energy(), four.get_potential_energy()
    assert abs(e3 - e4) < 1e-12 * abs(e3)
    dyn3 = RigidVerlet(three, 1.0 * units.fs)
    dyn4 = RigidVerlet(four, 1.0 * units.fs)
    assert dyn4.degrees_of_freedom == dyn3.degrees_of_freedom == 6 * 8
    assert temperature(four) == pytest.approx(three.get_temperature(), rel=1e-12)
    dyn3.run(500)
    dyn4.run(500)
    heavy = np.arange(len(four)) % 4 != 3
    deviation = np.abs(four.positions[heavy] - three.positions).max()
    assert deviation < 1e-9, deviation
    # M stays on the bisector at d_OM and carries no momentum.
    x = four.positions.reshape(-1, 4, 3)
    bisector = 0.5 * (x[:, 1] + x[:, 2]) - x[:, 0]
    expected = x[:, 0] + 0.15 * bisector / np.linalg.norm(bisector, axis=1)[:, None]
    assert np.abs(x[:, 3] - expected).max() < 1e-12
    assert not np.any(four.get_momenta()[3::4])
    assert np.abs(four.get_forces()[3::4]).max() > 0.1  # M does feel forces
    assert kinetic_energy(four) == pytest.approx(three.get_kinetic_energy(), rel=1e-9)
    assert temperature(four) == pytest.approx(three.get_temperature(), rel=1e-9)


def test_explicit_m_site_conserves_energy(tip4p_pair):
    """NVE with massless sites conserves energy exactly as the three-site run does.

    Measured on these 8 waters at 300 K, 2 fs, 1000 steps: the conserved energy
    fluctuates by 3.66e-3 eV peak to peak (1.25e-3 eV at 1 fs: the O(dt²) error of
    Verlet) and ends 2.2e-4 eV from its start, for both runs (peak to peak equal
    to 1e-8 eV).  Over the first 200 steps, before roundoff differences have grown
    (see the trajectory test), the two series agree to 1e-14 eV.  Bounds: 5e-3 and
    1e-3 eV; 1 % between the runs' fluctuations; 1e-10 eV over 200 steps.
    """
    series = []
    for atoms, calc in ((tip4p_pair[0], TIP4P(rc=40.0)),
                        (tip4p_pair[1], CoulombLJ(parameters=water_parameters(TIP4P_MODEL)))):
        copy = atoms.copy()
        copy.set_momenta(atoms.get_momenta(), apply_constraint=False)
        copy.calc = calc
        dyn = RigidVerlet(copy, 2.0 * units.fs)
        energies = []
        dyn.attach(lambda dyn=dyn, energies=energies: energies.append(
            dyn.get_conserved_energy()), interval=10)
        dyn.run(1000)
        series.append(np.array(energies))
    three, four = series
    assert np.ptp(four) < 5e-3, np.ptp(four)
    assert abs(four[-1] - four[0]) < 1e-3, four[-1] - four[0]
    assert abs(np.ptp(four) - np.ptp(three)) < 0.01 * np.ptp(three)
    assert np.abs(four[:20] - three[:20]).max() < 1e-10, np.abs(four[:20] - three[:20]).max()


@pytest.mark.parametrize("name", ["tip4p2005", "tip4pew", "opc"])
def test_four_site_models(name):
    """Builders carry M explicitly, massless, at d_OM on the bisector; charges are neutral."""
    model = water_model(name)
    box = water_box(2, model=name)
    assert box.get_chemical_formula() == "H16O8X8"
    masses = box.get_masses()
    assert np.all(masses[3::4] == 0) and np.all(masses[0::4] > 15)
    geometry = RigidBodies.resolve(box).geometry(box)
    d = geometry.model.body_coordinates.reshape(-1, 4, 3)
    assert np.allclose(np.linalg.norm(d[:, 3] - d[:, 0], axis=1), model.d_om, atol=1e-12)
    assert np.allclose(np.linalg.norm(d[:, 1] - d[:, 0], axis=1), model.r_oh, atol=1e-12)
    assert geometry.model.degrees_of_freedom == 6 * 8
    assert abs(model.charges(8).sum()) < 1e-12
    model.check(box)
    with pytest.raises(ValueError, match="atom 3 is O, expected X"):
        model.check(water_box(2))


def test_water_model_names():
    assert water_model("TIP4P/2005") is WATER_MODELS["tip4p2005"]
    assert water_model("TIP4P-Ew") is WATER_MODELS["tip4pew"]
    with pytest.raises(ValueError, match="unknown water model 'spc'"):
        water_model("spc")


def test_massless_atom_outside_a_body_is_refused():
    atoms = water_cluster(2, model="tip4p2005")
    atoms.calc = CoulombLJ(parameters=water_parameters(WATER_MODELS["tip4p2005"]))
    bodies = [[0, 1, 2], [4, 5, 6, 7]]  # atom 3 (M) left free
    with pytest.raises(ValueError, match=r"atom 3 \(X\) has mass 0 and belongs to no rigid body"):
        RigidVerlet(atoms, units.fs, bodies=bodies)
    assert atoms.constraints == []  # refused before anything was changed


def test_body_without_mass_and_mass_at_one_point_are_refused():
    atoms = Atoms("X2OX", positions=[[0, 0, 0], [1, 0, 0], [3, 0, 0], [3, 0.5, 0]])
    atoms.set_masses([0, 0, 16, 0])
    with pytest.raises(ValueError, match=r"body 0 \(atoms \[0, 1\]\) has no mass"):
        RigidBodies([0, 0, 1, 1]).geometry(atoms)
    helium = atoms.copy()  # atoms 0 and 1 massive (X must stay massless: He, given 1 amu)
    helium.numbers[:2] = 2
    with pytest.raises(ValueError, match=r"body 0 \(atoms \[2, 3\]\) has all its mass at one"):
        RigidBodies([1, 1, 0, 0]).geometry(_massive(helium, [0, 1]))
    with pytest.raises(ValueError, match=r"atom 1 \(X\) has mass -1.0 amu"):
        bad = atoms.copy()
        bad.set_masses([1, -1, 16, 0])
        RigidBodies([0, 0, 1, 1]).geometry(bad)


@pytest.mark.parametrize("source", ["api", "pdb", "xyz"])
def test_a_massive_m_site_is_refused_wherever_the_atoms_come_from(tmp_path, source):
    """Outside ``water_model:``: M of 1 amu (ASE's default for X) ran 5.5 % too dense.

    Through the API, and from a PDB or plain XYZ file (no masses stored), as a
    configuration with ``commands:`` reads them.
    """
    from ase.io import read, write

    atoms = water_cluster(2, model="tip4p2005")
    if source == "api":
        masses = atoms.get_masses()
        masses[[3, 7]] = 1.0
        atoms.set_masses(masses)
    else:
        write(tmp_path / f"w.{source}", atoms, format="proteindatabank" if source == "pdb" else
              "xyz")
        atoms = read(tmp_path / f"w.{source}")
    atoms.calc = CoulombLJ(parameters=water_parameters(WATER_MODELS["tip4p2005"]))
    with pytest.raises(ValueError, match=r"^atom 3 \(X\) has mass 1 amu, but X \(Z = 0\) is a "
                                         r"massless virtual site, such as the M of four-site "
                                         r"water \(2 X atoms have mass\); give them mass 0"):
        RigidVerlet(atoms, units.fs, bodies=[[0, 1, 2, 3], [4, 5, 6, 7]])
    assert atoms.constraints == []


def _massive(atoms, indices):
    """A copy with the given atoms at 1 amu."""
    atoms = atoms.copy()
    masses = atoms.get_masses()
    masses[indices] = 1.0
    atoms.set_masses(masses)
    return atoms


def test_massless_site_off_a_linear_body_is_refused():
    """A linear body has no orientation about its axis to carry an off-axis site."""
    co2 = Atoms("CO2X", positions=[[0, 0, 0], [1.16, 0, 0], [-1.16, 0, 0], [0, 0.3, 0]])
    co2.set_masses([12, 16, 16, 0])
    with pytest.raises(ValueError, match=r"atom 3 is massless and 0.3 Å off the axis"):
        RigidBodies([0, 0, 0, 0]).geometry(co2)
    on_axis = co2.copy()
    on_axis.positions[3] = [0.5, 0, 0]
    model = RigidBodies([0, 0, 0, 0]).geometry(on_axis).model
    assert model.degrees_of_freedom == 5


def test_tiny_mass_off_a_linear_body_is_refused():
    """A tiny mass keeps the body linear (m d² = 9e-12 amu Å² against 1e-7 of 43
    amu Å²) and would lose the axial part of its torque: refused like M."""
    co2 = Atoms("CO2H", positions=[[0, 0, 0], [1.16, 0, 0], [-1.16, 0, 0], [0, 0.3, 0]])
    co2.set_masses([12, 16, 16, 1e-10])
    with pytest.raises(ValueError, match=r"atom 3 is of mass 1e-10 amu and 0.3 Å off the axis"):
        RigidBodies([0, 0, 0, 0]).geometry(co2)
    # A CO2 given with 4-decimal coordinates (1e-4 Å off) is still a linear body.
    nearly = co2[:3]
    nearly.positions[1, 1] = 1e-4
    assert RigidBodies([0, 0, 0]).geometry(nearly).model.degrees_of_freedom == 5


def test_momentum_on_a_massless_site_is_refused():
    atoms = water_cluster(2, model="tip4p2005")
    atoms.calc = CoulombLJ(parameters=water_parameters(WATER_MODELS["tip4p2005"]))
    p = np.zeros((8, 3))
    p[3] = [0.0, 0.1, 0.0]
    atoms.set_momenta(p, apply_constraint=False)
    with pytest.raises(ValueError, match=r"atom 3 \(X\) has mass 0 but momentum"):
        RigidVerlet(atoms, units.fs)
    atoms.set_momenta(np.zeros((8, 3)), apply_constraint=False)
    dyn = RigidVerlet(atoms, units.fs)
    dyn.run(2)
    positions = atoms.positions.copy()
    atoms.set_momenta(p, apply_constraint=False)
    with pytest.raises(ValueError, match=r"atom 3 \(X\) has mass 0 but momentum .*set after"):
        dyn.run(1)
    assert np.array_equal(atoms.positions, positions)


@pytest.mark.lammps
def test_lammps_follows_explicit_m_sites():
    """LAMMPS sees M as an atom: same forces, and fix rigid/nve with M follows rigidmd.

    Forces of ``lj/cut/coul/cut`` (cut-off beyond the cluster, intramolecular pairs
    excluded) through LAMMPSCalculator equal CoulombLJ's to 1.1e-15 relative.  LAMMPS
    ``fix rigid/nve`` with M at 1e-20 amu (LAMMPS refuses a mass of 0) and RigidVerlet
    with M massless: measured gap 1.1e-11 Å and 3.5e-14 eV after 500 steps of 1 fs
    (roundoff growing in a chaotic cluster, as for three-site water in
    physics/test_against_lammps.py); bounds 1e-8 Å and 1e-10 eV.
    """
    from rigidmd.lammps import LAMMPSCalculator, run_rigid_reference

    model = water_model("tip4p2005")
    atoms = water_cluster(8, seed=4, model="tip4p2005")
    rigid_maxwell_boltzmann(atoms, 300.0, rng=np.random.default_rng(2))
    atoms.set_initial_charges(model.charges(8))
    lammps = atoms.copy()
    lammps.calc = LAMMPSCalculator(model.lammps_commands(40.0, None, tail=False),
                                   atom_types={"O": 1, "H": 2, "X": 3}, ase_constants=True)
    reference = atoms.copy()
    reference.calc = CoulombLJ(parameters=water_parameters(model))
    f = reference.get_forces()
    assert np.abs(lammps.get_forces() - f).max() < 1e-12 * np.abs(f).max()
    assert lammps.get_potential_energy() == pytest.approx(reference.get_potential_energy(),
                                                          abs=1e-12)

    commands = model.lammps_commands(40.0, None, tail=False) + [
        "neigh_modify exclude molecule/intra all"]
    body_ids = RigidBodies.resolve(atoms, "mol-id").body_ids
    ref = run_rigid_reference(atoms, body_ids, commands, 1 * units.fs, 500, every=10,
                              charges=model.charges(8))
    ours = atoms.copy()
    ours.set_momenta(atoms.get_momenta(), apply_constraint=False)
    ours.calc = CoulombLJ(parameters=water_parameters(model))
    dyn = RigidVerlet(ours, 1 * units.fs)
    positions, energies = [], []
    dyn.attach(lambda: (positions.append(ours.positions.copy()),
                        energies.append(ours.get_potential_energy() + kinetic_energy(ours))),
               interval=10)
    dyn.run(500)
    assert np.abs(np.array(positions) - ref.positions).max() < 1e-8
    assert np.abs(np.array(energies) - ref.total_energy).max() < 1e-10


def test_numpy_and_numba_paths_agree_with_massless_sites(tip4p_pair):
    """The readable NumPy path and the compiled kernel place M and move bodies alike.

    Measured: 4e-14 Å apart after 100 steps (the same arithmetic in another order,
    grown by the chaos of the cluster); bound 1e-11 Å.
    """
    runs = []
    for backend in ("numpy", "numba"):
        atoms = tip4p_pair[1].copy()
        atoms.set_momenta(tip4p_pair[1].get_momenta(), apply_constraint=False)
        atoms.calc = CoulombLJ(parameters=water_parameters(TIP4P_MODEL))
        RigidVerlet(atoms, 1.0 * units.fs, backend=backend).run(100)
        runs.append((atoms.positions.copy(), atoms.get_momenta()))
    assert np.abs(runs[0][0] - runs[1][0]).max() < 1e-11
    assert not np.any(runs[0][1][3::4]) and not np.any(runs[1][1][3::4])


def test_the_short_range_commands_refuse_bad_values_in_one_line():
    for cutoff, alpha in ((0.0, 0.2), (-1.0, 0.2), (5.0, -0.1), (float("nan"), 0.2)):
        with pytest.raises(ValueError, match="positive cutoff") as err:
            water_model("tip4p2005").lammps_short_range_commands(cutoff, alpha)
        assert "\n" not in str(err.value)


def test_the_short_range_commands_are_smooth_or_one_pair_style():
    model = water_model("tip4p2005")
    smooth = model.lammps_short_range_commands(5.0)
    assert smooth[0] == "pair_style hybrid/overlay lj/smooth/linear 5.0 coul/dsf 0.2 5.0"
    assert f"pair_coeff O O lj/smooth/linear {model.epsilon!r} {model.sigma!r}" in smooth
    plain = model.lammps_short_range_commands(4.0, alpha=0.25, smooth=False)
    assert plain[0] == "pair_style lj/cut/coul/dsf 0.25 4.0 4.0"
    assert plain[-1] == "pair_modify shift yes"


def _reflect_m_across_o_h1(atoms):
    """A copy with every M reflected across its O–H1 line, in the molecule's plane.

    O–M and H1–M keep their lengths; H2–M does not (1.101 Å against 0.871 for
    TIP4P/2005), and M moves by 0.20–0.25 Å.
    """
    bad = atoms.copy()
    x = bad.positions.reshape(-1, 4, 3)
    u = x[:, 1] - x[:, 0]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = x[:, 3] - x[:, 0]
    along = np.sum(v * u, axis=1, keepdims=True) * u
    x[:, 3] = x[:, 0] + along - (v - along)
    bad.positions = x.reshape(-1, 3)
    return bad


@pytest.mark.parametrize("name", ["tip4p2005", "opc", "tip4pew"])
def test_check_refuses_an_m_site_in_the_wrong_place(name):
    """Only the O–M and H1–M distances were compared: an M reflected across the O–H1 line
    passed (a 27-water TIP4P/2005 box so built: -263.931 eV in LAMMPS against -274.880 eV),
    and so did one out of the plane.  Every site is now compared with its place after the
    best superposition.  Measured, for the three models: the reflected M is 0.146–0.186 Å
    from its place, and one moved 0.01 Å out of the plane 0.0061–0.0065 Å (its distances
    change at second order, O–M by 3.1e-4–4.0e-4 Å, below the 1e-3 Å tolerance)."""
    model = water_model(name)
    box = water_box(3, seed=0, model=name)
    model.check(box)
    with pytest.raises(ValueError, match=r"molecule 0 \(atoms 0-3\) is not in this model's "
                                         r"geometry \(atom 3 is 0.1[4-8]\d* Å from"):
        model.check(_reflect_m_across_o_h1(box))
    lifted = box.copy()
    x = lifted.positions.reshape(-1, 4, 3)
    normal = np.cross(x[5, 1] - x[5, 0], x[5, 2] - x[5, 0])
    lifted.positions[23] += 0.01 * normal / np.linalg.norm(normal)  # M of molecule 5
    assert abs(np.linalg.norm(lifted.positions[23] - x[5, 0]) - model.d_om) < 1e-3
    with pytest.raises(ValueError, match=r"molecule 5 \(atoms 20-23\) .* \(atom 23 is "
                                         r"0.00[5-9]\d* Å from"):
        model.check(lifted)


def test_check_tolerance_passes_rounded_positions_and_refuses_the_nearest_model():
    """The 1e-3 Å tolerance: positions rounded to four decimals move a site by at most
    8e-5 Å (measured, 216 waters), three decimals 8e-4 Å; TIP4P's geometry is 3.45e-3 Å
    from TIP4P/2005's (O–M 0.15 against 0.1546 Å), the closest pair of models."""
    model = water_model("tip4p2005")
    box = water_box(6, seed=3, model="tip4p2005")
    for decimals in (3, 4):
        rounded = box.copy()
        rounded.positions = box.positions.round(decimals)
        model.check(rounded)
    with pytest.raises(ValueError, match=r"atom 3 is 0.00345 Å from the model's place"):
        model.check(water_box(2, model="tip4p"))
    with pytest.raises(ValueError, match="tolerance must be a finite number > 0, got nan"):
        model.check(box, tolerance=float("nan"))


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_check_refuses_a_position_that_is_not_finite(value):
    """NaN > tolerance is False: a NaN position passed the check."""
    box = water_box(2, seed=0)
    box.positions[4, 1] = value
    with pytest.raises(ValueError, match=r"^tip3p: atom 4 \(H\) has the position \[.*"
                                         r"(nan|inf).*\]; positions must be finite$"):
        water_model("tip3p").check(box)


def test_charges_take_whole_counts_only():
    """``charges(2.5)`` gave two molecules' charges and ``charges(-1)`` none."""
    model = water_model("tip4p2005")
    assert model.charges(0).shape == (0,)
    assert np.array_equal(model.charges(2.0), model.charges(2))
    assert model.charges(np.int64(3)).shape == (12,)
    for bad, error in ((2.5, ValueError), (-1, ValueError), (np.nan, ValueError),
                       ("2", TypeError), (True, TypeError)):
        with pytest.raises(error, match=r"^tip4p2005: n_molecules must be a whole number >= "
                                        r"0, got "):
            model.charges(bad)


def test_the_tail_correction_comes_with_k_space_only():
    """With ``kspace=None`` (a cluster) ``tail`` stayed True: LAMMPS warned and the energy
    of an 8-water cluster moved by -0.094 eV with the box it drew.  ``tail=None`` (the
    default) means with k-space; ``tail=True`` without it is refused."""
    model = water_model("tip4p2005")
    eps, sigma = model.epsilon, model.sigma
    assert model.lammps_commands(4.5) == [
        "pair_style lj/cut/coul/long 4.5", "pair_coeff * * 0.0 1.0",
        f"pair_coeff O O {eps!r} {sigma!r}", "pair_modify tail yes", "kspace_style pppm 1e-05"]
    assert model.lammps_commands(4.5, "ewald", 1e-6, tail=False) == [
        "pair_style lj/cut/coul/long 4.5", "pair_coeff * * 0.0 1.0",
        f"pair_coeff O O {eps!r} {sigma!r}", "kspace_style ewald 1e-06"]
    cluster = ["pair_style lj/cut/coul/cut 40.0", "pair_coeff * * 0.0 1.0",
               f"pair_coeff O O {eps!r} {sigma!r}"]
    assert model.lammps_commands(40.0, None) == cluster
    assert model.lammps_commands(40.0, None, tail=False) == cluster
    with pytest.raises(ValueError, match=r"^tip4p2005: tail=True needs k-space"):
        model.lammps_commands(40.0, None, tail=True)


@pytest.mark.parametrize("options, error, message", [
    ({"cutoff": -3.0}, ValueError, "cutoff must be a finite number > 0 Å, got -3.0"),
    ({"cutoff": 0.0}, ValueError, "cutoff must be a finite number > 0 Å, got 0.0"),
    ({"cutoff": np.inf}, ValueError, "cutoff must be a finite number > 0 Å, got inf"),
    ({"cutoff": "4.5"}, TypeError, "cutoff must be a finite number > 0 Å, got '4.5'"),
    ({"kspace": "PPPM"}, ValueError, "kspace must be one of pppm, ewald or None .* got 'PPPM'"),
    ({"kspace": "pppm/tip4p"}, ValueError, "kspace must be one of pppm, ewald or None"),
    ({"accuracy": -1e-5}, ValueError, "accuracy must be a finite number > 0, got -1e-05"),
    ({"accuracy": 1.0}, ValueError, "accuracy is a relative force accuracy, between 0 and 1"),
    ({"tail": "no"}, TypeError, "tail must be True, False or None .* got 'no'"),
    ({"tail": 1}, TypeError, "tail must be True, False or None .* got 1"),
])
def test_the_lammps_commands_refuse_bad_values_in_one_line(options, error, message):
    """They were passed on: ``tail="no"`` wrote ``pair_modify tail yes``, a negative
    accuracy ran, and a negative cut-off or ``PPPM`` failed inside LAMMPS."""
    arguments = {"cutoff": 4.5} | options
    with pytest.raises(error, match=f"^spce: {message}") as err:
        water_model("spce").lammps_commands(**arguments)
    assert "\n" not in str(err.value)


def test_without_k_space_the_accuracy_is_not_read():
    model = water_model("spce")
    assert model.lammps_commands(9.0, None, None) == model.lammps_commands(9.0, None)


def test_water_model_takes_a_model_as_well_as_a_name():
    opc = WATER_MODELS["opc"]
    assert water_model(opc) is opc
    with pytest.raises(ValueError, match="^unknown water model None; use one of tip3p"):
        water_model(None)


def test_the_modules_table_shows_the_models_parameters():
    """The table gave TIP4P's σ as 3.15365 Å; the model (ASE's) has 3.153578."""
    import rigidmd.water

    rows = [line.split() for line in rigidmd.water.__doc__.splitlines()
            if line.startswith("``") and len(line.split()) == 7]
    assert [row[0].strip("`") for row in rows] == list(WATER_MODELS)
    kj = units.kJ / units.mol
    for row in rows:
        model = WATER_MODELS[row[0].strip("`")]
        values = (model.r_oh, model.angle_hoh, model.d_om, model.q_h, model.sigma,
                  model.epsilon / kj)
        for shown, value in zip(row[1:], values, strict=True):
            decimals = len(shown.partition(".")[2])
            assert abs(float(shown) - value) <= 0.5 * 10.0**-decimals, (row[0], shown, value)
