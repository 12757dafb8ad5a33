"""Rigid bodies under a tight-binding calculator: tblite's GFN2-xTB through ASE.

tblite installs from PyPI as a wheel (the ``test`` extra has it) and needs no
downloads at run time.  One thread, so that the figures below reproduce.
"""

import os

import numpy as np
import pytest
from ase import units
from ase.build import molecule

from rigidmd import RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core import quaternion as quat
from rigidmd.systems import random_quaternions, water_cluster, water_molecule

os.environ.setdefault("OMP_NUM_THREADS", "1")
tblite_ase = pytest.importorskip(
    "tblite.ase", reason='needs tblite (pip install "rigidmd[tb]"; the test extra has it)')

pytestmark = pytest.mark.tblite


def gfn2():
    return tblite_ase.TBLite(method="GFN2-xTB", verbosity=0)


def conserved(dyn, steps, every=5):
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=every)
    dyn.run(steps)
    return np.array(energies)


def test_rigid_water_cluster_conserves_energy_under_gfn2():
    """8 rigid waters at 300 K, NO_SQUISH at 1 fs for 0.5 ps with GFN2-xTB forces.

    Measured: the energy spans 1.2e-3 eV and drifts -1.0e-3 eV/ps (2 fs: 3.1e-3 eV,
    -2.0e-3 eV/ps), the size of a force-field run's (the SCC is converged tightly
    enough not to heat the run).  Bounds 4e-3 eV and 4e-3 eV/ps.
    """
    atoms = water_cluster(8, seed=1)
    atoms.calc = gfn2()
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    energies = conserved(RigidVerlet(atoms, 1 * units.fs), 500)
    slope = np.polyfit(np.arange(len(energies)) * 5e-3, energies, 1)[0]  # eV/ps
    assert np.ptp(energies) < 4e-3, np.ptp(energies)
    assert abs(slope) < 4e-3, slope


def solvated_methanol(seed=0):
    """A flexible methanol with six rigid waters around it, 3.3 Å out along ±x, ±y, ±z."""
    solute = molecule("CH3OH")
    solute.positions -= solute.get_center_of_mass()
    water = water_molecule()
    local = water.positions - water.get_center_of_mass()
    q = random_quaternions(6, np.random.default_rng(seed))
    centres = 3.3 * np.concatenate([np.eye(3), -np.eye(3)])
    waters = centres[:, None, :] + quat.rotate(q[:, None, :], local[None])
    atoms = solute.copy()
    for w in waters:
        atoms += water.__class__("OH2", positions=w)
    bodies = [list(range(len(solute) + 3 * k, len(solute) + 3 * k + 3)) for k in range(6)]
    return atoms, bodies, len(solute)


def test_rigid_solvent_and_flexible_solute_in_one_step():
    """Free solute atoms and rigid waters move in the same step and conserve energy.

    0.5 fs (the flexible C-H and O-H bonds set the step), 200 steps at 300 K.
    Measured: the O-H bond of methanol ranges over 0.023 Å while every water's
    intramolecular distances stay within 2.1e-14 Å of their start (roundoff in the
    placement); the energy spans 1.0e-3 eV.  Bounds: 0.01 Å of bond motion,
    1e-12 Å of water distortion, 4e-3 eV.
    """
    atoms, bodies, n_solute = solvated_methanol()
    atoms.calc = gfn2()
    rigid_maxwell_boltzmann(atoms, 300, bodies=bodies, rng=np.random.default_rng(1))
    dyn = RigidVerlet(atoms, 0.5 * units.fs, bodies=bodies)
    assert dyn.model.n_bodies == 6 and dyn.model.n_free == n_solute
    assert dyn.degrees_of_freedom == 6 * 6 + 3 * n_solute
    oh, water_distances = [], []

    def record():
        x = atoms.positions
        oh.append(np.linalg.norm(x[1] - x[3]))  # CH3OH: C, O, H(O), H, H, H -> O-H(O)
        w = x[n_solute:].reshape(6, 3, 3)
        water_distances.append(np.linalg.norm(w[:, [0, 0, 1]] - w[:, [1, 2, 2]], axis=2))

    dyn.attach(record, interval=5)
    energies = conserved(dyn, 200)
    water_distances = np.array(water_distances)
    assert np.ptp(oh) > 0.01, np.ptp(oh)
    assert np.abs(water_distances - water_distances[0]).max() < 1e-12
    assert np.ptp(energies) < 4e-3, np.ptp(energies)


def test_relax_bodies_gives_every_water_the_gfn2_geometry():
    """TIP3P-geometry waters get GFN2-xTB's own water, in place.

    Measured: GFN2-xTB relaxes water to O-H 0.9592 Å and 107.22° (TIP3P: 0.9572 Å,
    104.52°), 4.8e-3 eV below the TIP3P geometry; centres of mass move by 4e-16 Å,
    the bodies' principal frames not at all (|q0·q1| = 1 - 1e-16).
    """
    from rigidmd import RigidBodies
    from rigidmd.relax import relax_bodies

    atoms = water_cluster(8, seed=1)
    result = relax_bodies(atoms, gfn2())
    water = result.templates["OHH"]
    assert water.get_distance(0, 1) == pytest.approx(0.9592, abs=2e-4)
    assert water.get_angle(1, 0, 2) == pytest.approx(107.22, abs=0.05)
    assert result.strain_energies["OHH"] == pytest.approx(4.8e-3, abs=0.5e-3)
    assert result.bodies["OHH"] == list(range(8))
    before = RigidBodies.resolve(atoms).geometry(atoms)
    after = RigidBodies.resolve(result.atoms).geometry(result.atoms)
    assert np.abs(after.com - before.com).max() < 1e-12
    assert np.abs(np.sum(after.quaternions * before.quaternions, axis=1)).min() > 1 - 1e-9
    x = result.atoms.positions.reshape(8, 3, 3)
    np.testing.assert_allclose(np.linalg.norm(x[:, 1:] - x[:, :1], axis=2),
                               water.get_distance(0, 1), atol=1e-12)
    # A rigid run from there feels no internal strain to speak of: the isolated relaxed
    # molecule has forces below fmax (1e-3 eV/Å).
    water.calc = gfn2()
    assert np.abs(water.get_forces()).max() < 1e-3


def test_relax_bodies_refuses_what_it_cannot_do():
    from rigidmd.relax import relax_bodies

    four = water_cluster(2, model="tip4p2005")
    with pytest.raises(ValueError, match="atom 3 is massless"):
        relax_bodies(four, gfn2())
    with pytest.raises(ValueError, match=r"OHH \(body 0, atoms \[0, 1, 2\]\) did not relax"):
        relax_bodies(water_cluster(2), gfn2(), steps=1)
