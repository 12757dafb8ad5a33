"""The backend: one object chosen at construction, no branch on it elsewhere, each kernel
against its NumPy reference.

* :func:`rigidmd.core.backend.resolve_backend` gives one of two objects, with the
  messages of before; a dynamics, its link, record and coupling view share it.
* No module but ``core/backend.py`` branches on the backend: the syntax tree of every
  module under ``src/rigidmd`` is searched for an ``if``, a conditional expression, a
  ``while``, an ``and``/``or`` or a comprehension's condition that tests a name or
  attribute called ``compiled``, ``fused`` or ``AVAILABLE``, or compares something
  called ``backend`` with a string.
* Every operation the backends offer (:func:`rigidmd.core.backend.operations`) is run
  on both from the same random inputs and compared; an operation without a case here
  fails the test (a new kernel comes with its check).
"""

import ast
import functools
from pathlib import Path

import numpy as np
import pytest
from helpers import LAMMPS_IMAGE_BITS as BITS
from helpers import dimer_fluid, mixture, npt
from helpers import lammps_image_case as _case

import rigidmd.lammps._numpy  # noqa: F401  (registers the LAMMPS kernels' operations)
from rigidmd import RigidDynamics
from rigidmd.core import _numba
from rigidmd.core.backend import (
    NUMBA,
    NUMPY,
    Backend,
    CompiledBackend,
    operations,
    register,
    resolve_backend,
)
from rigidmd.core.bodies import RigidBodies, check_bodies_fit
from rigidmd.core.link import BodyLink
from rigidmd.core.state import RigidState
from rigidmd.couplings.barostats import CRescaleBarostat

SOURCE = Path(__file__).resolve().parents[1] / "src" / "rigidmd"
#: The one module allowed to tell the backends apart.
BACKEND_MODULE = SOURCE / "core" / "backend.py"
#: Names whose test is a branch on the backend.
FLAGS = {"compiled", "fused", "AVAILABLE"}

needs_numba = pytest.mark.skipif(not _numba.AVAILABLE, reason="needs numba")


# ---------------------------------------------------------------- one object
def test_the_backend_is_resolved_once_to_one_of_two_objects():
    assert resolve_backend("numpy") is NUMPY and resolve_backend(NUMPY) is NUMPY
    assert resolve_backend(None) is (NUMBA if _numba.AVAILABLE else NUMPY)
    assert type(NUMPY) is Backend and type(NUMBA) is CompiledBackend
    assert (NUMPY.name, NUMBA.name) == ("numpy", "numba")
    with pytest.raises(ValueError, match="backend must be 'numba' or 'numpy', got 'gpu'"):
        resolve_backend("gpu")
    with pytest.raises(ValueError, match="is registered already"):
        register("mtk_kick", len, len)
    with pytest.raises(ValueError, match="one of the core's"):
        register("place", len, len)


@needs_numba
@pytest.mark.parametrize("name", ["numpy", "numba"])
def test_a_dynamics_carries_one_backend_to_every_part(name):
    dyn = npt(dimer_fluid(n_side=2, rc=5.0), "mtk", backend=name)
    backend = resolve_backend(name)
    assert dyn.backend == name  # the public string, stored in checkpoints
    assert dyn.link.backend is backend and dyn.record.backend is backend
    assert dyn.view.backend is backend
    assert dyn.fused is (name == "numba")
    assert (dyn.stepper.kernel is None) is (name == "numpy")


# ---------------------------------------------------------------- no branch outside
def _name(node) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def branches_on_backend(tree) -> list[tuple[int, str]]:
    """``(line, condition)`` of each condition in ``tree`` that tests the backend."""
    conditions = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.If, ast.IfExp, ast.While)):
            conditions.append(node.test)
        elif isinstance(node, ast.BoolOp):
            conditions.extend(node.values)
        elif isinstance(node, ast.comprehension):
            conditions.extend(node.ifs)
    found = set()
    for condition in conditions:
        for node in ast.walk(condition):
            flagged = _name(node) in FLAGS
            if isinstance(node, ast.Compare):
                operands = [node.left, *node.comparators]
                flagged = flagged or (
                    any("backend" in (_name(n) or "") for o in operands for n in ast.walk(o))
                    and any(isinstance(o, ast.Constant) and isinstance(o.value, str)
                            for o in operands))
            if flagged:
                found.add((node.lineno, ast.unparse(condition)))
    return sorted(found)


