"""Physics and behaviour of RigidVerlet (NO_SQUISH) without LAMMPS."""

import re
import warnings

import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P
from ase.constraints import FixBondLengths
from ase.io import Trajectory, read
from helpers import ZeroForce, mixture, total_momenta, waters

from rigidmd import NonFiniteForceError, RigidVerlet, rigid_maxwell_boltzmann

BACKENDS = ["numpy", "numba"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_energy_conservation(backend):
    atoms = waters()
    dyn = RigidVerlet(atoms, 1 * units.fs, backend=backend)
    energies = []
    dyn.attach(lambda: energies.append(atoms.get_total_energy()), interval=5)
    dyn.run(2000)
    e = np.array(energies)
    t_ps = np.arange(len(e)) * 5e-3
    drift = np.polyfit(t_ps, e, 1)[0]
    # Measured: 8 waters (250 K start, 380 K after 2 ps), max |E - E0| =
    # 7.0e-4 eV against a 0.70 eV swing of the kinetic energy, RMS 1.7e-4 eV,
    # fitted drift 3e-5 eV/ps.  The bounds leave a factor ~3 for roundoff.
    assert np.abs(e - e[0]).max() < 2e-3
    assert abs(drift) < 1e-4


def test_second_order_convergence():
    """Error at t = 40 fs against a 1/16 fs reference falls 4x per halving of dt."""
    final = {}
    for dt in (2.0, 1.0, 0.5, 0.0625):
        atoms = waters()
        RigidVerlet(atoms, dt * units.fs).run(int(round(40 / dt)))
        final[dt] = atoms.positions.copy()
    err = {dt: np.abs(final[dt] - final[0.0625]).max() for dt in (2.0, 1.0, 0.5)}
    orders = [np.log2(err[2.0] / err[1.0]), np.log2(err[1.0] / err[0.5])]
    # Measured 2.00 and 2.01.
    np.testing.assert_allclose(orders, 2.0, atol=0.1)


def test_momentum_and_angular_momentum_conserved():
    atoms = waters()
    P0, L0 = total_momenta(atoms)
    RigidVerlet(atoms, 1 * units.fs).run(500)
    P1, L1 = total_momenta(atoms)
    # Pairwise central forces: both are constants of the splitting; measured
    # changes are 1e-14 (roundoff on |P|, |L| ~ 1-5).
    np.testing.assert_allclose(P1, P0, atol=1e-11)
    np.testing.assert_allclose(L1, L0, atol=1e-11)


def test_angular_momentum_with_linear_bodies():
    atoms = mixture()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    P0, L0 = total_momenta(atoms)
    np.testing.assert_allclose(dyn.get_angular_momentum(), L0, atol=1e-13)
    dyn.run(500)
    P1, L1 = total_momenta(atoms)
    np.testing.assert_allclose(P1, P0, atol=1e-11)
    # The integrator's invariant includes the axial NO_SQUISH momentum of the
    # CO2 molecules: conserved to 1e-13 (measured).
    np.testing.assert_allclose(dyn.get_angular_momentum(), L0, atol=1e-11)
    # The atoms cannot show that axial part, so their own angular momentum
    # moves by the splitting error: measured 1.1e-5 of |L| = 23 over 500 fs
    # (LAMMPS fix rigid/nve does the same).  A bound, not a tolerance.
    assert 1e-9 < np.abs(L1 - L0).max() < 1e-3


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("make", [waters, mixture], ids=["waters", "co2-water-neon"])
def test_time_reversal(make, backend):
    atoms = make()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id", backend=backend)
    start = atoms.positions.copy()
    dyn.run(100)
    assert np.abs(atoms.positions - start).max() > 0.1
    atoms.set_momenta(-atoms.get_momenta())
    dyn.run(100)
    # Measured 4e-14 Å; chaos amplifies roundoff by < 1e3 over 200 fs.
    assert np.abs(atoms.positions - start).max() < 1e-9


def test_backends_agree():
    runs = []
    for backend in BACKENDS:
        atoms = mixture()
        RigidVerlet(atoms, 1 * units.fs, bodies="mol-id", backend=backend).run(100)
        runs.append((atoms.positions.copy(), atoms.get_momenta()))
    # Same arithmetic in a different order: measured 1.2e-14 Å and 3e-14 (momenta, ASE units)
    # (roundoff, amplified by the chaos over 100 steps); a factor 100 of room
    # for other CPUs' libm.
    np.testing.assert_allclose(runs[0][0], runs[1][0], atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], atol=3e-12)


