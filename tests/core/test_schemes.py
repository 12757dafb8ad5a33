"""Schemes as operator lists: parsing, validation, YAML, custom schemes."""

import numpy as np
import pytest
from ase import units
from helpers import mixture, waters

from rigidmd import RigidVerlet
from rigidmd.core.schemes import BUILTIN_SCHEMES, OPERATORS, Scheme, resolve_scheme


def test_builtins_are_valid_schemes():
    calls = {"no_squish": 1, "richardson": 1, "rozmanov_kusalik": 1, "pcdm": 2, "exadem": 1,
             "baoab": 1}
    for name in BUILTIN_SCHEMES:
        scheme = resolve_scheme(name)
        assert scheme.name == name
        assert scheme.force_calls_per_step == calls[name]


def test_list_and_yaml_give_the_builtin(tmp_path):
    yaml_text = """
- translational_kick: {dt_scale: 0.5}
- drift
- rotational_kick: {dt_scale: 0.5}
- no_squish_rotate: {dt_scale: 1.0}
- compute_force
- translational_kick: {dt_scale: 0.5}
- rotational_kick
"""
    path = tmp_path / "nve.yaml"
    path.write_text(yaml_text)
    from_yaml = resolve_scheme(str(path))
    from_list = Scheme(["translational_kick", "drift", "rotational_kick", "no_squish_rotate",
                        "compute_force", "translational_kick", "rotational_kick"])
    builtin = resolve_scheme("no_squish")
    assert from_yaml == builtin and from_list == builtin
    # ... and the same trajectory, bit for bit, through the operator path.
    runs = []
    for spec in (builtin, str(path)):
        atoms = waters(4)
        RigidVerlet(atoms, units.fs, integrator=spec, backend="numpy").run(20)
        runs.append(atoms.positions.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_exadem_yaml_with_merged_operators(tmp_path):
    path = tmp_path / "exadem.yml"
    path.write_text("scheme:\n  - combined_compute_prolog\n  - reset_force_moment\n"
                    "  - compute_force\n  - force_to_accel\n  - combined_compute_epilog\n")
    assert resolve_scheme(str(path)) == resolve_scheme("exadem")


def test_reordered_scheme_runs():
    """A user's own splitting: rotate first, then translate (still second order)."""
    scheme = [("rotational_kick", {"dt_scale": 0.5}), ("no_squish_rotate", {}),
              ("translational_kick", {"dt_scale": 0.5}), ("drift", {}), "compute_force",
              ("translational_kick", {"dt_scale": 0.5}), ("rotational_kick", {"dt_scale": 0.5})]
    atoms = mixture()
    e0 = atoms.get_total_energy()
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", integrator=scheme)
    dyn.run(200)
    assert dyn.todict()["integrator"] == "custom"
    assert dyn.todict()["scheme"][1] == {"no_squish_rotate": {"dt_scale": 1.0}}
    # Same energy error as the built-in NO_SQUISH (measured 8e-4 eV here).
    assert abs(atoms.get_total_energy() - e0) < 3e-3


@pytest.mark.parametrize(
    "spec, error, match",
    [
        (["drift", "warp_drive", "compute_force"], ValueError, "unknown operator 'warp_drive'"),
        (["drift", "translational_kick"], ValueError, "never evaluates forces"),
        (["compute_force", "drift"], ValueError, r"moves atoms \(drift\) after its last"),
        ([{"drift": {"dt": 0.5}}, "compute_force"], ValueError, "unknown parameter 'dt'"),
        ([{"drift": {"dt_scale": -1}}, "compute_force"], ValueError, "dt_scale must be positive"),
        ([{"drift": {"dt_scale": "half"}}, "compute_force"], TypeError, "must be a number"),
        ([42, "compute_force"], TypeError, "scheme entry 0"),
        ("leapfrog", ValueError, "unknown integrator 'leapfrog'"),
        ([{"rozmanov_kusalik_rotate": {"max_iter": 0}}, "compute_force"], ValueError,
         "max_iter must be a positive integer"),
    ],
)
def test_bad_schemes_are_refused(spec, error, match):
    with pytest.raises(error, match=match):
        resolve_scheme(spec)
    atoms = waters(2)
    before = atoms.positions.copy()
    with pytest.raises(error, match=match):
        RigidVerlet(atoms, units.fs, integrator=spec)
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def test_builtin_parameters():
    scheme = resolve_scheme("rozmanov_kusalik", tol=1e-10, max_iter=7)
    (_, params), = [(n, p) for n, p in scheme.steps if n == "rozmanov_kusalik_rotate"]
    assert params == {"dt_scale": 1.0, "tol": 1e-10, "max_iter": 7}
    with pytest.raises(ValueError, match="takes no parameter 'tol'"):
        resolve_scheme("no_squish", tol=1e-3)


def test_every_operator_is_documented():
    import rigidmd.core.schemes as module

    for name in OPERATORS:
        assert f"``{name}``" in module.__doc__, name


def test_compiled_kernel_matches_its_operators():
    """Each fused loop of the no_squish kernel against the operators it fuses, one by one."""
    from rigidmd.core import _numba
    from rigidmd.core import observables as obs
    from rigidmd.core import operators as ops

    atoms = mixture()
    dyn = RigidVerlet(atoms, units.fs, bodies="mol-id", backend="numpy")
    dyn.run(3)
    m, dt = dyn.model, 2 * units.fs
    forces = atoms.get_forces()
    ref, fused = dyn.state.copy(), dyn.state.copy()
    F, tau = ops.reduce_forces(forces, dyn.record.r, m)

    # First loop: translational_kick(dt/2), drift(dt), rotational_kick(dt/2),
    # no_squish_rotate(dt), placement.
    ops.translational_kick(ref, F, forces[m.free], m, 0.5 * dt)
    ref.X += dt * ref.V
    ops.rotational_kick(ref, tau, 0.5 * dt)
    ops.free_rotor(ref, m.inv_moments, dt)
    r_ref, x_ref = ops.place_atoms(ref, m)
    r, positions = np.zeros_like(r_ref), np.zeros((len(atoms), 3))
    body, atom, index = _numba.pack_model(m.inv_mass, m.inv_moments, m.body_coordinates,
                                          m.atom_masses, m.bounds, m.order)
    n = m.n_bodies
    _numba.first_half(fused.data, n, F, tau, body, atom, index, dt, r, positions,
                      np.array([np.eye(3)] * 3), False)
    # Measured: X and V identical, q and p within 5e-16 relative, lab
    # displacements and positions within 9e-16 Å (the kernel's Taylor sin/cos
    # below 0.25 rad and its fused sums round differently).
    for name in ("X", "V", "q", "p"):
        np.testing.assert_allclose(getattr(fused, name), getattr(ref, name), rtol=1e-14,
                                   atol=1e-15, err_msg=name)
    np.testing.assert_allclose(r, r_ref, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(positions[m.order], x_ref, rtol=1e-14, atol=1e-14)

    # Second loop: reduction, translational_kick(dt/2), rotational_kick(dt/2), momenta.
    F2, tau2 = np.zeros_like(F), np.zeros_like(tau)
    momenta = np.zeros((len(atoms), 3))
    assert _numba.second_half(fused.data, n, F2, tau2, body, atom, index, dt, forces, r,
                              momenta, True)
    F_ref, tau_ref = ops.reduce_forces(forces, r_ref, m)
    ops.translational_kick(ref, F_ref, forces[m.free], m, 0.5 * dt)
    ops.rotational_kick(ref, tau_ref, 0.5 * dt)
    np.testing.assert_allclose(F2, F_ref, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(tau2, tau_ref, rtol=1e-13, atol=1e-14)
    for name in ("V", "p"):
        np.testing.assert_allclose(getattr(fused, name), getattr(ref, name), rtol=1e-14,
                                   atol=1e-15, err_msg=name)
    p_ref = m.atom_masses[:, None] * ops.atom_velocities(ref, r_ref, m)
    np.testing.assert_allclose(momenta[m.order], p_ref, rtol=1e-13, atol=1e-14)
    # ... and the stand-alone placement and momenta loops the dynamics uses.
    r3, positions3, momenta3 = np.zeros_like(r), np.zeros_like(positions), np.zeros_like(momenta)
    _numba.place(fused.X, fused.q, m.body_coordinates, m.bounds, m.order, r3, positions3)
    np.testing.assert_array_equal(positions3[m.order], positions[m.order])
    _numba.momenta(fused.V, fused.q, fused.p, m.inv_moments, m.bounds, m.order, m.atom_masses,
                   r3, momenta3)
    np.testing.assert_array_equal(momenta3[m.order], momenta[m.order])
    # Without write_momenta the second loop leaves the momenta alone.
    untouched = np.full((len(atoms), 3), 7.0)
    assert _numba.second_half(fused.copy().data, n, F2, tau2, body, atom, index, dt, forces,
                              r, untouched, False)
    assert np.all(untouched == 7.0)
    # The step-size check's compiled fastest body: the observables' numbers.
    b, speed = _numba.largest_angular_speed(fused.q, fused.p, m.inv_moments)
    b_ref, speed_ref = obs.largest_angular_speed(fused, m)
    assert b == b_ref and speed == pytest.approx(speed_ref, rel=1e-14)
    # A NaN force on any body atom: the second loop refuses and writes nothing at all.
    bad = forces.copy()
    bad[m.order[-1], 1] = np.nan
    before = fused.copy()
    F3, tau3, momenta4 = F2.copy(), tau2.copy(), np.full((len(atoms), 3), 7.0)
    assert not _numba.second_half(fused.data, n, F3, tau3, body, atom, index, dt, bad, r,
                                  momenta4, True)
    np.testing.assert_array_equal(fused.data, before.data)
    np.testing.assert_array_equal(F3, F2)
    np.testing.assert_array_equal(tau3, tau2)
    assert np.all(momenta4 == 7.0)
