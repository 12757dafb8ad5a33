"""The dielectric constant from dipole fluctuations (rigidmd.mdanalysis.dielectric)."""

import numpy as np
import pytest
from ase import units

from rigidmd.systems import water_box
from rigidmd.water import water_model


# ---------------------------------------------------- dielectric constant
def dipole_fluid(rng, n_mol=40, n_frames=4000, q=0.8, s=1.4, box=20.0, shift=0.0):
    """Neutral two-site molecules whose bond vectors are Gaussian (σ = s per component):
    <M_i²> = n q² s², so ε = 1 + n q² s² / (V ε0 kT) exactly (in expectation).
    ``shift`` moves every molecule by whole boxes (unwrapped positions)."""
    import MDAnalysis as mda
    from MDAnalysis.coordinates.memory import MemoryReader

    u = mda.Universe.empty(2 * n_mol, n_residues=n_mol,
                           atom_resindex=np.repeat(np.arange(n_mol), 2), trajectory=True)
    u.add_TopologyAttr("charges", np.tile([q, -q], n_mol))
    u.add_TopologyAttr("masses", np.ones(2 * n_mol))
    u.add_TopologyAttr("bonds", [(2 * i, 2 * i + 1) for i in range(n_mol)])
    centres = rng.uniform(0, box, (n_mol, 3)) + shift
    x = np.empty((n_frames, 2 * n_mol, 3))
    x[:, 0::2] = centres
    x[:, 1::2] = centres + rng.normal(0.0, s, (n_frames, n_mol, 3))
    u.load_new(x.astype(np.float32), format=MemoryReader,
               dimensions=np.array([box, box, box, 90, 90, 90], dtype=np.float32))
    from rigidmd.mdanalysis.dielectric import EPSILON0
    exact = 1 + n_mol * q**2 * s**2 / (box**3 * EPSILON0 * units.kB * 300.0)
    return u, exact


@pytest.mark.mdanalysis
def test_dielectric_constant_of_known_fluctuations(rng):
    """ε within 3 jackknife errors of the exact value; MDAnalysis's own class gives the
    same ε; unwrapped molecules (shifted by whole boxes) give the same M."""
    from MDAnalysis.analysis.dielectric import DielectricConstant as MDA

    from rigidmd.mdanalysis import DielectricConstant, dielectric_from_dipoles

    u, exact = dipole_fluid(rng)
    assert 20 < exact < 100
    ours = DielectricConstant(u.atoms, temperature=300.0, make_whole=False).run()
    res = ours.results
    assert abs(res.eps_mean - exact) < 3 * res.eps_stderr, (res.eps_mean, exact, res.eps_stderr)
    assert 0.005 * exact < res.eps_stderr < 0.1 * exact
    theirs = MDA(u.atoms, temperature=300.0, make_whole=False).run()
    assert res.eps_mean == pytest.approx(theirs.results.eps_mean, rel=1e-6)
    assert dielectric_from_dipoles(res.dipoles, 20.0**3, 300.0) == pytest.approx(
        res.eps_mean, rel=1e-4)
    shifted, _ = dipole_fluid(np.random.default_rng(7), n_frames=50, shift=60.0)
    same, _ = dipole_fluid(np.random.default_rng(7), n_frames=50)
    a = DielectricConstant(shifted.atoms, temperature=300.0, blocks=5).run().results
    b = DielectricConstant(same.atoms, temperature=300.0, blocks=5).run().results
    assert np.allclose(a.dipoles, b.dipoles, atol=1e-3)


@pytest.mark.mdanalysis
def test_dielectric_takes_the_m_site_charges_from_the_topology():
    """A TIP4P/2005 box through to_universe: M is the sum of the molecular dipoles over
    all sites, M sites included, whole molecules (water_box's straddle the boundaries)."""
    from ase.geometry import find_mic

    from rigidmd.mdanalysis import DielectricConstant, to_universe

    model = water_model("tip4p2005")
    box = water_box(2, model="tip4p2005", whole=False)
    box.set_initial_charges(model.charges(8))
    u = to_universe([box])
    res = DielectricConstant(u.atoms, blocks=2).run().results
    x = box.positions.reshape(8, 4, 3)
    d = find_mic((x - x[:, :1]).reshape(-1, 3), box.cell)[0]
    expected = model.charges(8) @ d
    assert np.linalg.norm(model.charges(8) @ box.positions - expected) > 1.0  # not whole
    assert np.allclose(res.dipoles[0], expected, atol=1e-4)


@pytest.mark.parametrize("kwargs, match", [
    ({"temperature": -5}, "temperature must be a positive number"),
    ({"blocks": 0}, "blocks must be a whole number >= 2"),
    ({"charges": 0.0}, "charges are all zero"),
])
def test_what_gives_no_dielectric_constant_is_refused(kwargs, match):
    """A topology without charges gave ε = 1 ± 0 (a tip3p run's PSF had none); a negative
    temperature ε = −147; blocks = 0 a NaN error, each in silence."""
    from rigidmd.mdanalysis import DielectricConstant

    u, _ = dipole_fluid(np.random.default_rng(1), n_frames=10)
    if "charges" in kwargs:
        u.atoms.charges = np.zeros(len(u.atoms))
    with pytest.raises(ValueError, match=match):
        DielectricConstant(u.atoms, **{k: v for k, v in kwargs.items() if k != "charges"})