@pytest.mark.parametrize("integrator", ["no_squish", "richardson", "rozmanov_kusalik", "pcdm"])
def test_timestep_change_takes_effect_on_every_backend(integrator):
    """``dyn.dt`` (or ``set_timestep``) changed between runs is used by every path."""
    runs = []
    for backend in BACKENDS:
        atoms = waters(4)
        dyn = RigidVerlet(atoms, 1 * units.fs, integrator=integrator, backend=backend)
        dyn.run(5)
        dyn.set_timestep(2 * units.fs)
        dyn.run(10)
        runs.append(atoms.positions.copy())
        # The clock adds up the steps actually taken, not nsteps * dt.
        assert dyn.get_time() == pytest.approx(25 * units.fs, rel=1e-14)
    # The two backends (numba kernel or operators for no_squish; operators for the
    # others): measured 3.6e-15 Å; before the fix they differed by 6.4e-3 Å.
    np.testing.assert_allclose(runs[0], runs[1], atol=1e-12)
    # ... and the steps are 2 fs long: the same as a new dynamics started at 2 fs
    # from the state after the first 5 steps (measured 1e-14 Å).
    atoms = waters(4)
    RigidVerlet(atoms, 1 * units.fs, integrator=integrator).run(5)
    RigidVerlet(atoms, 2 * units.fs, integrator=integrator).run(10)
    np.testing.assert_allclose(atoms.positions, runs[0], atol=1e-10)


def test_bad_timestep_change_is_refused_and_changes_nothing():
    atoms = waters(2)
    dyn = RigidVerlet(atoms, 1 * units.fs)
    for bad in (0.0, -1.0, np.nan, "2 fs"):
        with pytest.raises((ValueError, TypeError), match="timestep"):
            dyn.dt = bad
        assert dyn.dt == 1 * units.fs


def test_observer_changes_are_honoured_like_ase():
    """A water whose momenta an observer zeroes at step 2 stops there (ASE's VelocityVerlet too)."""
    from ase.md.verlet import VelocityVerlet

    stopped = {}
    for name in ("rigid", "ase"):
        atoms = waters(1)
        atoms.calc = ZeroForce()
        dyn = RigidVerlet(atoms, units.fs) if name == "rigid" else VelocityVerlet(atoms, units.fs)
        positions = {}

        def zero_at_2(dyn=dyn, atoms=atoms, positions=positions):
            positions[dyn.nsteps] = atoms.positions.copy()
            if dyn.nsteps == 2:
                atoms.set_momenta(np.zeros((3, 3)), apply_constraint=False)

        dyn.attach(zero_at_2, interval=1)
        dyn.run(5)
        stopped[name] = np.abs(positions[5] - positions[2]).max()
        assert np.abs(positions[2] - positions[0]).max() > 1e-3  # it did move before
    # Before the fix the rigid water moved 3e-3 Å after being stopped.
    assert stopped["rigid"] == stopped["ase"] == 0.0


def test_changes_between_irun_yields_are_honoured():
    atoms = waters(2)
    atoms.calc = ZeroForce()
    dyn = RigidVerlet(atoms, units.fs)
    start = atoms.positions.copy()
    for _ in dyn.irun(6):
        if dyn.nsteps == 3:
            # Pure translation of the first molecule, the second stopped and shifted.
            atoms.arrays["momenta"][:] = 0.0
            atoms.arrays["momenta"][:3] = atoms.get_masses()[:3, None] * [0.01, 0, 0]
            atoms.positions[3:] += [0.5, 0, 0]
            moved = atoms.positions.copy()
            velocities = atoms.get_velocities()
    # From step 3 on, free flight with the changed state.
    expected = moved + 3 * units.fs * velocities
    np.testing.assert_allclose(atoms.positions, expected, atol=1e-12)
    assert np.abs(atoms.positions - start).max() > 0.45  # the shift was kept


def test_unchanged_atoms_are_not_re_read():
    """Observers that only read (logger, trajectory) cost no copies; others one snapshot each."""
    atoms = waters(4)
    dyn = RigidVerlet(atoms, units.fs)
    calls = []
    original = dyn.sync.sync
    dyn.sync.sync = lambda *args: calls.append(1) or original(*args)
    dyn.attach(lambda: atoms.get_kinetic_energy(), interval=1)  # reads only
    dyn.run(10)
    assert calls == [1]  # once, at the start of the run, not at every step


