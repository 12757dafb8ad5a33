"""The BAOAB part (rigidmd.couplings.baoab): its kernels against its operators, its physics.

The class RigidLangevinBAOAB (``friction`` or ``T_tau``, its refusals, its checkpoint) is
tested in ``tests/md/test_langevinbaoab.py``.

The physics is checked on a system with an exact answer: independent rigid
water-shaped tops whose atoms are tethered to fixed points by springs
proportional to their masses, :math:`U = \\tfrac12 k\\sum_i m_i |x_i - a_i|^2`.
Then :math:`U = \\tfrac12 kM|X - A|^2 + k(1 - \\cos\\theta)\\,n^\\mathsf{T} I n`
(rotation by :math:`\\theta` about :math:`n` from the anchored orientation): the
centre of mass is a harmonic oscillator of frequency :math:`\\sqrt k`
(:math:`\\langle U_\\mathrm{tr}\\rangle = \\tfrac32 k_BT` exactly), and every small
rotation too; :math:`\\langle U_\\mathrm{rot}\\rangle` is an integral over the rotation
group, computed here by quadrature.
"""

import numpy as np
import pytest
from ase import units
from helpers import benchmark_module, block_mean, mixture

from rigidmd import RigidDynamics, RigidLangevin, RigidLangevinBAOAB
from rigidmd.core import _numba
from rigidmd.core import operators as ops
from rigidmd.couplings import _numba as coupling_kernels
from rigidmd.couplings import _numpy as coupling_references
from rigidmd.couplings.baoab import LangevinBAOABThermostat
from rigidmd.couplings.base import NotExportable

#: The tethered tops and their exact rotational energy: validation/baoab_tethered_tops.py's.
TOPS = benchmark_module("baoab_tethered_tops")
tethered_tops, exact_rotational_energy = TOPS.tethered_tops, TOPS.exact_rotational_energy


def sample(cls, dt, steps, n=128, T=300.0, equilibration=200, seed=1, backend=None):
    """Per step after equilibration: U_tr, U_rot, reported T_tr, T_rot, end-of-step T_tr, T_rot."""
    atoms, k, bodies = tethered_tops(n, 0.5 / dt)  # omega dt = 0.5 on every degree
    dyn = cls(atoms, dt, T, 0.5 / dt, rng=np.random.default_rng(seed), fixcm=False,
              bodies=bodies, backend=backend)
    anchors, M, km = dyn.state.X.copy(), dyn.model.mass, atoms.calc.km
    rows = []

    def record():
        if dyn.nsteps < equilibration:
            return
        U = 0.5 * float(np.sum(km * (atoms.positions - atoms.calc.anchors) ** 2))
        U_tr = 0.5 * k * float(M @ ((dyn.state.X - anchors) ** 2).sum(1))
        end = (dyn.get_translational_kinetic_energy(), dyn.get_rotational_kinetic_energy())
        rows.append((U_tr, U - U_tr, *dyn.get_kinetic_temperatures(),
                     *(2 * K / (3 * n * units.kB) for K in end)))

    record.modifies_atoms, record.wants_properties = False, False
    dyn.attach(record)
    dyn.run(steps)
    return np.array(rows), dyn, k


