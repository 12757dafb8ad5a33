import warnings

import numpy as np
import pytest
from ase import Atoms

from rigidmd import RigidBodies
from rigidmd.core import quaternion as quat
from rigidmd.systems import co2_water_mixture, water_box, water_cluster


def reconstruct(geom):
    """Unwrapped atom positions X + R(q) d, in geom.model.order."""
    return geom.com[geom.model.atom_body] + quat.rotate(
        geom.quaternions[geom.model.atom_body], geom.model.body_coordinates
    )


def test_rules_agree_on_waters():
    atoms = water_cluster(5, seed=3)
    expected = np.repeat(np.arange(5), 3)
    atoms.set_tags(expected + 7)
    for spec, rule in [(None, "mol-id"), ("connectivity", "connectivity"), ("mol-id", "mol-id"),
                       ("tags", "tags"),
                       (expected, "body-ids"), ([[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11],
                                                 [12, 13, 14]], "index-lists")]:
        bodies = RigidBodies.resolve(atoms, spec)
        np.testing.assert_array_equal(bodies.body_ids, expected)
        assert bodies.rule == rule
        assert bodies.n_bodies == 5
    assert RigidBodies.resolve(atoms, bodies) is bodies


def test_free_atoms_and_single_atom_bodies():
    atoms = water_cluster(2, seed=1) + Atoms("Ne2", positions=[[9, 0, 0], [0, 9, 0]])
    bodies = RigidBodies.resolve(atoms, [0, 0, 0, 1, 1, 1, 5, -1])
    np.testing.assert_array_equal(bodies.body_ids, [0, 0, 0, 1, 1, 1, -1, -1])
    np.testing.assert_array_equal(bodies.free_indices, [6, 7])
    # Unlisted atoms are free; connectivity finds the isolated atoms too.
    assert list(RigidBodies.resolve(atoms, [[0, 1, 2]]).free_indices) == [3, 4, 5, 6, 7]
    # ASE filled the neons' mol-id with 0, so the default rule (mol-id) makes them one
    # body, and says so; connectivity finds them free.
    with pytest.warns(UserWarning, match=r"body 0 \(atoms \[6, 7\]\) falls into 2 pieces"):
        assert RigidBodies.resolve(atoms).n_bodies == 3
    conn = RigidBodies.resolve(atoms, "connectivity")
    np.testing.assert_array_equal(conn.body_ids, [0, 0, 0, 1, 1, 1, -1, -1])
    geom = conn.geometry(atoms)
    # Two waters (6 each) and two point particles (3 each).
    assert geom.model.degrees_of_freedom == 18


def test_geometry_is_principal_and_reconstructs(rng):
    atoms = co2_water_mixture(3, 3, seed=2)
    bodies = RigidBodies.resolve(atoms, "mol-id")
    g = bodies.geometry(atoms)
    np.testing.assert_allclose(reconstruct(g), atoms.positions[g.model.order], atol=1e-13)
    masses = atoms.get_masses()
    for b in range(bodies.n_bodies):
        idx = bodies.atoms_of(b)
        m = masses[idx]
        com = m @ atoms.positions[idx] / m.sum()
        np.testing.assert_allclose(g.com[b], com, atol=1e-13)
        r = atoms.positions[idx] - com
        tensor = np.sum(m[:, None, None] * (np.eye(3) * (r * r).sum(1)[:, None, None]
                                             - r[:, :, None] * r[:, None, :]), axis=0)
        # The body frame diagonalises the inertia tensor.
        R = quat.to_matrix(g.quaternions[b])
        diag = R.T @ tensor @ R
        np.testing.assert_allclose(diag, np.diag(g.model.moments[b]), atol=1e-9)
    linear = g.model.linear
    is_co2 = np.array([atoms.symbols[bodies.atoms_of(b)[0]] == "C" for b in range(6)])
    np.testing.assert_array_equal(linear, is_co2)
    assert g.model.degrees_of_freedom == 6 * 3 + 5 * 3
    assert np.all(g.model.moments[linear, 0] == 0.0)


def test_periodic_molecules_are_made_whole():
    atoms = water_box(3, seed=4, whole=False)
    g = RigidBodies.resolve(atoms, "mol-id").geometry(atoms)
    x = reconstruct(g)
    # Some molecules straddle the boundary, yet every O–H distance is the bond length.
    wrapped = atoms.positions[g.model.order]
    assert np.any(np.abs(x - wrapped) > 1.0)
    oh = np.linalg.norm(x.reshape(-1, 3, 3)[:, 1:] - x.reshape(-1, 3, 3)[:, :1], axis=2)
    np.testing.assert_allclose(oh, 0.9572, atol=1e-12)
    # The unwrapped images are the wrapped atoms shifted by lattice vectors.
    frac = np.linalg.solve(atoms.cell.T, (x - wrapped).T).T
    np.testing.assert_allclose(frac, np.round(frac), atol=1e-12)