def test_degrees_of_freedom_and_temperature():
    atoms = mixture()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    # 4 linear CO2 (5), 4 waters (6), 2 point particles (3).
    assert dyn.degrees_of_freedom == 4 * 5 + 4 * 6 + 2 * 3
    assert atoms.get_number_of_degrees_of_freedom() == 50
    ekin = atoms.get_kinetic_energy()
    assert atoms.get_temperature() == pytest.approx(2 * ekin / (50 * units.kB))
    parts = dyn.get_translational_kinetic_energy() + dyn.get_rotational_kinetic_energy()
    assert parts == pytest.approx(ekin, rel=1e-12)
    # The CO2 molecules, and only they, are found linear.
    is_co2 = [atoms.symbols[dyn.bodies.atoms_of(b)[0]] == "C" for b in range(8)]
    np.testing.assert_array_equal(dyn.model.linear, is_co2)
    # Each body's rotational energy is what its atoms carry about its centre of mass.
    dyn.run(20)
    masses, v = atoms.get_masses(), atoms.get_velocities()
    for b in range(8):
        idx = dyn.bodies.atoms_of(b)
        relative = v[idx] - dyn.com_velocities[b]
        assert dyn.rotational_kinetic_energies[b] == pytest.approx(
            0.5 * np.sum(masses[idx, None] * relative**2), rel=1e-10)


def test_per_body_state_is_consistent():
    atoms = waters(4)
    dyn = RigidVerlet(atoms, 1 * units.fs)
    dyn.run(10)
    masses = atoms.get_masses().reshape(4, 3)
    x = atoms.positions.reshape(4, 3, 3)
    v = atoms.get_velocities().reshape(4, 3, 3)
    com = np.einsum("bi,bik->bk", masses, x) / masses.sum(1)[:, None]
    np.testing.assert_allclose(dyn.com_positions, com, atol=1e-12)
    np.testing.assert_allclose(dyn.com_velocities, np.einsum("bi,bik->bk", masses, v)
                               / masses.sum(1)[:, None], atol=1e-12)
    L = np.einsum("bi,bik->bk", masses, np.cross(x - com[:, None], v - dyn.com_velocities[:, None]))
    np.testing.assert_allclose(dyn.angular_momenta, L, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(dyn.quaternions, axis=1), 1.0, atol=1e-13)
    omega = dyn.angular_velocities
    np.testing.assert_allclose(v, dyn.com_velocities[:, None] + np.cross(
        omega[:, None], x - com[:, None]), atol=1e-12)


def test_projection_reports_removed_energy():
    atoms = waters(4)
    rng = np.random.default_rng(0)
    atoms.set_momenta(atoms.get_momenta() + 0.05 * rng.normal(size=(12, 3)))
    ekin = atoms.get_kinetic_energy()
    with pytest.warns(UserWarning, match="removed .* eV of kinetic energy"):
        dyn = RigidVerlet(atoms, 1 * units.fs)
    assert dyn.removed_kinetic_energy > 0
    assert atoms.get_kinetic_energy() == pytest.approx(ekin - dyn.removed_kinetic_energy, rel=1e-12)
    # Rigid-consistent velocities lose nothing and warn nothing.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dyn = RigidVerlet(atoms, 1 * units.fs)
    assert abs(dyn.removed_kinetic_energy) < 1e-14


def test_changes_between_runs_are_picked_up():
    atoms = waters(4)
    dyn = RigidVerlet(atoms, 1 * units.fs)
    dyn.run(5)
    d_ref = dyn.model.body_coordinates.copy()
    # Move one molecule rigidly and redraw velocities.
    atoms.positions[3:6] += [0.3, -0.2, 0.1]
    rigid_maxwell_boltzmann(atoms, 100, rng=np.random.default_rng(5))
    expected_com = dyn.com_positions[1] + [0.3, -0.2, 0.1]
    ekin = atoms.get_kinetic_energy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # rigid changes: nothing to report
        dyn.run(0)
    np.testing.assert_allclose(dyn.com_positions[1], expected_com, atol=1e-12)
    assert atoms.get_kinetic_energy() == pytest.approx(ekin, rel=1e-12)
    np.testing.assert_array_equal(dyn.model.body_coordinates, d_ref)
    # A deformed molecule is snapped back onto its rigid shape, with a warning.
    atoms.positions[0] += [0.05, 0, 0]
    with pytest.warns(UserWarning) as record:
        dyn.run(1)
    messages = " ".join(str(w.message) for w in record)
    # Moving one atom by 0.05 Å leaves it a few hundredths of an ångström
    # from the best rigid fit; the momenta read with the refitted geometry
    # are no longer rigid, and the energy that projection removes is reported.
    misfit = float(re.search(r"atoms of body 0 are (\S+) Å from a rigid image", messages)[1])
    assert 0.01 < misfit < 0.05
    removed = float(re.search(r"removed (\S+) eV of kinetic energy", messages)[1])
    assert removed == pytest.approx(dyn.removed_kinetic_energy, rel=1e-5)
    assert removed > 0
    oh = np.linalg.norm(atoms.positions[1] - atoms.positions[0])
    assert oh == pytest.approx(0.9572, abs=1e-12)


