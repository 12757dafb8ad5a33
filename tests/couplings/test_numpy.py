"""The NumPy references of the coupling kernels (:mod:`rigidmd.couplings._numpy`), directly.

Each function against a closed form or an exact property: :func:`exprel` against its
series and :math:`(e^x - 1)/x`, the matrix exponentials against diagonal cases and
:math:`G B = A - 1`, a Nosé–Hoover chain's time reversibility, the MTK kick and friction
in cases computed by hand, the Ornstein–Uhlenbeck step's mean and noise factors.  (The
kernels against these references: ``tests/core/test_backend.py`` and
``tests/couplings/test_numba.py``.)
"""

import numpy as np
import pytest
from scipy.linalg import expm

from rigidmd.core import operators as ops
from rigidmd.core import quaternion as quat
from rigidmd.couplings import _numpy
from rigidmd.couplings._numba import COUPLE_CODES


def buffer(n, nf, seed=0):
    """A state buffer of ``n`` bodies and ``nf`` point particles (RigidState.data's layout:
    X, V, q, p of the bodies, then x, v of the particles), unit quaternions and random
    momenta."""
    rng = np.random.default_rng(seed)
    data = rng.normal(size=14 * n + 6 * nf)
    q = quat.normalize(rng.normal(size=(n, 4))) if n else np.zeros((0, 4))
    data[6 * n:10 * n] = q.ravel()
    data[10 * n:14 * n] = ops.conjugate_momentum(q, rng.normal(size=(n, 3))).ravel()
    return data


def views(data, n, nf):
    V = data[3 * n:6 * n].reshape(n, 3)
    v = data[14 * n + 3 * nf:14 * n + 6 * nf].reshape(nf, 3)
    q, p = data[6 * n:10 * n].reshape(n, 4), data[10 * n:14 * n].reshape(n, 4)
    return V, v, q, p


# ---------------------------------------------------------------- exprel, exponentials
def test_exprel_is_one_at_zero_and_its_series_near_it():
    assert _numpy.exprel(0.0) == 1.0
    x = np.array([1e-12, -3e-9, 2e-7, -9.9e-6])
    series = 1 + x / 2 + x**2 / 6 + x**3 / 24
    # Below |x| = 1e-5 the function is the three-term series: the next term, x^3/24, is
    # under 4.2e-17 relative there (below one ulp of 1).
    np.testing.assert_allclose(_numpy.exprel(x), series, rtol=2e-16, atol=0)


def test_exprel_is_the_closed_form_away_from_zero():
    x = np.array([-30.0, -1.0, 0.5, 1.0, 10.0, 300.0])
    expected = (np.exp(x) - 1) / x  # no cancellation to speak of for |x| >= 1/2
    # Measured: 2.2e-16 relative at most (one ulp); bound 1e-15.
    np.testing.assert_allclose(_numpy.exprel(x), expected, rtol=1e-15, atol=0)
    # Near the switch, where (e^x - 1)/x itself loses 4e-13 to cancellation: the series
    # to x^4 (the next term is 1e-22 relative).
    x = 1e-4
    assert _numpy.exprel(x) == pytest.approx(1 + x / 2 + x**2 / 6 + x**3 / 24 + x**4 / 120,
                                             rel=1e-15, abs=0)
    assert _numpy.exprel(-800.0) == pytest.approx(1 / 800, rel=1e-15)  # e^x underflows


def test_exprel_is_continuous_where_the_series_takes_over():
    """Either side of |x| = 1e-5, the series and expm1(x)/x agree to roundoff."""
    for edge in (1e-5, -1e-5):
        below, above = np.nextafter(edge, 0.0), edge
        # Measured: 0 and 2.2e-16 apart (one ulp of 1); bound 5e-16.
        assert _numpy.exprel(below) == pytest.approx(_numpy.exprel(above), rel=5e-16, abs=0)


def test_symmetric_exp_of_a_diagonal_matrix():
    g, t = np.array([-2.0, 0.0, 0.7]), 0.3
    A, B = _numpy.symmetric_exp(np.diag(g), t)
    np.testing.assert_allclose(A, np.diag(np.exp(g * t)), rtol=1e-15, atol=1e-16)
    # B = diag((e^{g t} - 1)/g), t at g = 0.
    np.testing.assert_allclose(B, np.diag([np.expm1(-0.6) / -2, t, np.expm1(0.21) / 0.7]),
                               rtol=1e-15, atol=1e-16)
    A0, B0 = _numpy.symmetric_exp(np.zeros((3, 3)), t)
    np.testing.assert_array_equal(A0, np.eye(3))
    np.testing.assert_array_equal(B0, t * np.eye(3))