def test_the_water_box_is_built_of_whole_molecules():
    # ASE's TIP3P takes the distances within a molecule without the minimum image: on
    # molecules split across the boundary it gave +192 eV for 64 waters (rc = 6 Å).
    from ase.calculators.tip3p import TIP3P

    atoms = water_box(4)
    x = atoms.positions.reshape(-1, 3, 3)
    oh = np.linalg.norm(x[:, 1:] - x[:, :1], axis=2)
    np.testing.assert_allclose(oh, 0.9572, atol=1e-12)
    atoms.calc = TIP3P(rc=6.0)
    split = water_box(4, whole=False)
    split.calc = TIP3P(rc=6.0)
    # The same molecules, each whole: ASE's own TIP3P on the wrapped atoms made whole
    # again by moving each molecule's hydrogens next to its oxygen.
    whole = split.copy()
    xs = whole.positions.reshape(-1, 3, 3)
    shift = np.linalg.solve(whole.cell.T, (xs[:, 1:] - xs[:, :1]).reshape(-1, 3).T).T
    xs[:, 1:] -= (np.round(shift) @ whole.cell.array).reshape(-1, 2, 3)
    whole.positions = xs.reshape(-1, 3)
    whole.calc = TIP3P(rc=6.0)
    # Roundoff of the oxygens' images (measured: 2.6e-14 eV).
    assert atoms.get_potential_energy() == pytest.approx(whole.get_potential_energy(),
                                                         rel=0, abs=1e-11)
    assert atoms.get_potential_energy() < 1.0 < split.get_potential_energy() - 100


@pytest.mark.parametrize(
    "spec, error, match",
    [
        ([[0, 1, 2], [2, 3, 4]], ValueError, "atom 2 is in both body 0 and body 1"),
        ([[0, 1, 99]], ValueError, "body 0 names atom 99"),
        ([[0, 1], []], ValueError, "body 1 is empty"),
        ([[0, 1, 1]], ValueError, "lists atom 1 twice"),
        ([[0.5, 1]], TypeError, "non-integer"),
        (np.zeros(4, dtype=int), ValueError, "one body id per atom"),
        (np.full(6, 0.5), TypeError, "must be integers"),
        ("residues", ValueError, "unknown rule 'residues'"),
        ("mol-id", ValueError, "no 'mol-id' array"),
    ],
)
def test_bad_body_definitions(spec, error, match):
    atoms = water_cluster(2, seed=0)
    del atoms.arrays["mol-id"]
    with pytest.raises(error, match=match):
        RigidBodies.resolve(atoms, spec)


def test_bad_geometry():
    atoms = Atoms("H2O", positions=[[1, 1, 1]] * 3)
    with pytest.raises(ValueError, match=r"body 0 \(atoms \[0, 1, 2\]\) has all its mass at one"):
        RigidBodies.resolve(atoms, [[0, 1, 2]]).geometry(atoms)
    atoms = water_cluster(2)
    # (A mass of 0 is a virtual site, allowed inside a body: see test_water.py.)
    for mass in (-1.0, np.nan):
        m = atoms.get_masses()
        m[4] = mass
        atoms.set_masses(m)
        with pytest.raises(ValueError, match="atom 4 .* has mass"):
            RigidBodies.resolve(atoms, "mol-id").geometry(atoms)


def test_body_larger_than_half_the_cell_is_refused():
    atoms = Atoms("H2", positions=[[0, 0, 0], [1.9, 0, 0]], cell=[4, 4, 4], pbc=True)
    RigidBodies.resolve(atoms, [[0, 1]]).geometry(atoms)  # 1.9 < 2: fine
    atoms.positions[1, 0] = 2.1  # minimum image is now -1.9 through the boundary: fine too
    RigidBodies.resolve(atoms, [[0, 1]]).geometry(atoms)
    chain = Atoms("H3", positions=[[0, 0, 0], [1.5, 0, 0], [3.0, 0, 0]], cell=[4, 4, 4], pbc=True)
    message = "body 0 .* spans 2.500 Å across cell vector 0, more than half"
    with pytest.raises(ValueError, match=message):
        RigidBodies.resolve(chain, [[0, 1, 2]]).geometry(chain)