def test_trajectory_and_log(tmp_path):
    atoms = waters(4)
    traj, log = tmp_path / "md.traj", tmp_path / "md.log"
    dyn = RigidVerlet(atoms, 1 * units.fs, trajectory=str(traj), logfile=str(log), loginterval=5)
    dyn.run(20)
    frames = read(traj, ":")  # plain ASE, no rigidmd import needed to read
    assert len(frames) == 5
    np.testing.assert_allclose(frames[-1].positions, atoms.positions)
    np.testing.assert_allclose(frames[-1].get_momenta(), atoms.get_momenta())
    assert frames[-1].constraints == []
    header, *lines = [ln.split() for ln in log.read_text().splitlines()]
    assert header == ["Time[ps]", "Etot[eV]", "Epot[eV]", "Ekin[eV]", "T[K]", "Econs[eV]",
                      "T_tr[K]", "T_rot[K]"]
    assert len(lines) == 5
    # The logger's temperature counts 6 degrees of freedom per water.
    assert float(lines[-1][4]) == pytest.approx(atoms.get_temperature(), abs=0.01)
    # T_tr and T_rot split it: 12 translational and 12 rotational degrees of freedom.
    T_tr, T_rot = map(float, lines[-1][6:8])
    assert (T_tr, T_rot) == pytest.approx(dyn.get_kinetic_temperatures(), abs=0.006)
    assert 0.5 * (T_tr + T_rot) == pytest.approx(float(lines[-1][4]), abs=0.011)
    # The conserved energy of NVE is the total energy, with 6 decimals (µeV).
    assert lines[-1][5] == lines[-1][1] and len(lines[-1][1].split(".")[1]) == 6
    assert atoms.get_temperature() == pytest.approx(
        2 * atoms.get_kinetic_energy() / (24 * units.kB))
    with Trajectory(traj) as t:
        assert t.description["md-type"] == "RigidVerlet"


def test_restart_from_trajectory(tmp_path):
    atoms = waters(8)
    traj = tmp_path / "run.traj"
    RigidVerlet(atoms, 1 * units.fs, trajectory=str(traj), loginterval=10).run(200)
    frame = read(traj, index=10)  # step 100
    frame.calc = TIP3P(rc=40)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # frames hold rigid velocities
        RigidVerlet(frame, 1 * units.fs).run(100)
    # Measured 2e-13 Å: the restarted run rebuilds its body frames from the
    # frame, which changes only roundoff.
    assert np.abs(frame.positions - atoms.positions).max() < 1e-8


class Exploding(Calculator):
    """TIP3P until the n-th call, NaN forces after."""

    implemented_properties = ["energy", "forces"]

    def __init__(self, n):
        super().__init__()
        self.n, self.calls, self.tip3p = n, 0, TIP3P(rc=40)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.calls += 1
        self.results = {"energy": self.tip3p.get_potential_energy(atoms),
                        "forces": self.tip3p.get_forces(atoms)}
        if self.calls > self.n:
            self.results["forces"][4, 1] = np.nan


def test_non_finite_forces_stop_the_run_cleanly(tmp_path):
    atoms = waters(4)
    atoms.calc = Exploding(11)  # the first call is the start of the run
    traj, log = tmp_path / "md.traj", tmp_path / "md.log"
    dyn = RigidVerlet(atoms, 1 * units.fs, trajectory=str(traj), logfile=str(log))
    with pytest.raises(NonFiniteForceError, match=r"atom\(s\) \[4\] after step 10"):
        dyn.run(20)
    frames = read(traj, ":")
    assert len(frames) == 11  # steps 0..10
    # The atoms are left at the last good step.
    np.testing.assert_array_equal(frames[-1].positions, atoms.positions)
    assert len(log.read_text().splitlines()) == 12