def test_symmetric_exp_is_the_exponential_and_its_integral():
    rng = np.random.default_rng(3)
    M = rng.normal(size=(3, 3))
    G, t = M + M.T, 0.4
    A, B, det = _numpy.symmetric_exp_det(G, t)
    # Measured: 8.4e-15 of the largest element from scipy's expm (eigh's roundoff and
    # Pade's, |A| = 8.3), 8.9e-16 from G B = A - 1; bounds 1e-13 and 1e-14.
    np.testing.assert_allclose(A, expm(G * t), rtol=0, atol=1e-13 * np.abs(A).max())
    np.testing.assert_allclose(G @ B, A - np.eye(3), rtol=0, atol=1e-14)
    np.testing.assert_allclose(B, B.T, rtol=0, atol=1e-15)
    assert det == pytest.approx(np.exp(np.trace(G) * t), rel=1e-14)  # measured 1.3e-15


def test_project_keeps_what_each_couple_mode_moves():
    G = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 12.0]])
    np.testing.assert_array_equal(_numpy.project(G, "iso"), 6.0 * np.eye(3))
    np.testing.assert_array_equal(_numpy.project(G, "aniso"), np.diag([1.0, 5.0, 12.0]))
    np.testing.assert_array_equal(_numpy.project(G, "tri"), 0.5 * (G + G.T))


# ---------------------------------------------------------------- Nosé–Hoover chains
def test_a_chain_without_degrees_of_freedom_does_nothing():
    xi, eta = np.array([0.3, -0.1, 0.2]), np.zeros(3)
    assert _numpy.chain_propagate(xi, eta, 0, 2.0, 1.0, 0.1, 0.5, 1) == 1.0
    np.testing.assert_array_equal(xi, [0.3, -0.1, 0.2])
    np.testing.assert_array_equal(eta, 0.0)


def test_a_single_thermostat_at_its_temperature_and_at_rest_stays_there():
    """M = 1, 2K = N_f kT, xi = 0: no force on xi, so no scaling and no motion."""
    xi, eta = np.zeros(1), np.zeros(1)
    ndof, kT = 12, 0.025
    assert _numpy.chain_propagate(xi, eta, ndof, 3.0, 0.5 * ndof * kT, kT, 0.7, 4) == 1.0
    np.testing.assert_array_equal(xi, 0.0)
    np.testing.assert_array_equal(eta, 0.0)


def test_a_hot_system_is_cooled_by_exp_of_minus_the_integral_of_xi():
    """M = 1 over one step with tloop 1: xi is kicked by h/2 (2K - N_f kT)/Q, the particles
    scaled by exp(-h xi), and eta = h xi."""
    ndof, kT, unit, h, K = 6, 0.025, 4.0, 0.2, 0.3
    Q = ndof * unit
    xi, eta = np.zeros(1), np.zeros(1)
    scale = _numpy.chain_propagate(xi, eta, ndof, unit, K, kT, h, 1)
    half = 0.5 * h * (2 * K - ndof * kT) / Q
    assert scale == pytest.approx(np.exp(-h * half), rel=1e-15)
    assert eta[0] == pytest.approx(h * half, rel=1e-15)
    second = 0.5 * h * (2 * K * scale**2 - ndof * kT) / Q
    assert xi[0] == pytest.approx(half + second, rel=1e-15)


