"""Mean squared displacement and diffusion (rigidmd.mdanalysis.diffusion): ballistic
motion has MSD = <v²> t² exactly, also for rigid waters that rotate and cross the
periodic boundaries.
"""

import warnings

import numpy as np
import pytest

mda = pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')
from ase import Atoms, units
from helpers import ZeroForce

from rigidmd import RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.mdanalysis import (
    PS,
    MeanSquaredDisplacement,
    mean_squared_displacement,
    to_universe,
)
from rigidmd.mdanalysis.diffusion import yeh_hummer_correction
from rigidmd.systems import water_box

pytestmark = pytest.mark.filterwarnings(
    "ignore:DCDReader currently makes independent timesteps:DeprecationWarning")


# ---------------------------------------------------------------------------- MSD


def test_msd_function_is_exact_for_ballistic_motion():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(50, 3))
    t = np.arange(30) * 0.1
    x = rng.uniform(0, 20, (50, 3)) + t[:, None, None] * v
    msd = mean_squared_displacement(x)
    np.testing.assert_allclose(msd, t[:, None] ** 2 * np.sum(v**2, axis=1), rtol=1e-10,
                               atol=1e-12)


def test_msd_of_ballistic_rigid_waters_across_the_box(tmp_path):
    """Free rigid waters tumble and cross the faces; their centres move as V t."""
    atoms = water_box(3, seed=2, whole=False)  # molecules across the faces from the start
    atoms.calc = ZeroForce()
    rigid_maxwell_boltzmann(atoms, 1000.0, bodies="mol-id", rng=np.random.default_rng(2))
    dyn = RigidVerlet(atoms, 2 * units.fs, bodies="mol-id")
    speed2 = np.sum(dyn.com_velocities**2, axis=1)  # Å² per ASE time²
    frames = []

    def record():
        wrapped = atoms.copy()
        wrapped.wrap()  # as a code that wraps atoms one by one would write them
        frames.append(wrapped)

    dyn.attach(record, interval=10)
    dyn.run(400)  # 0.8 ps: molecules travel up to several Å
    u = to_universe(frames, bodies="mol-id", dt=0.02)
    start = np.array([res.atoms.center_of_mass() for res in u.residues])
    u.trajectory[-1]
    end = np.array([res.atoms.center_of_mass() for res in u.residues])
    assert np.abs(end - start).max() > 3.1  # some jumped by a box length when wrapped
    # Ballistic motion: the MSD grows as t^2, so no diffusion coefficient is given.
    with pytest.warns(RuntimeWarning, match=r"t\^2\.00"):
        msd = MeanSquaredDisplacement(u, "all").run()
    assert msd.results.msd_exponent == pytest.approx(2.0, abs=1e-3)
    assert np.isnan(msd.results.diffusion_coefficient)
    lag = msd.results.lagtimes * PS  # ASE time
    expected = speed2.mean() * lag**2
    np.testing.assert_allclose(msd.results.timeseries, expected, rtol=1e-4, atol=1e-4)
    # Without unwrapping, the jumps across the faces count as motion.  (Whether that MSD
    # also looks non-linear, and warns, depends on which molecules cross the faces.)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "MeanSquaredDisplacement", RuntimeWarning)
        same = MeanSquaredDisplacement(u, "all", unwrap=False).run()
    assert np.abs(same.results.timeseries - expected).max() > 1.0
    assert msd.plot(tmp_path / "msd.png") is not None


def test_diffusion_coefficient_of_a_random_walk():
    rng = np.random.default_rng(7)
    D, dt = 0.25, 0.05  # Å²/ps, ps
    steps = rng.normal(scale=np.sqrt(2 * D * dt), size=(800, 400, 3))
    x = rng.uniform(0, 100, (400, 3)) + np.cumsum(steps, axis=0)
    frames = [Atoms("Ar400", positions=p) for p in x]
    u = to_universe(frames, dt=dt, bodies=np.full(400, -1))  # every atom free
    msd = MeanSquaredDisplacement(u, "all", compound="atoms").run()
    assert msd.results.diffusion_coefficient == pytest.approx(D, rel=0.05)
    assert msd.results.diffusion_coefficient_cm2_s == pytest.approx(
        msd.results.diffusion_coefficient * 1e-4)
    xy = MeanSquaredDisplacement(u, "all", compound="atoms", msd_type="xy",
                                 fit_range=(2.0, 10.0)).run()
    assert xy.results.diffusion_coefficient == pytest.approx(D, rel=0.05)
    assert xy.results.fit_range == (2.0, 10.0)
    # A drift of the whole system (as a Langevin thermostat leaves) is removed on request.
    t = np.arange(len(x)) * dt
    drifting = [Atoms("Ar400", positions=p + 0.3 * tk) for p, tk in zip(x, t, strict=True)]
    u = to_universe(drifting, dt=dt, bodies=np.full(400, -1))
    # The drift makes the MSD grow faster than linearly (exponent 1.6 measured): no D.
    with pytest.warns(RuntimeWarning, match="not linearly"):
        plain = MeanSquaredDisplacement(u, "all", compound="atoms").run()
    assert plain.results.msd_exponent > 1.25 and not plain.results.diffusive
    assert np.isnan(plain.results.diffusion_coefficient)
    fixed = MeanSquaredDisplacement(u, "all", compound="atoms", remove_com_motion=True).run()
    assert fixed.results.diffusion_coefficient == pytest.approx(D, rel=0.05)


