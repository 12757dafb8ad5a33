"""The compiled coupling kernels against their NumPy references, operator by operator.

Each kernel of :mod:`rigidmd.couplings._numba` (and the record's and the force
evaluator's loops in :mod:`rigidmd.core._numba`) is run beside the reference it
replaces, from the same state, and compared.  The tolerances are roundoff:
the kernels sum in another order (and take ``exp``/``expm1`` from another
library) than NumPy does.
"""

import numpy as np
import pytest
from ase.stress import voigt_6_to_full_3x3_stress
from helpers import argon_crystal, dimer_fluid, npt

from rigidmd.core import _numba
from rigidmd.core import observables as obs
from rigidmd.core import operators as ops
from rigidmd.core.backend import NUMBA, NUMPY
from rigidmd.core.bodies import cell_widths
from rigidmd.core.state import RigidState
from rigidmd.couplings import _numba as coupling_kernels
from rigidmd.couplings.barostats import MTKBarostat, symmetric_exp
from rigidmd.couplings.base import NoseHooverChain
from rigidmd.couplings.thermostats import NoseHooverThermostat

# Measured on the cases below: at most a few ulp (4e-16 relative) on every quantity.
RTOL = 1e-14
# The cell matrices of a step are near the identity: their small off-diagonal entries carry
# the roundoff of 1 (measured 5e-16 on a sheared cell, where the reference itself is
# symmetric only to 5e-17).
MATRIX_ATOL = 2e-15