@pytest.mark.parametrize("tloop", [1, 3])
def test_a_chain_step_is_undone_by_the_step_back(tloop):
    """The splitting is symmetric: from where h left the chain and the kinetic energy,
    -h gives back xi and eta and the inverse scale."""
    xi, eta = np.array([0.4, -0.2, 0.1]), np.array([0.05, 0.0, -0.3])
    start = xi.copy(), eta.copy()
    ndof, unit, K, kT, h = 9, 2.0, 0.4, 0.025, 0.3
    forward = _numpy.chain_propagate(xi, eta, ndof, unit, K, kT, h, tloop)
    back = _numpy.chain_propagate(xi, eta, ndof, unit, K * forward**2, kT, -h, tloop)
    # Measured: 3e-16 apart at most (roundoff of the exponentials); bound 1e-14.
    assert back * forward == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(xi, start[0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(eta, start[1], rtol=0, atol=1e-14)


def test_chain_scale_is_chain_propagate_driven_by_the_momentum():
    p = np.array([[0.3, -0.2, 0.1], [0.0, 0.5, -0.4]])
    mass, ndof, unit, kT, h = 7.0, 6, 2.0, 0.025, 0.4
    xi, eta = np.array([0.1, 0.2]), np.zeros(2)
    xi2, eta2 = xi.copy(), eta.copy()
    expected = p * _numpy.chain_propagate(xi2, eta2, ndof, unit, (p**2).sum() / (2 * mass),
                                          kT, h, 2)
    _numpy.chain_scale(p, mass, xi, eta, ndof, unit, kT, h, 2)
    np.testing.assert_array_equal(p, expected)
    np.testing.assert_array_equal(xi, xi2)
    np.testing.assert_array_equal(eta, eta2)


def test_nose_hoover_scale_is_two_chains_then_their_scalings():
    n, nf = 3, 2
    data = buffer(n, nf)
    before = data.copy()
    chains = [np.array([0.1, -0.2]), np.zeros(2), np.array([0.3, 0.0]), np.zeros(2)]
    copies = [c.copy() for c in chains]
    args = (0.4, 0.6, 0.025, 0.3, 2)  # K_t, K_r, kT, h, tloop
    s_t, s_r = _numpy.nose_hoover_scale(data, n, nf, chains[0], chains[1], 6, chains[2],
                                        chains[3], 9, 2.0, *args)
    assert s_t == _numpy.chain_propagate(copies[0], copies[1], 6, 2.0, 0.4, 0.025, 0.3, 2)
    assert s_r == _numpy.chain_propagate(copies[2], copies[3], 9, 2.0, 0.6, 0.025, 0.3, 2)
    V, v, q, p = views(data, n, nf)
    V0, v0, q0, p0 = views(before, n, nf)
    np.testing.assert_array_equal(V, V0 * s_t)
    np.testing.assert_array_equal(v, v0 * s_t)
    np.testing.assert_array_equal(p, p0 * s_r)
    np.testing.assert_array_equal(q, q0)
    np.testing.assert_array_equal(data[:3 * n], before[:3 * n])  # X
    np.testing.assert_array_equal(data[14 * n:14 * n + 3 * nf], before[14 * n:14 * n + 3 * nf])


def test_scale_velocities_touches_only_the_velocities_and_momenta():
    n, nf = 2, 3
    data = buffer(n, nf, seed=1)
    before = data.copy()
    _numpy.scale_velocities(data, n, nf, 0.5, 2.0)
    V, v, q, p = views(data, n, nf)
    V0, v0, q0, p0 = views(before, n, nf)
    np.testing.assert_array_equal(V, 0.5 * V0)
    np.testing.assert_array_equal(v, 0.5 * v0)
    np.testing.assert_array_equal(p, 2.0 * p0)
    np.testing.assert_array_equal(q, q0)


# ---------------------------------------------------------------- MTK
@pytest.mark.parametrize("couple", ["iso", "aniso", "tri"])
def test_mtk_kick_by_hand(couple):
    """p_g += h Pi[W + K - P0 V + 2K_t/N_f], with 2K_t = Tr K."""
    W = np.array([[0.3, 0.1, -0.2], [0.1, -0.4, 0.05], [-0.2, 0.05, 0.6]])
    K = np.array([[0.2, 0.01, 0.0], [0.01, 0.3, 0.02], [0.0, 0.02, 0.25]])
    volume, P0, n_f, h = 1000.0, 6e-4, 57, 0.5
    p_g = np.full((3, 3), 0.1)
    _numpy.mtk_kick(p_g, W, K, volume, P0, n_f, h, COUPLE_CODES[couple])
    G = W + K - P0 * volume * np.eye(3) + np.trace(K) / n_f * np.eye(3)
    np.testing.assert_allclose(p_g, 0.1 + h * _numpy.project(G, couple), rtol=1e-14,
                               atol=1e-16)


def test_mtk_friction_at_rest_changes_nothing_and_diagonal_by_hand():
    n, nf = 2, 1
    data = buffer(n, nf, seed=2)
    before = data.copy()
    factor = _numpy.mtk_friction(data, n, nf, np.zeros((3, 3)), 50.0, 15, 0.3)
    np.testing.assert_array_equal(factor, np.eye(3))
    np.testing.assert_array_equal(data, before)
    p_g, W, n_f, h = np.diag([1.0, -2.0, 4.0]), 50.0, 15, 0.3
    factor = _numpy.mtk_friction(data, n, nf, p_g, W, n_f, h)
    expected = np.exp(-(np.diag(p_g) + 3.0 / n_f) / W * h)
    np.testing.assert_allclose(factor, np.diag(expected), rtol=1e-15, atol=1e-300)
    V, v, q, p = views(data, n, nf)
    V0, v0, _, p0 = views(before, n, nf)
    np.testing.assert_allclose(V, V0 * expected, rtol=1e-15)
    np.testing.assert_allclose(v, v0 * expected, rtol=1e-15)
    np.testing.assert_array_equal(p, p0)  # the rotation is not rescaled


# ---------------------------------------------------------------- Ornstein–Uhlenbeck
def ou_inputs(n, nf, seed=4):
    rng = np.random.default_rng(seed)
    return (rng.uniform(1, 20, n), rng.uniform(1, 20, nf), rng.uniform(0.5, 3, (n, 3)))


def test_without_noise_the_o_step_multiplies_every_momentum_by_c():
    """The mean factor: V, v and the body angular momenta times c."""
    n, nf, c = 3, 2, 0.8
    data = buffer(n, nf, seed=5)
    before = data.copy()
    mass, free, moments = ou_inputs(n, nf)
    _numpy.ornstein_uhlenbeck(data, n, nf, c, 0.7, 1 / np.sqrt(mass), 1 / np.sqrt(free),
                              np.sqrt(moments), np.zeros(6 * n + 3 * nf))
    V, v, q, p = views(data, n, nf)
    V0, v0, q0, p0 = views(before, n, nf)
    np.testing.assert_allclose(V, c * V0, rtol=1e-15)
    np.testing.assert_allclose(v, c * v0, rtol=1e-15)
    np.testing.assert_array_equal(q, q0)
    # Measured: 1.1e-16 (the body frame and back; 3.3e-16 in the next test); bound 1e-14.
    np.testing.assert_allclose(ops.body_angular_momentum(q, p),
                               c * ops.body_angular_momentum(q0, p0), rtol=0, atol=1e-14)


def test_from_rest_the_o_step_is_the_noise_times_sigma_over_the_root_masses():
    """The noise factor: c = 0 leaves sigma xi / sqrt(M) (V, then v) and sigma sqrt(I) xi
    (L_b), the deviates taken in that order."""
    n, nf, sigma = 2, 3, 0.6
    data = buffer(n, nf, seed=6)
    mass, free, moments = ou_inputs(n, nf, seed=7)
    noise = np.random.default_rng(8).normal(size=6 * n + 3 * nf)
    _numpy.ornstein_uhlenbeck(data, n, nf, 0.0, sigma, 1 / np.sqrt(mass), 1 / np.sqrt(free),
                              np.sqrt(moments), noise)
    V, v, q, p = views(data, n, nf)
    np.testing.assert_allclose(V, sigma * noise[:3 * n].reshape(n, 3) / np.sqrt(mass)[:, None],
                               rtol=1e-15)
    np.testing.assert_allclose(v, sigma * noise[3 * n:3 * n + 3 * nf].reshape(nf, 3)
                               / np.sqrt(free)[:, None], rtol=1e-15)
    np.testing.assert_allclose(ops.body_angular_momentum(q, p),
                               sigma * np.sqrt(moments) * noise[3 * n + 3 * nf:].reshape(n, 3),
                               rtol=0, atol=1e-14)


def test_the_o_step_keeps_the_canonical_variance():
    """c^2 kT/M + sigma^2/M = kT/M with sigma^2 = kT (1 - c^2): one O step from canonical
    velocities leaves them canonical (20000 bodies; the sample variance of 60000 deviates
    has a relative standard error of 0.58 %, the bound is 4 of them)."""
    n, kT, c = 20000, 0.025, 0.3
    rng = np.random.default_rng(9)
    mass = rng.uniform(1, 30, n)
    data = np.zeros(14 * n)
    data[6 * n:10 * n:4] = 1.0  # identity orientations
    data[3 * n:6 * n] = (rng.normal(size=(n, 3)) * np.sqrt(kT / mass)[:, None]).ravel()
    _numpy.ornstein_uhlenbeck(data, n, 0, c, np.sqrt(kT * (1 - c * c)), 1 / np.sqrt(mass),
                              np.ones(0), np.ones((n, 3)), rng.normal(size=6 * n))
    V = data[3 * n:6 * n].reshape(n, 3)
    assert np.mean(mass[:, None] * V**2) / kT == pytest.approx(1.0, abs=4 * 0.0058)
