"""Rotational correlation of bodies (rigidmd.mdanalysis.rotation): free rotors spinning
about the normal of their plane have u(0)·u(t) = cos ωt, so C1 = cos ωt and
C2 = (3 cos² ωt − 1)/2.
"""

import warnings

import numpy as np
import pytest

mda = pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')
from ase import units
from helpers import ZeroForce, water_frames

from rigidmd import RigidBodies, RigidVerlet
from rigidmd.lammps import tip3p_charges
from rigidmd.mdanalysis import (
    PS,
    RotationalCorrelation,
    body_dipole_directions,
    orientational_correlation,
    relaxation_time,
    to_universe,
)
from rigidmd.systems import water_box

pytestmark = pytest.mark.filterwarnings(
    "ignore:DCDReader currently makes independent timesteps:DeprecationWarning")


# ---------------------------------------------------------------------------- rotation


@pytest.fixture
def spinning_waters():
    """Waters spinning at omega about the normal of their plane (a principal axis)."""
    rng = np.random.default_rng(3)
    atoms = water_box(2, seed=3, spacing=8.0)  # far apart: no interactions anyway
    atoms.set_initial_charges(tip3p_charges(atoms))
    omega = 2 * np.pi / (0.4 * PS)  # one turn in 0.4 ps
    atoms.positions = RigidBodies.resolve(atoms, "mol-id").whole_positions(atoms)
    atoms.pbc, atoms.cell = False, None  # isolated molecules
    x = atoms.positions.reshape(-1, 3, 3)
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    m = atoms.get_masses().reshape(-1, 3)
    com = np.einsum("ni,nij->nj", m, x) / m.sum(axis=1, keepdims=True)
    v = rng.normal(scale=0.01, size=(len(x), 1, 3)) + omega * np.cross(
        normal[:, None, :], x - com[:, None, :])
    atoms.set_momenta((m[..., None] * v).reshape(-1, 3))
    atoms.calc = ZeroForce()
    return atoms, omega


def test_dipole_correlation_of_free_rotors(spinning_waters):
    atoms, omega = spinning_waters
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    frames, dipoles = [], []

    def record():
        frames.append(atoms.copy())
        dipoles.append(body_dipole_directions(dyn))

    dyn.attach(record, interval=4)
    dyn.run(400)  # 0.4 ps: one turn; frames every 4 fs
    t = np.arange(len(frames)) * 4 * units.fs
    expected1 = np.cos(omega * t)
    expected2 = 1.5 * expected1**2 - 0.5
    # From the bodies' orientations (quaternions): exact up to roundoff.
    c1, c2 = orientational_correlation(np.array(dipoles))
    np.testing.assert_allclose(c1, expected1, atol=1e-9)
    np.testing.assert_allclose(c2, expected2, atol=1e-9)
    # From atom positions through MDAnalysis (float32 coordinates).
    u = to_universe(frames, bodies="mol-id", dt=0.004)
    for vector in ("dipole", "bisector"):
        rot = RotationalCorrelation(u, vector=vector, max_lag=0.4).run()
        assert rot.results.vector == vector
        np.testing.assert_allclose(rot.results.times, t / PS, atol=1e-12)
        np.testing.assert_allclose(rot.results.c1, expected1, atol=2e-5)
        np.testing.assert_allclose(rot.results.c2, expected2, atol=2e-5)


def test_rotational_relaxation_times(tmp_path):
    t = np.arange(0, 10, 0.01)
    c = 0.9 * np.exp(-t / 2.0)
    tau, integral, amplitude = relaxation_time(t, c)
    assert tau == pytest.approx(2.0, rel=1e-10) and amplitude == pytest.approx(0.9)
    assert integral == pytest.approx(1.8, rel=1e-4)
    assert np.isnan(relaxation_time(t[:3], c[:3])[0])  # too few points in the window
    # Molecules that diffuse in orientation: C1 = exp(-2 Dr t), C2 = exp(-6 Dr t).
    rng = np.random.default_rng(11)
    Dr, dt, n = 0.5, 0.01, 2000
    u = np.tile([0.0, 0.0, 1.0], (300, 1))
    vectors = np.empty((n, 300, 3))
    for k in range(n):  # small random rotations (Euler-Maruyama on the sphere)
        vectors[k] = u
        kick = rng.normal(scale=np.sqrt(2 * Dr * dt), size=u.shape)
        u = u + np.cross(kick, u)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
    c1, c2 = orientational_correlation(vectors, max_lag=200)
    lag = np.arange(201) * dt
    assert relaxation_time(lag, c1)[0] == pytest.approx(1 / (2 * Dr), rel=0.1)
    assert relaxation_time(lag, c2)[0] == pytest.approx(1 / (6 * Dr), rel=0.1)
    with pytest.raises(ValueError, match="shape"):
        orientational_correlation(np.zeros((5, 3)))


def test_rotational_correlation_needs_charges_for_dipoles(tmp_path):
    frames = water_frames(6)
    for f in frames:
        f.set_initial_charges(None)
    u = to_universe(frames, dt=0.01)
    with pytest.raises(ValueError, match="charges"):
        RotationalCorrelation(u, vector="dipole")
    rot = RotationalCorrelation(u).run()  # auto: no charges, so the bisector
    assert rot.results.vector == "bisector"
    np.testing.assert_allclose(rot.results.c1, 1.0, atol=1e-5)  # rigid translation only
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert rot.plot(tmp_path / "rot.png") is not None
    assert (tmp_path / "rot.png").stat().st_size > 0
    with pytest.raises(ValueError, match="matches no atoms"):
        RotationalCorrelation(u, select="resname XYZ")


def test_a_window_outside_the_correlation_is_refused(spinning_waters):
    """(0.5, 0.1) gave NaN times in silence."""
    u = to_universe(spinning_waters[0])
    for bad in ((0.5, 0.1), (0.0, 0.5), (0.1, 1.5), 0.3):
        with pytest.raises(ValueError, match="window must be"):
            RotationalCorrelation(u, window=bad)


def test_max_lag_must_be_a_positive_time():
    """``max_lag=-3.0`` gave one lag and τ NaN in silence; ``"0.2 ps"`` a bare TypeError."""
    u = to_universe(water_frames(6), dt=0.1)
    for bad in (-3.0, "0.2 ps", float("nan"), float("inf"), True, 0):
        with pytest.raises(ValueError, match=r"^RotationalCorrelation: max_lag must be a "
                                             "positive time in ps"):
            RotationalCorrelation(u, vector="bisector", max_lag=bad)
    with pytest.raises(ValueError, match=r"^RotationalCorrelation: max_lag 0.02 ps is shorter "
                                         r"than the time between the frames analysed \(0.1 ps"):
        RotationalCorrelation(u, vector="bisector", max_lag=0.02).run()
    rot = RotationalCorrelation(u, vector="bisector", max_lag=0.2).run()
    np.testing.assert_allclose(rot.results.times, [0.0, 0.1, 0.2], rtol=1e-6)