class NaNEnergy(Calculator):
    """TIP3P forces with a NaN energy."""

    implemented_properties = ["energy", "forces"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.results = {"energy": np.nan, "forces": TIP3P(rc=40).get_forces(atoms)}


def test_non_finite_input_is_named():
    """NaN positions, momenta set between runs, and a NaN energy: atom and quantity named."""
    atoms = waters(4)
    atoms.positions[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"^atom 5 has a non-finite position \[.*nan"):
        RigidVerlet(atoms, units.fs)
    atoms = waters(4)
    atoms.calc = TIP3P(rc=40)
    dyn = RigidVerlet(atoms, units.fs)
    dyn.run(2)
    before = atoms.positions.copy()
    p = atoms.get_momenta()
    p[7, 2] = np.inf
    atoms.set_momenta(p)
    with pytest.raises(ValueError, match=r"atom 7 has a non-finite momentum .* after step 2"):
        dyn.run(2)
    np.testing.assert_array_equal(atoms.positions, before)
    atoms.positions[[3, 9], 0] = np.nan
    with pytest.raises(ValueError, match=r"atom 3 has a non-finite position .* 2 in all"):
        dyn.run(1)
    # A NaN energy stops the run where a logger would write it.
    atoms = waters(4)
    atoms.calc = NaNEnergy()
    dyn = RigidVerlet(atoms, units.fs, logfile="-", loginterval=5)
    with pytest.raises(NonFiniteForceError, match=r"non-finite energy \(nan\) with finite "):
        dyn.run(10)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(timestep=-1.0), ValueError, "timestep must be positive"),
        (dict(timestep="1 fs"), TypeError, "timestep must be a number"),
        (dict(bodies=[[0, 1, 2], [2, 3]]), ValueError, "atom 2 is in both body 0 and body 1"),
        (dict(backend="fortran"), ValueError, "backend must be"),
    ],
)
def test_bad_arguments_change_nothing(tmp_path, kwargs, error, match):
    atoms = waters(2)
    before = atoms.copy()
    traj = tmp_path / "keep.traj"
    traj.write_text("precious")
    args = dict(timestep=1 * units.fs) | kwargs
    with pytest.raises(error, match=match):
        RigidVerlet(atoms, trajectory=str(traj), **args)
    assert traj.read_text() == "precious"
    assert atoms == before and np.array_equal(atoms.get_momenta(), before.get_momenta())
    assert atoms.constraints == []


def test_refuses_other_constraints_and_bad_masses():
    atoms = waters(2)
    atoms.set_constraint(FixBondLengths([[0, 1]]))
    with pytest.raises(ValueError, match="cannot honour other ASE constraints"):
        RigidVerlet(atoms, 1 * units.fs)
    atoms = waters(2)
    masses = atoms.get_masses()
    masses[2] = 0.0
    atoms.set_masses(masses)
    # O and one H left with mass: a linear body cannot carry a massless atom off its axis.
    with pytest.raises(ValueError, match="atom 2 is massless and .* off the axis"):
        RigidVerlet(atoms, 1 * units.fs)
    masses[2] = -1.0
    atoms.set_masses(masses)
    with pytest.raises(ValueError, match="atom 2 .* has mass -1.0"):
        RigidVerlet(atoms, 1 * units.fs)
    with pytest.raises(TypeError, match="must be an ase.Atoms"):
        RigidVerlet([atoms], 1 * units.fs)


def test_trajectory_frames_carry_the_bodies_in_their_tags(tmp_path):
    """ASE's .traj drops the mol-id array; the tags rigidmd sets keep the bodies."""
    from rigidmd import RigidBodies
    from rigidmd.systems import co2_water_mixture

    atoms = co2_water_mixture(n_co2=8, n_water=8, box=True)  # connectivity would join two
    atoms.calc = ZeroForce()
    dyn = RigidVerlet(atoms, units.fs, trajectory=str(tmp_path / "md.traj"))
    dyn.run(4)
    dyn.close()
    assert dyn.model.n_bodies == 16
    for frame in read(tmp_path / "md.traj", ":"):
        assert "mol-id" not in frame.arrays
        again = RigidBodies.resolve(frame)  # default rule: the tags
        assert again.rule == "tags" and again.n_bodies == 16
        np.testing.assert_array_equal(again.body_ids, dyn.bodies.body_ids)
    # Tags that mean something else are kept, with a warning.
    other = co2_water_mixture(n_co2=2, n_water=2)
    other.set_tags(np.arange(len(other)) % 2)
    other.calc = ZeroForce()
    with pytest.warns(UserWarning, match="tags group them differently"):
        RigidVerlet(other, units.fs, bodies="mol-id")
    np.testing.assert_array_equal(other.get_tags(), np.arange(len(other)) % 2)