def test_baoab_samples_the_exact_distribution_where_langevin_does_not():
    """At omega dt = 0.5: BAOAB's <U> exact, its post-O T_tr, T_rot the bath's, its
    end-of-step ones low by omega^2 dt^2 / 4; RigidLangevin's <U> high by as much."""
    T, dt, n = 300.0, 4 * units.fs, 128
    kT = units.kB * T
    baoab, dyn, k = sample(RigidLangevinBAOAB, dt, 1400, n)
    langevin, _, _ = sample(RigidLangevin, dt, 1400, n)
    exact = (1.5 * n * kT, n * exact_rotational_energy(dyn.model.moments[0], k, kT))
    assert exact[1] / exact[0] == pytest.approx(1.0042, abs=1e-4)  # nearly harmonic
    for column in (0, 1):
        # Measured (seeds 1-3, 1200 samples of 128 tops): block errors 0.3-0.5 % of <U>;
        # BAOAB within 0.8 % of exact (at most 1.5 errors), RigidLangevin 6.2-6.9 % high
        # (the harmonic OBABO error, 1 / (1 - omega^2 dt^2 / 4) - 1 = 6.7 %).  Bounds: four
        # times the largest error, 2 %, from 1; and 3.5 % (half the bias) for Langevin.
        assert block_mean(baoab[:, column])[0] / exact[column] == pytest.approx(1.0, abs=0.02)
        assert block_mean(langevin[:, column])[0] / exact[column] > 1.035
    # Kinetic temperatures, measured (seeds 1-3): after O (reported) 298.6-300.0 K, block
    # errors 0.6-1.2 K; at the end of the step 280.3-281.5 K, i.e. T (1 - omega^2 dt^2 / 4)
    # = 281.25 K, errors likewise.  Bounds: four times the largest error, 5 K.
    for column in (2, 3):
        assert block_mean(baoab[:, column])[0] == pytest.approx(T, abs=5.0)
        assert block_mean(baoab[:, column + 2])[0] == pytest.approx(T * (1 - 0.25**2), abs=5.0)
        assert block_mean(langevin[:, column])[0] == pytest.approx(T, abs=5.0)
    # RigidLangevin reports the end of its step, which samples the bath (O comes last).
    np.testing.assert_array_equal(langevin[:, 2:4], langevin[:, 4:6])


