"""Schemes as operator lists: parsing, validation, YAML, custom schemes."""

import numpy as np
import pytest
from ase import units
from helpers import mixture, waters

from rigidmd import RigidVerlet
from rigidmd.schemes import BUILTIN_SCHEMES, OPERATORS, Scheme, resolve_scheme


def test_builtins_are_valid_schemes():
    calls = {"no_squish": 1, "richardson": 1, "rozmanov_kusalik": 1, "pcdm": 2, "exadem": 1}
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
    import rigidmd.schemes as module

    for name in OPERATORS:
        assert f"``{name}``" in module.__doc__, name