def test_the_search_finds_each_kind_of_branch():
    """The search below can fail: each form of a branch on the backend is found."""
    code = """
if link.compiled:
    pass
x = a if backend == "numba" else b
y = fused and z
while not AVAILABLE:
    pass
w = [k for k in ks if self.backend.name != "numpy"]
ok = kernel is None or plain
"""
    assert [line for line, _ in branches_on_backend(ast.parse(code))] == [2, 4, 5, 6, 8]


def test_no_module_but_the_backend_branches_on_the_backend():
    offences = []
    for path in sorted(SOURCE.rglob("*.py")):
        if path == BACKEND_MODULE:
            continue
        for line, condition in branches_on_backend(ast.parse(path.read_text())):
            offences.append(f"{path.relative_to(SOURCE.parent)}:{line}: {condition}")
    assert offences == [], "\n".join(offences)


# ---------------------------------------------------------------- each kernel, its reference
@functools.cache
def _system():
    """A model of 4 CO2 (linear), 4 waters and 2 neon atoms, and a random state of it."""
    atoms = mixture()
    geometry = RigidBodies.resolve(atoms, "mol-id").geometry(atoms)
    model = geometry.model
    link = BodyLink(atoms, model, "numpy")
    state = link.initial_state(geometry)
    rng = np.random.default_rng(5)
    q = rng.normal(size=state.q.shape)
    state.q = q / np.linalg.norm(q, axis=1)[:, None]
    state.V, state.p = rng.normal(size=state.V.shape), rng.normal(size=state.p.shape)
    state.v = rng.normal(size=state.v.shape)
    return atoms, model, state


def _buffer_state(rng, n=7, nf=3):
    """A state of ``n`` bodies and ``nf`` point particles, random everywhere (no model)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    cell = np.array([[10.0, 0, 0], [1.5, 9.0, 0], [-0.7, 2.0, 11.0]])
    return RigidState(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), q,
                      rng.normal(size=(n, 4)), rng.normal(size=(nf, 3)),
                      rng.normal(size=(nf, 3)), cell)


def _symmetric(rng, scale=1e-2):
    G = rng.normal(size=(3, 3)) * scale
    return G + G.T


# Each case runs one operation on ``backend`` from inputs drawn from ``rng`` (the same
# seed for both backends) and returns what it computed and what it changed in place.
def _place(backend, rng):
    atoms, model, state = _system()
    positions = np.zeros((len(atoms), 3))
    r = backend.place(state, model, np.empty((len(model.order), 3)), positions)
    return r, positions[model.order]


def _write_momenta(backend, rng):
    atoms, model, state = _system()
    r = NUMPY.place(state, model, None, np.zeros((len(atoms), 3)))
    momenta = np.zeros((len(atoms), 3))
    backend.write_momenta(state, model, r, momenta)
    return momenta[model.order]


def _largest_angular_speed(backend, rng):
    _, model, state = _system()
    return backend.largest_angular_speed(state, model)


def _kinetic_tensor(backend, rng):
    _, model, state = _system()
    return backend.kinetic_tensor(state, model)


def _rotational_energy(backend, rng):
    _, model, state = _system()
    return backend.rotational_energy(state, model)


def _congruence(backend, rng):
    return backend.congruence(np.eye(3) + _symmetric(rng), _symmetric(rng, 1.0))


def _net_force(backend, rng):
    return backend.net_force(rng.normal(size=(9, 3)), rng.normal(size=(4, 3)))


def _molecular_virial(backend, rng):
    atoms, model, state = _system()
    r = NUMPY.place(state, model, None, np.zeros((len(atoms), 3)))
    forces = rng.normal(size=(len(atoms), 3))
    stress = rng.normal(size=6) * 1e-3
    full = _symmetric(rng, 1e-3)
    return (backend.molecular_virial(stress, 812.5, r, forces, model),
            backend.molecular_virial(full, 812.5, r, forces, model))


def _cell_clearly_fits(backend, rng):
    """Where the compiled backend skips the full check, the full check passes."""
    _, model, _ = _system()
    skipped = []
    for scale in np.linspace(0.5, 3.0, 26):
        cell = scale * 4.0 * model.radius * (np.eye(3) + 0.2 * _symmetric(rng, 1.0))
        for pbc in (np.array([True] * 3), np.array([True, False, True])):
            if backend.cell_clearly_fits(model, cell, pbc):
                check_bodies_fit(model, cell, pbc)  # raises if the skip were wrong
                skipped.append(True)
    return len(skipped)


def _one_step(function, scheme):
    """One step of ``scheme`` through ``function`` from a dynamics' context (NumPy)."""
    atoms = mixture()
    dyn = RigidDynamics(atoms, 0.5, bodies="mol-id", backend="numpy", integrator=scheme)
    ctx = dyn.stepper.context
    (function or dyn.scheme.run)(ctx, 0.5)
    return dyn.state.data.copy(), dyn.record.F, dyn.record.tau