def test_kernels_are_the_operators():
    """Each fused loop of the baoab kernel, and the O kernel, against the NumPy operators."""
    atoms = mixture()
    dyn = RigidLangevinBAOAB(atoms, units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                             rng=np.random.default_rng(2), backend="numpy")
    dyn.run(3)
    m, dt, record = dyn.model, 2 * units.fs, dyn.record
    body, atom, index = m.packed
    n = m.n_bodies
    ref, fused = dyn.state.copy(), dyn.state.copy()
    # B and the first A: translational_kick, rotational_kick, drift, free rotor, each dt/2.
    ops.translational_kick(ref, record.F, record.f, m, 0.5 * dt)
    ops.rotational_kick(ref, record.tau, 0.5 * dt)
    ops.drift(ref, 0.5 * dt)
    ops.free_rotor(ref, m.inv_moments, 0.5 * dt)
    _numba.kick_half_drift(fused.data, n, record.F, record.tau, body, dt)
    # Measured: X and V identical, q and p within 3e-16 relative (the kernel's Taylor
    # sin/cos and fused sums round differently), as for the no_squish kernel.
    for name in ("X", "V", "q", "p"):
        np.testing.assert_allclose(getattr(fused, name), getattr(ref, name), rtol=1e-14,
                                   atol=1e-15)
    fused.data[...] = ref.data  # each loop from the same state (free atoms: NumPy's own)
    # O: the same deviates into the kernel and into the reference.
    noise = np.random.default_rng(3).standard_normal(6 * n + 3 * m.n_free)
    scales = (1.0 / np.sqrt(m.mass), 1.0 / np.sqrt(m.free_masses), np.sqrt(m.moments))
    coupling_references.ornstein_uhlenbeck(ref.data, n, m.n_free, 0.8, 0.05, *scales, noise)
    coupling_kernels.ornstein_uhlenbeck(fused.data, n, m.n_free, 0.8, 0.05, *scales, noise)
    np.testing.assert_allclose(fused.data, ref.data, rtol=1e-14, atol=1e-15)
    assert not np.array_equal(ref.V, dyn.state.V)  # it did act
    fused.data[...] = ref.data
    # The second A and the placement.
    ops.drift(ref, 0.5 * dt)
    ops.free_rotor(ref, m.inv_moments, 0.5 * dt)
    r_ref, x_ref = ops.place_atoms(ref, m)
    r, positions = np.zeros_like(r_ref), np.zeros((len(atoms), 3))
    _numba.half_drift_place(fused.data, n, body, atom, index, dt, r, positions)
    for name in ("X", "V", "q", "p"):
        np.testing.assert_allclose(getattr(fused, name), getattr(ref, name), rtol=1e-14,
                                   atol=1e-15)
    np.testing.assert_allclose(r, r_ref, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(positions[m.order], x_ref, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("fixcm", [True, False])
def test_numba_and_numpy_paths_agree(fixcm):
    """30 steps on each backend from the same seed: the same trajectory to roundoff."""
    runs = []
    for backend in ("numpy", "numba"):
        atoms = mixture()
        dyn = RigidLangevinBAOAB(atoms, 2 * units.fs, 300, 0.02 / units.fs, bodies="mol-id",
                                 rng=np.random.default_rng(4), fixcm=fixcm, backend=backend)
        assert dyn.fused == (backend == "numba") and dyn.scheme.name == "baoab"
        dyn.run(30)
        runs.append((atoms.positions.copy(), atoms.get_momenta(), dyn.get_conserved_energy(),
                     dyn.get_kinetic_temperatures()))
    # Measured: positions within 2e-14 Å, momenta 3e-14, after 30 steps of roundoff growth.
    np.testing.assert_allclose(runs[1][0], runs[0][0], rtol=0, atol=1e-11)
    np.testing.assert_allclose(runs[1][1], runs[0][1], rtol=0, atol=1e-11)
    assert runs[1][2] == pytest.approx(runs[0][2], abs=1e-10)
    assert runs[1][3] == pytest.approx(runs[0][3], rel=1e-10)


def test_one_force_call_per_step_and_one_draw():
    atoms = mixture()
    rng = np.random.default_rng(5)
    dyn = RigidLangevinBAOAB(atoms, 2 * units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                             rng=rng)
    assert dyn.scheme.force_calls_per_step == 1
    state = dict(rng.bit_generator.state)
    dyn.run(1)
    # One call of 6 n + 3 n_free deviates: the generator is where one such call leaves it.
    copy = np.random.default_rng(5)
    copy.bit_generator.state = state
    copy.standard_normal(6 * dyn.model.n_bodies + 3 * dyn.model.n_free)
    assert rng.bit_generator.state == copy.bit_generator.state


def test_the_default_integrator_becomes_baoab_and_others_are_refused():
    part = LangevinBAOABThermostat(300, 0.01 / units.fs)
    dyn = RigidDynamics(mixture(), units.fs, bodies="mol-id", couplings=[part])
    assert dyn.scheme.name == "baoab"
    with pytest.raises(ValueError, match="acts in the middle of the step.*'richardson' has none"):
        RigidLangevinBAOAB(mixture(), units.fs, 300, 0.01, bodies="mol-id",
                           integrator="richardson")


def test_a_barostat_moving_the_cell_in_the_drift_is_refused():
    from helpers import dimer_fluid

    from rigidmd.couplings.barostats import CRescaleBarostat
    atoms = dimer_fluid(n_side=3, rc=5.0)
    parts = [LangevinBAOABThermostat(80, 0.01 / units.fs, fixcm=False),
             CRescaleBarostat(80, units.bar, 500 * units.fs, 1e-4 / units.bar)]
    with pytest.raises(ValueError, match="langevin_baoab acts in the middle.*crescale barostat"):
        RigidDynamics(atoms, units.fs, bodies="tags", couplings=parts)


def test_the_fused_kernels_fall_back_on_the_scheme_itself():
    """Under a barostat the baoab kernel runs its operator list: the built-in scheme's."""
    from rigidmd.core.schemes import BUILTIN_SCHEMES, OPERATORS
    from rigidmd.core.stepcontext import BAOAB_OPERATORS

    scheme = [(OPERATORS[name].function, params.get("dt_scale"))
              for name, params in BUILTIN_SCHEMES["baoab"]]
    assert [(function, scale) for function, scale, _ in BAOAB_OPERATORS] == scheme


def test_monte_carlo_barostat_composes():
    from helpers import dimer_fluid

    from rigidmd import RigidMCBarostat
    atoms = dimer_fluid(n_side=3, rc=5.0)
    dyn = RigidMCBarostat(atoms, 2 * units.fs, 80, units.bar, bodies="tags", every=2,
                          thermostat=LangevinBAOABThermostat(80, 0.01 / units.fs,
                                                             fixcm=False),
                          rng=np.random.default_rng(1))
    assert dyn.scheme.name == "baoab"
    dyn.run(6)
    assert np.isfinite(dyn.get_conserved_energy())


def test_lammps_export_is_refused_in_one_line():
    part = LangevinBAOABThermostat(300, 0.01 / units.fs)
    with pytest.raises(NotExportable, match="BAOAB.*export with kind langevin") as err:
        part.lammps_fix(units.fs)
    assert "\n" not in str(err.value)


def test_log_reports_post_O_temperatures(tmp_path):
    """The log's T, T_tr, T_rot are those after O; Econs that of the end of the step."""
    atoms = mixture()
    log = tmp_path / "md.log"
    dyn = RigidLangevinBAOAB(atoms, 2 * units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                             rng=np.random.default_rng(6), logfile=str(log))
    dyn.run(4)
    header, *lines = [line.split() for line in log.read_text().splitlines()]
    last = dict(zip(header, map(float, lines[-1]), strict=True))
    K_tr, K_rot = dyn.thermostat.reported
    assert (last["T_tr[K]"], last["T_rot[K]"]) == pytest.approx(
        dyn.get_kinetic_temperatures(), abs=0.006)
    assert last["Ekin[eV]"] == pytest.approx(K_tr + K_rot, abs=1e-6)
    assert last["Ekin[eV]"] != pytest.approx(dyn.atoms.get_kinetic_energy(), abs=1e-5)
    assert last["Econs[eV]"] == pytest.approx(dyn.get_conserved_energy(), abs=1e-6)


def test_configured_run_resumes_bit_for_bit(tmp_path, monkeypatch, capsys):
    """``thermostat: {kind: langevin_baoab}`` from the command line: the summary's T_tr and
    T_rot are post-O; 20 steps, then --resume to 40, writes the bytes of 40 straight."""
    from helpers import file_bytes, run_here, short_project

    straight = short_project(tmp_path / "straight", thermostat="langevin_baoab")
    status, stdout, stderr = run_here(straight, monkeypatch, capsys)
    assert status == 0, stderr
    assert "baoab integrator" in stdout
    assert "T_tr = " in stdout and "(after the O step)" in stdout
    header = (straight / "out" / "md.log").read_text().splitlines()[0].split()
    assert header[6:8] == ["T_tr[K]", "T_rot[K]"]
    resumed = short_project(tmp_path / "resumed", thermostat="langevin_baoab")
    assert run_here(resumed, monkeypatch, capsys, "--steps", 20)[0] == 0
    status, _, stderr = run_here(resumed, monkeypatch, capsys, "--resume")
    assert status == 0, stderr
    assert file_bytes(resumed) == file_bytes(straight)


@pytest.mark.parametrize("case", ["numpy", "monte_carlo"])
def test_checkpoints_continue_bit_for_bit(tmp_path, case):
    """The NumPy path, and the composition with the Monte Carlo barostat (the numba
    backend alone is in tests/core/test_checkpoint.py): 12 steps, or 5, a checkpoint, 7 more."""
    from helpers import CoulombLJ, PeriodicLJ, dimer_fluid

    from rigidmd import RigidMCBarostat, load_checkpoint

    def build():
        rng = np.random.default_rng(8)
        if case == "numpy":
            return RigidLangevinBAOAB(mixture(), 2 * units.fs, 300, 0.01 / units.fs, rng=rng,
                                      bodies="mol-id", backend="numpy")
        part = LangevinBAOABThermostat(80, 0.01 / units.fs, rng=rng, fixcm=False)
        return RigidMCBarostat(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, 80, units.bar,
                               bodies="tags", every=2, thermostat=part, rng=rng)

    reference = build()
    reference.run(12)
    first = build()
    first.run(5)
    first.save_checkpoint(tmp_path / "state.npz")
    calculator = CoulombLJ() if case == "numpy" else PeriodicLJ(rc=5.0)
    resumed = load_checkpoint(tmp_path / "state.npz", calculator)
    assert resumed.scheme.name == "baoab"
    assert resumed.thermostat.reported == first.thermostat.reported
    resumed.run(7)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(resumed.atoms.get_momenta(), reference.atoms.get_momenta())
    np.testing.assert_array_equal(resumed.atoms.cell.array, reference.atoms.cell.array)
    assert resumed.get_kinetic_temperatures() == reference.get_kinetic_temperatures()