def test_a_too_large_time_step_is_reported_once():
    """100 fs: the waters spin by tens of radians per step, and the run says so, once."""
    atoms = waters(4)
    atoms.calc = TIP3P(rc=40)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    dyn = RigidVerlet(atoms, 100 * units.fs)
    with pytest.warns(UserWarning, match=r"body \d turns by .* rad per step at step 10 .* "
                      r"time step 100 fs is probably too large") as record:
        dyn.run(50)
    assert len([w for w in record if "too large" in str(w.message)]) == 1
    # Point particles: the energy check (where a logger has the energy computed anyway).
    from ase.calculators.lj import LennardJones

    argon = Atoms("Ar3", positions=[[0, 0, 0], [3.8, 0, 0], [1.9, 3.3, 0]])
    argon.calc = LennardJones(sigma=3.4, epsilon=0.0104, rc=10.0)
    argon.set_momenta([[0.0, 0.0, 0.0], [-20.0, 0.0, 0.0], [0.0, -20.0, 0.0]])
    dyn = RigidVerlet(argon, 20 * units.fs, bodies=[], logfile="/dev/null")
    with pytest.warns(UserWarning, match=r"the conserved energy changed by .* kinetic energy"):
        dyn.run(20)
    # 2 fs: no warning (measured largest |omega| dt 0.14 rad, energy change 0.2 % of K).
    atoms = waters(4)
    atoms.calc = TIP3P(rc=40)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        RigidVerlet(atoms, 2 * units.fs, logfile="/dev/null").run(100)


def test_rigid_temperature_of_stored_frames(tmp_path):
    """A frame read back reports 2/3 of the logged temperature; rigid_temperature the same."""
    from rigidmd import rigid_temperature

    atoms = waters(4)
    atoms.calc = TIP3P(rc=40)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(5))
    traj = tmp_path / "md.traj"
    dyn = RigidVerlet(atoms, units.fs, trajectory=str(traj), loginterval=5)
    logged = []
    dyn.attach(lambda: logged.append(atoms.get_temperature()), interval=5)
    dyn.run(20)
    dyn.close()
    frames = read(traj, ":")
    np.testing.assert_allclose(rigid_temperature(traj), logged, rtol=1e-12)
    np.testing.assert_allclose(rigid_temperature(frames), logged, rtol=1e-12)
    assert rigid_temperature(frames[-1]) == pytest.approx(logged[-1], rel=1e-12)
    # 12 atoms, 4 rigid waters: 36 / 24 of the rigid count in plain ASE.
    assert frames[-1].get_temperature() == pytest.approx(logged[-1] * 24 / 36, rel=1e-12)
    with pytest.raises(ValueError, match="frame 1 has 9 atoms"):
        rigid_temperature([frames[0], frames[1][:9]])