def _scheme_kernel(backend, rng):
    from rigidmd.core.schemes import resolve_scheme

    return _one_step(backend.scheme_kernel(resolve_scheme("no_squish")), "no_squish")


def _step_function(backend, rng):
    from rigidmd.core.schemes import resolve_scheme

    return _one_step(backend.step_function(resolve_scheme("baoab")), "baoab")


def _equal_or_close(backend, rng):
    a = rng.normal(size=(5, 3))
    cases = [(a, a.copy()), (a, a * (1 + 1e-16)), (a, a + 1e-9), (a, a * (1 + 1e-9))]
    b = a.copy()
    b[2, 1] = np.nan
    c = a.copy()
    c[0, 0] = np.inf
    cases += [(b, b.copy()), (b, a), (c, c.copy()), (c, a)]
    return [backend.equal_or_close(x, y, 1e-12) for x, y in cases]


def _chain(rng, tchain=3):
    return rng.normal(size=tchain) * 1e-2, rng.normal(size=tchain)


def _chain_propagate(backend, rng):
    out = []
    for ndof, tloop in ((9, 1), (1, 3), (0, 2)):
        xi, eta = _chain(rng)
        out += [backend.chain_propagate(xi, eta, ndof, 0.025 * 50.0**2, 0.3, 0.025, 0.5,
                                        tloop), xi, eta]
    return out


def _chain_scale(backend, rng):
    p, (xi, eta) = rng.normal(size=(3, 3)), _chain(rng)
    backend.chain_scale(p, 40.0, xi, eta, 9, 0.025 * 50.0**2, 0.025, 0.5, 2)
    return p, xi, eta


def _symmetric_exp_det(backend, rng):
    out = []
    for t in (0.5, -1.0, 1e-9):
        G = _symmetric(rng)
        out += [*backend.symmetric_exp_det(G, t), *backend.symmetric_exp_det(np.diag(np.diag(G)),
                                                                             t)]
    return out


def _mtk_kick(backend, rng):
    out = []
    for couple in (0, 1, 2):
        p_g = _symmetric(rng)
        backend.mtk_kick(p_g, _symmetric(rng, 1.0), _symmetric(rng, 1.0) + 3 * np.eye(3),
                         812.5, 6e-7, 45, 0.5, couple)
        out.append(p_g)
    return out


def _mtk_friction(backend, rng):
    s = _buffer_state(rng)
    factor = backend.mtk_friction(s.data, 7, 3, _symmetric(rng, 10.0), 3e3, 45, 0.5)
    return factor, s.data