def test_the_one_rule_for_a_body_spanning_half_the_cell():
    """body_too_wide refuses exactly the cells with 2 R_b >= w_k / 2 (R_b: the body's radius,
    w_k: the width across a periodic cell vector); every body of a cell it passes reaches
    less than half the cell along every cell vector, computed atom by atom, so the
    minimum image is unambiguous (random sheared and shrunk cells around the threshold)."""
    from rigidmd.core.bodies import body_radii, body_too_wide, cell_widths, check_bodies_fit
    from rigidmd.md.verlet import RigidVerlet

    atoms = co2_water_mixture(n_co2=2, n_water=2, box=True)
    dyn = RigidVerlet(atoms, 1.0, bodies="mol-id")
    model, r = dyn.model, dyn.record.r
    spans = 2 * body_radii(model)
    rng = np.random.default_rng(0)
    refused = passed = 0
    for _ in range(400):
        cell = np.diag(rng.uniform(2.0, 12.0, 3)) + np.tril(rng.uniform(-1.5, 1.5, (3, 3)), -1)
        wide = body_too_wide(model, cell, [True] * 3)
        if spans.max() >= 0.5 * cell_widths(cell).min():
            b, k, span, width = wide
            assert span == spans.max() and width == cell_widths(cell).min()
            with pytest.raises(ValueError, match=f"body {b} .* not less than half the periodic "
                                                 f"cell's width across cell vector {k}"):
                check_bodies_fit(model, cell, [True] * 3)
            refused += 1
        else:
            assert wide is None
            check_bodies_fit(model, cell, [True] * 3)
            frac = np.linalg.solve(cell.T, r.T).T
            extent = np.maximum.reduceat(frac, model.starts) - np.minimum.reduceat(
                frac, model.starts)
            assert extent.max() < 0.5
            passed += 1
    assert refused > 50 and passed > 50  # both sides of the threshold were tried
    # A direction that is not periodic never refuses.
    assert body_too_wide(model, np.diag([1.0, 50.0, 50.0]), [False, True, True]) is None


def test_connectivity_warns_about_joined_molecules():
    atoms = water_cluster(3, seed=0)
    # Push the second water's oxygen within bonding reach of the first's hydrogen.
    shift = atoms.positions[1] + [0.0, 0.0, 1.0] - atoms.positions[3]
    atoms.positions[3:6] += shift
    with pytest.warns(UserWarning, match=r"body 0 .* has 2 times the atoms of another body"):
        bodies = RigidBodies.resolve(atoms, "connectivity")
    assert bodies.n_bodies == 2
    # The default rule uses the molecule ids the atoms carry, without a word.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert RigidBodies.resolve(atoms).n_bodies == 3


@pytest.mark.parametrize("n", [4, 8])
def test_default_rule_prefers_molecule_ids_then_tags(n):
    """Connectivity joins a CO2 and a water of a dense mixture; mol-id and tags do not."""
    atoms = co2_water_mixture(n_co2=n, n_water=n, box=True)
    assert RigidBodies.resolve(atoms).n_bodies == 2 * n
    mol = atoms.arrays.pop("mol-id")
    atoms.set_tags(mol)
    assert RigidBodies.resolve(atoms).n_bodies == 2 * n
    atoms.set_tags(0)
    # Connectivity alone: (4, 4) joins two waters, (8, 8) a CO2 and a water (CH2O3).
    message = "2 times the atoms" if n == 4 else "the only CH2O3 among 15 bodies"
    with pytest.warns(UserWarning, match=message):
        assert RigidBodies.resolve(atoms).n_bodies == 2 * n - 1


def test_bonded_body_longer_than_half_the_cell_is_not_folded():
    """A whole water in a 1.8 Å wide cell: the minimum image would make O–H 0.843 Å."""
    water = Atoms("OH2", positions=[[0, 0, 0], [0.96, 0, 0], [-0.24, 0.93, 0]],
                  cell=[1.8, 10, 10], pbc=True)
    with pytest.raises(ValueError, match=r"body 0 \(atoms \[0, 1, 2\]\) spans 1.200 Å "
                       r"across cell vector 0, .* would fold it"):
        RigidBodies.resolve(water, [[0, 1, 2]]).geometry(water)
    water.cell[0, 0] = 2.5  # wider than twice the molecule: fine, and nothing moves
    g = RigidBodies.resolve(water, [[0, 1, 2]]).geometry(water)
    np.testing.assert_allclose(g.com[0], water.get_center_of_mass(), atol=1e-12)


def _top(kind):
    """A molecule of each kind of principal frame, exact to the last bit of its symmetry."""
    c, s = np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)
    ring = np.array([[1.0, 0.0, 0.0], [c, s, 0.0], [c, -s, 0.0]])
    if kind == "asymmetric":  # water
        return Atoms("OH2", positions=[[0, 0, 0.1173], [0, 0.7572, -0.4692],
                                       [0, -0.7572, -0.4692]])
    if kind == "linear":  # CO2
        return Atoms("OCO", positions=[[0, 0, -1.16], [0, 0, 0], [0, 0, 1.16]])
    if kind == "oblate":  # NH3: I1 = I2 < I3
        return Atoms("NH3", positions=np.vstack([[0, 0, 0.38], 0.94 * ring]))
    if kind == "planar oblate":  # BF3: every atom in the plane of equal moments
        return Atoms("BF3", positions=np.vstack([[0, 0, 0], 1.31 * ring]))
    if kind == "prolate":  # CH3Cl: I1 < I2 = I3
        return Atoms("CH3Cl", positions=np.vstack([[0, 0, 0], 1.03 * ring + [0, 0, -0.36],
                                                   [0, 0, 1.78]]))
    # CH4: three equal moments
    t = 0.63
    return Atoms("CH4", positions=[[0, 0, 0], [t, t, t], [-t, -t, t], [-t, t, -t],
                                   [t, -t, -t]])