def random_state(rng, n=7, nf=3):
    """Bodies and point particles with random velocities, momenta and a tilted cell."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    cell = np.array([[10.0, 0, 0], [1.5, 9.0, 0], [-0.7, 2.0, 11.0]])
    return RigidState(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), q,
                      rng.normal(size=(n, 4)), rng.normal(size=(nf, 3)),
                      rng.normal(size=(nf, 3)), cell)


def symmetric(rng, diagonal=False):
    G = rng.normal(size=(3, 3)) * 1e-2
    return np.diag(np.diag(G)) if diagonal else G + G.T


@pytest.mark.parametrize("tchain, tloop, ndof", [(1, 1, 9), (3, 1, 9), (4, 3, 1), (3, 2, 0)])
def test_chain_propagate_is_the_reference(tchain, tloop, ndof):
    rng = np.random.default_rng(tchain + tloop)
    chains = [NoseHooverChain(ndof, 50.0, tchain, tloop) for _ in range(2)]
    chains[0].xi[:] = rng.normal(size=tchain) * 1e-2  # away from the zero start
    chains[1].set_state(chains[0].get_state())
    for K in (0.3, 0.05, 1.2):
        scales = [chain.propagate(K, 0.025, 0.5, backend) for chain, backend
                  in zip(chains, (NUMPY, NUMBA), strict=True)]
        assert scales[1] == pytest.approx(scales[0], rel=RTOL, abs=0)
        np.testing.assert_allclose(chains[1].xi, chains[0].xi, rtol=RTOL, atol=1e-300)
        np.testing.assert_allclose(chains[1].eta, chains[0].eta, rtol=RTOL, atol=1e-300)


@pytest.mark.parametrize("diagonal", [True, False])
def test_symmetric_exp_is_the_reference(diagonal):
    rng = np.random.default_rng(1)
    for t in (0.5, 1.0, -1.0, 1e-9):
        G = symmetric(rng, diagonal)
        A, B, det = coupling_kernels.symmetric_exp_det(G, t)
        A_ref, B_ref = symmetric_exp(G, t)
        if diagonal:  # no eigensolver: the reference's result, bit for bit
            np.testing.assert_array_equal(A, A_ref)
            np.testing.assert_array_equal(B, B_ref)
        np.testing.assert_allclose(A, A_ref, rtol=RTOL, atol=1e-16)
        np.testing.assert_allclose(B, B_ref, rtol=RTOL, atol=1e-16 * abs(t))
        assert det == pytest.approx(np.linalg.det(A_ref), rel=RTOL)


def test_state_scalings_and_sums_are_the_references():
    rng = np.random.default_rng(2)
    state = random_state(rng)
    n, nf = len(state.X), len(state.x)
    mass, free_masses = rng.uniform(1, 20, n), rng.uniform(1, 20, nf)
    inv_moments = rng.uniform(0, 2, (n, 3))
    inv_moments[0, 0] = 0.0  # a linear body
    ref = state.copy()
    F = np.eye(3) + symmetric(rng)
    coupling_kernels.scale_translation(state.data, n, nf, F)
    np.testing.assert_allclose(state.V, ref.V @ F.T, rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose(state.v, ref.v @ F.T, rtol=RTOL, atol=1e-15)
    np.testing.assert_array_equal(state.p, ref.p)
    ref = state.copy()
    coupling_kernels.scale_velocities(state.data, n, nf, 0.97, 1.03)
    np.testing.assert_array_equal(state.V, 0.97 * ref.V)
    np.testing.assert_array_equal(state.v, 0.97 * ref.v)
    np.testing.assert_array_equal(state.p, 1.03 * ref.p)
    np.testing.assert_array_equal(state.X, ref.X)
    np.testing.assert_array_equal(state.q, ref.q)
    # The record's sums.
    K_ref = (np.einsum("b,bi,bj->ij", mass, state.V, state.V)
             + np.einsum("f,fi,fj->ij", free_masses, state.v, state.v))
    np.testing.assert_allclose(_numba.kinetic_tensor(state.V, state.v, mass, free_masses),
                               K_ref, rtol=RTOL, atol=1e-14)
    L = ops.body_angular_momentum(state.q, state.p)
    assert _numba.rotational_energy(state.q, state.p, inv_moments) == pytest.approx(
        0.5 * np.sum(L**2 * inv_moments), rel=RTOL)
    # The force evaluator's: intramolecular virial, narrowest cell width.
    order = rng.permutation(12)[:9]
    r, forces = rng.normal(size=(9, 3)), rng.normal(size=(12, 3))
    w = r.T @ forces[order]
    np.testing.assert_allclose(_numba.intramolecular_virial(r, forces, order), 0.5 * (w + w.T),
                               rtol=RTOL, atol=1e-14)
    # ... and the molecular virial from a Voigt stress: the 3x3 formula's arithmetic.
    stress = rng.normal(size=6)
    np.testing.assert_array_equal(
        _numba.molecular_virial_voigt(stress, 812.5, r, forces, order),
        -812.5 * voigt_6_to_full_3x3_stress(stress)
        - _numba.intramolecular_virial(r, forces, order))
    for pbc in ([True] * 3, [True, False, True], [False] * 3):
        widths = np.where(pbc, cell_widths(state.cell), np.inf)
        assert _numba.smallest_width(state.cell, np.array(pbc)) == pytest.approx(
            widths.min(), rel=RTOL)


def mid_run(kind, couple, backend="numpy", **kwargs):
    """A barostatted run of 64 dimers (or 108 argon atoms, ``argon``) 5 steps in."""
    atoms = argon_crystal(shear=0.03) if kwargs.pop("argon", False) else dimer_fluid(
        n_side=4, rc=7.0)
    dyn = npt(atoms, kind, couple=couple, backend=backend,
              **({"bodies": []} if len(atoms) == 108 else {}))
    dyn.run(5)
    return dyn


def both(dyn, part, action):
    """``action(view)`` from one state on the reference and on the compiled path.

    Returns the two (state, part variables) pairs after it."""
    start, variables = dyn.state.copy(), part.get_state()
    results = []
    for backend in (NUMPY, NUMBA):
        start.copy_into(dyn.state)
        part.set_state(variables)  # copy_into moved the state's versions: sums anew
        dyn.link.backend = backend  # the one backend object: record, view and parts follow
        assert dyn.view.backend is backend and dyn.record.backend is backend
        assert dyn.record.kinetic_tensor is not None  # summed now: a scaling must update it
        out = action(dyn.view)
        results.append((dyn.state.copy(), part.get_state(), out))
    return results


def assert_same(ref, new, what):
    for name in ("X", "V", "q", "p", "x", "v", "cell"):
        np.testing.assert_allclose(getattr(new[0], name), getattr(ref[0], name), rtol=RTOL,
                                   atol=1e-16, err_msg=f"{what}: {name}")

    def flat(variables):
        if isinstance(variables, dict):
            return [x for key in sorted(variables) for x in flat(variables[key])]
        if isinstance(variables, list | tuple):
            return [x for v in variables for x in flat(v)]
        if isinstance(variables, str):  # a generator's name (its state is numbers)
            return []
        return [np.asarray(variables, dtype=float)]

    for a, b in zip(flat(new[1]), flat(ref[1]), strict=True):
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=1e-18, err_msg=what)


@pytest.mark.parametrize("couple", ["iso", "aniso", "tri"])
@pytest.mark.parametrize("argon", [False, True])
def test_mtk_half_steps_are_the_reference(couple, argon):
    """Each MTK operator (chain, kick, friction, drift) and whole halves, both paths."""
    dyn = mid_run("mtk", couple, argon=argon)
    baro = dyn.barostat
    assert isinstance(baro, MTKBarostat)
    # p_g away from zero (and off-diagonal for tri) so that every term is exercised.
    baro.p_g[...] = baro.W * 1e-4 * np.array([[3, 1, -2], [1, -1, 0.5], [-2, 0.5, 2]])
    if couple != "tri":
        baro.p_g[...] = np.diag(np.diag(baro.p_g))
    h = 0.5 * dyn.dt
    operators = {
        "thermostat": lambda view: baro._thermostat(view, h),
        "kick": lambda view: baro._kick(view, h),
        "friction": lambda view: baro._scale_momenta(view, h),
        "first half": lambda view: baro.first_half(view, h),
        "second half": lambda view: baro.second_half(view, h),
        "drift": lambda view: baro.drift_matrices(view, h),
    }
    for what, action in operators.items():
        ref, new = both(dyn, baro, action)
        assert_same(ref, new, what)
        if what == "drift":
            for a, b in zip(new[2][:3], ref[2][:3], strict=True):
                np.testing.assert_allclose(a, b, rtol=RTOL, atol=MATRIX_ATOL, err_msg=what)
        if what == "friction":  # the record's kinetic tensor follows the scaling
            np.testing.assert_allclose(dyn.record.kinetic_tensor,
                                       obs.kinetic_tensor(dyn.state, dyn.model), rtol=1e-13)


@pytest.mark.parametrize("couple", ["iso", "tri"])
def test_nose_hoover_half_step_is_the_reference(couple):
    dyn = mid_run("mtk", couple)
    thermostat = dyn.thermostat
    assert isinstance(thermostat, NoseHooverThermostat)
    for chain in thermostat.chains:
        chain.xi[:] = [0.02, -0.01, 0.005]
    ref, new = both(dyn, thermostat, lambda view: thermostat.first_half(view, 0.5 * dyn.dt))
    assert_same(ref, new, "Nosé–Hoover half step")


@pytest.mark.parametrize("couple", ["iso", "aniso", "tri"])
@pytest.mark.parametrize("argon", [False, True])
def test_crescale_move_and_bookkeeping_are_the_reference(couple, argon):
    """The cell move of one step and its second half's bookkeeping, both paths."""
    dyn = mid_run("crescale", couple, argon=argon)
    baro = dyn.barostat
    h = 0.5 * dyn.dt
    baro.first_half(dyn.view, h)  # draws this step's noise
    noise = baro._noise
    # The move, then (with the force call's virial as it stands) the second half.

    def move_and_book(view):
        baro._noise = noise
        dyn.view.cell_note = None
        A, B, S, note = baro.drift_matrices(view, h)
        dyn.view.cell_note = note
        dyn.state.V[...] = dyn.state.V @ S.T  # the drift's velocities
        dyn.state.v[...] = dyn.state.v @ S.T
        dyn.state.touched(momenta=True)
        baro.second_half(view, h)
        return A, B, S

    ref, new = both(dyn, baro, move_and_book)
    for a, b in zip(new[2], ref[2], strict=True):  # near-identity matrices: roundoff of 1
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=MATRIX_ATOL)
    assert_same(ref, new, "C-rescale move")
    assert new[1]["work"] != 0.0