def _scale_velocities(backend, rng):
    s = _buffer_state(rng)
    backend.scale_velocities(s.data, 7, 3, 0.97, 1.03)
    return s.data


def _nose_hoover_scale(backend, rng):
    s = _buffer_state(rng)
    (xi_t, eta_t), (xi_r, eta_r) = _chain(rng), _chain(rng)
    factors = backend.nose_hoover_scale(s.data, 7, 3, xi_t, eta_t, 27, xi_r, eta_r, 21,
                                        0.025 * 50.0**2, 0.4, 0.3, 0.025, 0.5, 1)
    return factors, s.data, xi_t, eta_t, xi_r, eta_r


def _ornstein_uhlenbeck(backend, rng):
    s = _buffer_state(rng)
    noise = rng.standard_normal(6 * 7 + 3 * 3)
    backend.ornstein_uhlenbeck(s.data, 7, 3, 0.8, 0.05, rng.uniform(0.1, 1, 7),
                               rng.uniform(0.1, 1, 3), rng.uniform(0, 3, (7, 3)), noise)
    return s.data


@functools.cache
def _crescale_run():
    """A C-rescale run of 27 dimers 3 steps in, this step's noise drawn."""
    dyn = npt(dimer_fluid(n_side=3, rc=6.0), "crescale", couple="tri", backend="numpy")
    dyn.run(3)
    baro = dyn.barostat
    assert isinstance(baro, CRescaleBarostat)
    baro.first_half(dyn.view, 0.5 * dyn.dt)
    return dyn, baro, dyn.state.copy(), baro.get_state(), baro._noise


def _crescale(backend):
    """The drift's matrices and the second half's work, from one state."""
    dyn, baro, start, variables, noise = _crescale_run()
    start.copy_into(dyn.state)
    baro.set_state(variables)
    baro._noise = noise
    record = dyn.record
    dyn.view.cell_note = None  # copy_into moved the state's versions: the record sums anew
    A, B, S, note = backend.crescale_drift(baro, dyn.view, record.volume, 0.5 * dyn.dt)
    dyn.view.cell_note = note
    dyn.state.V = dyn.state.V @ S.T  # the drift's velocities (assigning moves the version)
    dyn.state.v = dyn.state.v @ S.T
    return A, B, S, backend.crescale_bookkeeping(baro, dyn.view)


def _crescale_drift(backend, rng):
    return _crescale(backend)[:3]


def _crescale_bookkeeping(backend, rng):
    return _crescale(backend)[3]


def _write_positions(backend, rng):
    out = []
    for outside in (False, True):
        positions, order, image, cell = _case(int(rng.integers(1 << 30)), 40, 1.0, outside)
        x = np.empty((40, 3))
        out += [backend.write_positions(positions, order, image, BITS, cell, x), image, x]
    return out


def _read_forces(backend, rng):
    ids = (rng.permutation(30) + 1).astype(np.int32)
    out, order = np.empty((30, 3)), np.empty(30, dtype=np.int64)
    backend.read_forces(rng.normal(size=(30, 3)), ids, order, out)
    return out, order