def test_a_fit_range_that_cannot_be_fitted_is_said_as_such():
    """A reversed or negative range is refused naming fit_range; a range beyond the lag
    times gives NaN with a warning that says so (before: "MSD grows as t^nan ... not
    linearly", blaming the physics); too few frames selected are refused in one line (before,
    an OverflowError)."""
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 10, (20, 3)) + np.cumsum(rng.normal(size=(30, 20, 3)), axis=0)
    u = to_universe([Atoms("Ar20", positions=p) for p in x], dt=0.1,
                    bodies=np.full(20, -1))
    for bad in ((0.5, 0.1), (-1.0, 0.5), 0.5, ("a", 1)):
        with pytest.raises(ValueError, match="fit_range must be"):
            MeanSquaredDisplacement(u, "all", compound="atoms", fit_range=bad)
    with pytest.warns(RuntimeWarning, match=r"fit_range \(5, 10\) ps holds 0 of the lag "
                                            "times"):
        far = MeanSquaredDisplacement(u, "all", compound="atoms", fit_range=(5, 10)).run()
    assert np.isnan(far.results.diffusion_coefficient) and not far.results.diffusive
    with pytest.raises(ValueError, match=r"the frames selected .* are 0; it needs at least 2"):
        MeanSquaredDisplacement(u, "all", compound="atoms").run(start=50)


# --------------------------------------------------- Yeh–Hummer correction
def test_yeh_hummer_correction():
    """ξ kT/(6πηL): 0.372e-5 cm²/s for real water's η in the 18.6 Å TIP3P box of
    docs/validation/water.md, and 1.04e-5 with TIP3P's own 0.321 mPa s (González & Abascal
    2010)."""
    assert yeh_hummer_correction(298.0, 0.896, 18.6) * 1e-4 == pytest.approx(0.372e-5,
                                                                               rel=2e-3)
    assert yeh_hummer_correction(298.0, 0.321, 18.6) * 1e-4 == pytest.approx(1.037e-5,
                                                                               rel=2e-3)
    with pytest.raises(ValueError, match="positive"):
        yeh_hummer_correction(298.0, 0.0, 18.6)


def test_the_msd_of_massless_sites_is_refused():
    """The M sites of TIP4P/2005 (``"name MW"``, mass 0) have no centre of mass: the MSD was
    all NaN, with a warning blaming the physics ("MSD grows as t^nan")."""
    frames = []
    for k in range(6):
        atoms = water_box(2, model="tip4p2005")
        atoms.positions += 0.1 * k  # every site moves by (0.1, 0.1, 0.1) Å per frame
        frames.append(atoms)
    u = to_universe(frames, bodies=[list(range(4 * i, 4 * i + 4)) for i in range(8)], dt=0.1)
    with pytest.raises(ValueError, match=r"^MeanSquaredDisplacement: the selection 'name MW' "
                                         r"holds no mass in residue 1 \(SOL\)"):
        MeanSquaredDisplacement(u, "name MW")
    with pytest.raises(ValueError, match=r"^MeanSquaredDisplacement: the selection 'name MW' "
                                         "has no mass, so remove_com_motion"):
        MeanSquaredDisplacement(u, "name MW", compound="atoms", remove_com_motion=True)
    # The sites themselves, and the molecules' centres of mass, move 3 * 0.01 Å² per frame².
    expected = 0.03 * np.arange(6) ** 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # ballistic: no D, as it should be
        for select, compound in (("name MW", "atoms"), ("resname SOL", "residues")):
            msd = MeanSquaredDisplacement(u, select, compound=compound).run()
            # float32 positions of 6 Å: 5e-7 Å, so 1e-5 Å² on these MSDs (measured 2e-6)
            np.testing.assert_allclose(msd.results.timeseries, expected, atol=1e-5)