def test_import_without_a_writable_numba_cache():
    """numba refuses cache=True when it finds no writable place; rigidmd then compiles."""
    pytest.importorskip("numba")
    import subprocess
    import sys

    code = """
import numba.core.caching as caching
caching.CacheImpl._locator_classes = []  # what a read-only install with no home gives
import numpy as np
from ase import units
from ase.calculators.tip3p import TIP3P
import rigidmd.core._numba as compiled
from rigidmd import RigidVerlet
from rigidmd.systems import water_cluster
assert not compiled.CACHED
atoms = water_cluster(2)
atoms.calc = TIP3P(rc=40)
RigidVerlet(atoms, units.fs, backend="numba").run(3)
print("ran")
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "ran"


def test_plot_reads_old_and_new_logs(tmp_path):
    """``rigidmd plot``'s temperature panel: T_tr and T_rot when logged; a log written
    before those columns (ASE's columns and Econs) still plots, with T alone."""
    from rigidmd.run.logplot import plot_log, read_log, temperature_curves

    atoms = waters(4)
    log = tmp_path / "md.log"
    RigidVerlet(atoms, 1 * units.fs, logfile=str(log), loginterval=5).run(10)
    labels = [label for label, _ in temperature_curves(read_log(log))]
    assert labels == ["T", "T_tr (translation)", "T_rot (rotation)"]
    old = tmp_path / "old.log"
    old.write_text("\n".join(" ".join(line.split()[:6]) for line in
                             log.read_text().splitlines()) + "\n")
    assert [label for label, _ in temperature_curves(read_log(old))] == ["T"]
    for path in (log, old):
        assert plot_log(path, tmp_path / f"{path.stem}.png").stat().st_size > 0
def _every_dynamics():
    """One of each user class, by name: NVE, the thermostats, the barostats."""
    from helpers import dimer_fluid

    from rigidmd import (
        RigidBussi,
        RigidCRescale,
        RigidLangevin,
        RigidLangevinBAOAB,
        RigidMCBarostat,
        RigidNoseHoover,
        RigidNPT,
    )

    rng = np.random.default_rng
    fluid = {"bodies": "tags"}
    return {
        "RigidVerlet": lambda cls=RigidVerlet: cls(mixture(), units.fs, bodies="mol-id"),
        "RigidLangevin": lambda cls=RigidLangevin: cls(
            mixture(), units.fs, temperature_K=300, friction=0.01 / units.fs,
            bodies="mol-id", rng=rng(1)),
        "RigidBussi": lambda cls=RigidBussi: cls(mixture(), units.fs, 300, 20 * units.fs,
                                                 bodies="mol-id", rng=rng(1)),
        "RigidLangevinBAOAB": lambda cls=RigidLangevinBAOAB: cls(
            mixture(), units.fs, temperature_K=300, friction=0.01 / units.fs,
            bodies="mol-id", rng=rng(1)),
        "RigidNoseHoover": lambda cls=RigidNoseHoover: cls(
            mixture(), units.fs, temperature_K=300, tdamp=50 * units.fs, bodies="mol-id"),
        "RigidNPT": lambda cls=RigidNPT: cls(dimer_fluid(n_side=2, rc=3.0), 2 * units.fs, 80,
                                             units.bar, 50 * units.fs, 500 * units.fs,
                                             **fluid),
        "RigidCRescale": lambda cls=RigidCRescale: cls(
            dimer_fluid(n_side=2, rc=3.0), 2 * units.fs, 80, units.bar, 50 * units.fs,
            500 * units.fs, 1e-4 / units.bar, rng=rng(1), **fluid),
        "RigidMCBarostat": lambda cls=RigidMCBarostat: cls(
            dimer_fluid(n_side=2, rc=3.0), 2 * units.fs, 80, units.bar, 50 * units.fs,
            every=2, rng=rng(1), **fluid),
    }


@pytest.mark.parametrize("name", list(_every_dynamics()))
def test_irun_calls_what_ase_calls_in_its_order(name):
    """ASE's test_irun_force_call_order, for every rigid dynamics: a subclass may override
    ``_refresh_properties`` and ``log``, and irun calls them as ASE's loop does."""
    dyn = _every_dynamics()[name]()
    calls = []

    def record(what):
        return lambda *args, **kwargs: calls.append(what)

    for what in ("step", "_refresh_properties", "log", "call_observers"):
        setattr(dyn, what, record(what))
    list(dyn.irun(steps=2))
    assert calls == ["_refresh_properties", "log", "call_observers",
                     "step", "_refresh_properties", "log", "call_observers",
                     "step", "_refresh_properties", "log", "call_observers"]


def test_a_subclass_log_is_called_at_every_step_of_a_run():
    logged = []

    class Logged(RigidVerlet):
        def log(self):
            logged.append((self.nsteps, self.atoms.get_potential_energy()))

    atoms = mixture()
    dyn = Logged(atoms, units.fs, bodies="mol-id")
    dyn.run(3)
    dyn.run(2)
    assert [n for n, _ in logged] == [0, 1, 2, 3, 4, 5]
    # The log reads the energy of the atoms as they are at that step.
    assert logged[-1][1] == atoms.get_potential_energy()


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_a_state_exported_before_the_first_force_call_continues_exactly(kind, backend):
    """``get_state()`` of a dynamics that never called its calculator holds no forces (it
    says so: ``forces_known`` False); restored, the next run's start calls the calculator,
    as the original's did, so a barostat's first step has its virial and the run is the
    uninterrupted one bit for bit: restored in a new dynamics, and in one whose calculator
    holds results for these very positions (a ``run(0)``), which are not the record's."""
    from helpers import dimer_fluid, npt

    def build():
        return npt(dimer_fluid(n_side=3, rc=5.0), kind, backend=backend)

    reference = build()
    reference.run(4)
    saved = build().get_state()
    assert saved["record"]["forces_known"] is False and saved["record"]["virial"] is None
    restored = build()
    restored.set_state(saved)
    restored.run(4)
    assert restored.record.virial is not None and restored.record.forces_known
    again = build()
    again.run(0)  # the calculator now holds results for the saved positions
    again.set_state(saved)
    again.run(4)
    for dyn in (restored, again):
        np.testing.assert_array_equal(dyn.atoms.positions, reference.atoms.positions)
        np.testing.assert_array_equal(dyn.atoms.get_momenta(), reference.atoms.get_momenta())
        np.testing.assert_array_equal(dyn.atoms.cell.array, reference.atoms.cell.array)
        assert dyn.get_state()["record"]["forces_known"] is True


def test_from_parts_builds_the_class_around_ready_parts_and_checks_them():
    """``cls.from_parts`` gives an instance of ``cls`` holding the very parts (as the class
    holds them: ``thermostat``, ``barostat``), and refuses parts the class is not built
    around in one line, before touching the atoms."""
    from helpers import dimer_fluid

    from rigidmd import RigidBussi, RigidDynamics, RigidNPT
    from rigidmd.couplings.barostats import MTKBarostat
    from rigidmd.couplings.thermostats import BussiThermostat, NoseHooverThermostat

    part = BussiThermostat(300, 50 * units.fs)
    dyn = RigidBussi.from_parts(waters(2), units.fs, [part])
    assert type(dyn) is RigidBussi and dyn.thermostat is part and dyn.couplings == (part,)
    assert dyn.taut == 50 * units.fs and dyn.todict()["md-type"] == "RigidBussi"
    parts = [NoseHooverThermostat(80, 50 * units.fs), MTKBarostat(80, 0.0, 500 * units.fs)]
    npt = RigidNPT.from_parts(dimer_fluid(n_side=3, rc=5.0), units.fs, parts, bodies="tags")
    assert (npt.thermostat, npt.barostat) == tuple(parts)
    plain = RigidDynamics.from_parts(waters(2), units.fs, [BussiThermostat(300, 50 * units.fs)])
    assert type(plain) is RigidDynamics
    atoms = waters(2)
    before = atoms.positions.copy()
    for cls, given, message in [
            (RigidVerlet, [part], "RigidVerlet is built around the parts none; got "
                                  "BussiThermostat"),
            (RigidBussi, [], "RigidBussi is built around the parts BussiThermostat; got none"),
            (RigidNPT, [part, parts[1]], "RigidNPT is built around the parts "
                                         "NoseHooverThermostat, MTKBarostat; got "
                                         "BussiThermostat, MTKBarostat")]:
        with pytest.raises(ValueError) as err:
            cls.from_parts(atoms, units.fs, given)
        assert str(err.value) == message
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def _hand_built(kind, backend):
    from helpers import dimer_fluid, npt

    from rigidmd import RigidLangevinBAOAB

    if kind == "verlet":
        return RigidVerlet(dimer_fluid(n_side=3, rc=5.0), units.fs, bodies="tags",
                           backend=backend)
    if kind == "baoab":
        return RigidLangevinBAOAB(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs,
                                  temperature_K=80, friction=0.01 / units.fs, bodies="tags",
                                  rng=np.random.default_rng(5), backend=backend)
    return npt(dimer_fluid(n_side=3, rc=5.0), kind, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", ["verlet", "baoab", "mtk", "crescale"])
def test_steps_by_hand_are_the_run(kind, backend):
    """``for _ in range(n): dyn.step()`` on a dynamics never run, as ASE users drive it:
    the first step kicked with zero forces (3.9e-5 Å off ``run(3)`` after 3 steps of the
    dimer fluid) and MTK's raised numba's TypingError (no virial).  Each step by hand now
    starts as a run does, so the steps are ``run(n)`` bit for bit, with the same calculator
    calls, and a state saved after them says its forces are known."""
    runs = []
    for by_hand in (False, True):
        dyn = _hand_built(kind, backend)
        calls = []
        calc = dyn.atoms.calc
        original = calc.calculate

        def counted(*args, _calls=calls, _original=original, **kwargs):
            _calls.append(1)
            return _original(*args, **kwargs)

        calc.calculate = counted
        if by_hand:
            for _ in range(3):
                dyn.step()
        else:
            dyn.run(3)
        assert dyn.get_state()["record"]["forces_known"] is True
        runs.append((dyn.atoms.positions.copy(), dyn.atoms.get_momenta(),
                     dyn.atoms.cell.array.copy(), len(calls)))
    (p0, m0, c0, n0), (p1, m1, c1, n1) = runs
    np.testing.assert_array_equal(p1, p0)
    np.testing.assert_array_equal(m1, m0)
    np.testing.assert_array_equal(c1, c0)
    assert n1 == n0


def test_a_step_by_hand_reads_what_was_changed_on_the_atoms():
    """Between steps by hand the Atoms may be changed, as between runs (ASE's steps read the
    Atoms each time): a body moved by hand moves the same as between two runs (and not as
    if it had stayed: the old step wrote its own state over the change)."""

    def advance(dyn, by_hand):
        if by_hand:
            dyn.step()
        else:
            dyn.run(1)

    runs = {}
    for by_hand, shift in ((False, 0.05), (True, 0.05), (True, 0.0)):
        dyn = _hand_built("verlet", "numpy")
        advance(dyn, by_hand)
        atoms = dyn.atoms
        positions = atoms.positions.copy()
        positions[atoms.get_tags() == atoms.get_tags()[0]] += shift  # one body, moved whole
        atoms.positions = positions
        advance(dyn, by_hand)
        runs[(by_hand, shift)] = atoms.positions.copy()
    np.testing.assert_array_equal(runs[(True, 0.05)], runs[(False, 0.05)])
    assert np.abs(runs[(True, 0.05)] - runs[(True, 0.0)]).max() > 0.04