#: Every operation: its case, and the tolerance (rtol, atol) of the kernel against the
#: reference.  Measured on these inputs (largest difference of any output): 0 for
#: chain_propagate, nose_hoover_scale, mtk_kick, ornstein_uhlenbeck, rotational_energy,
#: crescale_bookkeeping; 4-9e-16 absolute for chain_scale, congruence, molecular_virial,
#: place, crescale_drift, mtk_friction and symmetric_exp_det (whose small off-diagonal
#: entries carry the roundoff of 1: atol), 7e-15 for write_momenta and 2e-14 for
#: kinetic_tensor (entries of about 30), 9e-15 for one fused step, 7e-15 for LAMMPS's
#: positions (about 30 Å).  The tolerances leave a factor of 5-20 above these; pairs whose
#: arithmetic is the same operation on the same numbers are (0, 0).
CASES = {
    "place": (_place, (1e-14, 1e-15)),
    "write_momenta": (_write_momenta, (1e-14, 1e-13)),
    "largest_angular_speed": (_largest_angular_speed, (1e-14, 0)),
    "kinetic_tensor": (_kinetic_tensor, (1e-14, 1e-13)),
    "rotational_energy": (_rotational_energy, (1e-14, 0)),
    "congruence": (_congruence, (1e-14, 1e-15)),
    "net_force": (_net_force, (1e-14, 1e-14)),
    "molecular_virial": (_molecular_virial, (1e-14, 1e-14)),
    "cell_clearly_fits": (_cell_clearly_fits, None),
    # One step of the fused kernel against the operators it fuses (sin/cos below 0.25 rad
    # and fused sums round differently: test_schemes.py measures the loops one by one).
    "scheme_kernel": (_scheme_kernel, (1e-13, 5e-14)),
    "step_function": (_step_function, (1e-13, 5e-14)),
    "equal_or_close": (_equal_or_close, (0, 0)),
    "chain_propagate": (_chain_propagate, (1e-14, 1e-300)),
    "chain_scale": (_chain_scale, (1e-14, 1e-300)),
    "symmetric_exp_det": (_symmetric_exp_det, (1e-14, 1e-15)),
    "mtk_kick": (_mtk_kick, (1e-14, 1e-16)),
    "mtk_friction": (_mtk_friction, (1e-14, 2e-15)),
    "scale_velocities": (_scale_velocities, (0, 0)),
    "nose_hoover_scale": (_nose_hoover_scale, (1e-14, 1e-300)),
    "ornstein_uhlenbeck": (_ornstein_uhlenbeck, (1e-14, 1e-15)),
    "crescale_drift": (_crescale_drift, (1e-14, 2e-15)),
    "crescale_bookkeeping": (_crescale_bookkeeping, (1e-14, 0)),
    # The same sums in another order (image @ cell as NumPy's matmul sums it).
    "write_positions": (_write_positions, (0, 1e-11)),
    "read_forces": (_read_forces, (0, 0)),
}


def _flat(value) -> list[np.ndarray]:
    if isinstance(value, list | tuple):
        return [x for v in value for x in _flat(v)]
    return [np.asarray(value, dtype=float)]


def test_every_operation_has_a_case():
    assert sorted(CASES) == sorted(operations())


@needs_numba
@pytest.mark.parametrize("name", sorted(CASES))
def test_the_kernel_is_its_reference(name):
    case, tolerance = CASES[name]
    ref = case(NUMPY, np.random.default_rng(11))
    new = case(NUMBA, np.random.default_rng(11))
    if tolerance is None:  # cell_clearly_fits: the reference never skips, the kernel does
        assert ref == 0 and new > 0
        return
    rtol, atol = tolerance
    ref, new = _flat(ref), _flat(new)
    assert len(ref) == len(new)
    for k, (a, b) in enumerate(zip(new, ref, strict=True)):
        np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, err_msg=f"{name}: output {k}")


def test_without_numba_the_compiled_backend_is_unavailable():
    """numba missing: ``None`` is NumPy, ``"numba"`` is refused as before, and a dynamics
    and the LAMMPS loops run on the references."""
    import subprocess
    import sys

    code = """
import sys
sys.modules["numba"] = None  # import numba raises ImportError
import numpy as np
from ase import units
from ase.calculators.tip3p import TIP3P
from rigidmd import RigidVerlet
from rigidmd.core.backend import NUMPY, resolve_backend
from rigidmd.lammps import _numpy
from rigidmd.systems import water_cluster
assert resolve_backend(None) is NUMPY
try:
    resolve_backend("numba")
except ValueError as err:
    assert str(err) == "backend='numba' but numba is not installed", err
else:
    raise AssertionError("numba was not refused")
atoms = water_cluster(2)
atoms.calc = TIP3P(rc=40)
dyn = RigidVerlet(atoms, units.fs)
dyn.run(2)
assert dyn.backend == "numpy" and not dyn.fused
print("ran")
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "ran"