KINDS = ["asymmetric", "linear", "oblate", "planar oblate", "prolate", "spherical"]


@pytest.mark.parametrize("kind", KINDS)
def test_the_body_frame_comes_from_the_atoms_not_from_lapack(kind, monkeypatch):
    # The same body, rigidly moved, has the same body-frame coordinates and moments:
    # its frame is taken from its atoms, never from the signs or the in-plane choice of
    # LAPACK's eigenvectors (which change with the last bits of the tensor).
    molecule = _top(kind)
    first = RigidBodies.resolve(molecule, [0] * len(molecule)).geometry(molecule).model
    rng = np.random.default_rng(7)
    eigh = np.linalg.eigh

    def another_lapack(tensor):
        # Eigenvectors as another LAPACK may return them: any signs, and any basis of
        # a space of equal moments.
        w, v = eigh(tensor)
        v = v * rng.choice([-1.0, 1.0], size=3)
        for i, j in ((0, 1), (1, 2)):
            same = np.abs(w[..., j] - w[..., i]) <= 1e-7 * w[..., 2]
            a = rng.uniform(0, 2 * np.pi)
            vi, vj = v[..., :, i].copy(), v[..., :, j].copy()
            v[..., :, i] = np.where(same[..., None], np.cos(a) * vi + np.sin(a) * vj, vi)
            v[..., :, j] = np.where(same[..., None], -np.sin(a) * vi + np.cos(a) * vj, vj)
        return w, v

    monkeypatch.setattr(np.linalg, "eigh", another_lapack)
    for _ in range(12):
        moved = molecule.copy()
        moved.rotate(rng.uniform(0, 360), rng.normal(size=3), center="COM")
        moved.translate(rng.normal(size=3))
        geometry = RigidBodies.resolve(moved, [0] * len(moved)).geometry(moved)
        model = geometry.model
        # Roundoff of the rotation and of eigh: at most 3.5e-15 Å and 1.8e-15 of the largest
        # moment, measured over 200 rotations of each kind.
        np.testing.assert_allclose(model.body_coordinates, first.body_coordinates, atol=1e-12)
        np.testing.assert_allclose(model.moments, first.moments, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(reconstruct(geometry), moved.positions[model.order],
                                   atol=1e-12)
        assert np.linalg.det(quat.to_matrix(geometry.quaternions[0])) == pytest.approx(1.0)


def test_the_tags_rule_refuses_atoms_without_tags():
    """``bodies='tags'`` on atoms whose tags were never set (all 0) made every atom one
    rigid body in silence: 4 waters glued into one body of 6 degrees of freedom."""
    from rigidmd.core.bodies import RigidBodies
    from rigidmd.systems import water_cluster

    atoms = water_cluster(4, seed=1)
    atoms.set_tags(0)
    with pytest.raises(ValueError, match=r"^bodies='tags' but every atom has tag 0 .* all 12 "
                                         r"atoms one rigid body"):
        RigidBodies.resolve(atoms, "tags")
    single = atoms[:3]  # one molecule: the connectivity rule makes it one body
    assert RigidBodies.resolve(single, "connectivity").n_bodies == 1


def test_a_flat_list_of_every_atom_index_is_read_as_body_ids_and_said():
    """``bodies=[0, 1, 2]`` on one water: one body id per atom (three point particles), as
    documented, but easily meant as the index list of one body; a warning says which."""
    atoms = water_cluster(1)
    with pytest.warns(UserWarning, match=r"^bodies: \[0, 1, \.\.\., 2\] is read as one body "
                                         r"id per atom, 3 single-atom bodies .* give "
                                         r"\[\[0, 1, \.\.\., 2\]\]$"):
        bodies = RigidBodies.resolve(atoms, [0, 1, 2])
    assert bodies.n_bodies == 0 and len(bodies.free_indices) == 3  # single atoms move free
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert RigidBodies.resolve(atoms, [[0, 1, 2]]).n_bodies == 1
        assert RigidBodies.resolve(atoms, [0, 0, 0]).n_bodies == 1
        assert len(RigidBodies.resolve(atoms[:1], [0]).free_indices) == 1  # one atom: no ask
