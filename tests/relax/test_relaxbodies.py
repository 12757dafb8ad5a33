"""Each kind of molecule in the geometry a calculator prefers (rigidmd.relax.relaxbodies).

A flexible stand-in with a known minimum: harmonic springs between every pair of atoms of
a molecule, O–H at 0.9 Å and H–H at 1.5 Å (a triangle, so all springs are relaxed at
once).  GFN2-xTB's geometry is checked in ``tests/physics/test_tight_binding.py``."""


import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import Calculator, all_changes

import rigidmd.relax
from rigidmd.relax import BodyRelaxation, relax_bodies
from rigidmd.systems import water_box
from rigidmd.water import water_model

REST = {frozenset("OH"): 0.9, frozenset("H"): 1.5}


class Springs(Calculator):
    implemented_properties = ["energy", "forces"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        x, symbols = atoms.positions, atoms.get_chemical_symbols()
        energy, forces = 0.0, np.zeros_like(x)
        for i in range(len(x)):
            for j in range(i + 1, len(x)):
                d = x[j] - x[i]
                r = np.linalg.norm(d)
                r0 = REST[frozenset((symbols[i], symbols[j]))]
                energy += 5.0 * (r - r0) ** 2
                f = 10.0 * (r - r0) * d / r
                forces[i] += f
                forces[j] -= f
        self.results = {"energy": energy, "forces": forces}


def distances(positions):
    o, h1, h2 = positions
    return np.linalg.norm(h1 - o), np.linalg.norm(h2 - o), np.linalg.norm(h2 - h1)


def test_every_body_gets_its_kinds_relaxed_geometry():
    atoms = water_box(2, seed=1)
    atoms.set_momenta(np.ones((24, 3)))
    result = relax_bodies(atoms, Springs(), fmax=1e-6)
    assert isinstance(result, BodyRelaxation)
    assert list(result.templates) == ["OHH"] and result.bodies == {"OHH": list(range(8))}
    template = distances(result.templates["OHH"].positions)
    assert np.allclose(template, (0.9, 0.9, 1.5), atol=1e-6)
    # TIP3P's geometry (0.9572 Å, 104.52°) stretched the springs: that energy was the strain.
    assert result.strain_energies["OHH"] > 0.01
    out = result.atoms
    assert out.calc is None and "momenta" not in out.arrays
    whole = rigidmd.RigidBodies.resolve(out).whole_positions(out).reshape(8, 3, 3)
    for body in whole:
        assert np.allclose(distances(body), template, atol=1e-9)
    # Each body's centre of mass stays where it was (not wrapped into the cell).
    masses = atoms.get_masses()[:3]
    old = rigidmd.RigidBodies.resolve(atoms).whole_positions(atoms).reshape(8, 3, 3)
    shift = np.einsum("k,nki->ni", masses, whole - old) / masses.sum()
    assert np.abs(shift).max() < 1e-9


def test_what_it_cannot_do_is_refused():
    model = water_model("tip4p2005")
    four = water_box(1, model="tip4p2005")
    with pytest.raises(ValueError, match="relax_bodies: atom 3 is massless"):
        relax_bodies(four, Springs())
    assert model.sites == 4
    with pytest.raises(ValueError, match=r"relax_bodies: OHH \(body 0, atoms \[0, 1, 2\]\) "
                                         r"did not relax "
                                         r"to fmax=1e-09 eV/Å in 1 steps"):
        relax_bodies(water_box(1, seed=0), Springs(), fmax=1e-9, steps=1)


def test_the_old_name_is_gone():
    """No release had ``rigidmd.relax.Relaxation`` (now BodyRelaxation), so no shim keeps it."""
    with pytest.raises(AttributeError, match="has no attribute 'Relaxation'"):
        rigidmd.relax.Relaxation  # noqa: B018
    assert rigidmd.relax.BodyRelaxation is BodyRelaxation


def test_bodies_stay_whole_and_free_atoms_stay_put():
    """Everything was wrapped into the cell: a free atom moved (-1 Å to 8.3 Å) and 19 of
    27 waters came back split (ASE's TIP3P then gave 79.8 eV against 3.28 whole).  Now
    each body is placed whole about its centre of mass and free atoms are not touched.
    Measured centre-of-mass shifts 1.2e-15 Å; bound 1e-9 Å."""
    box = water_box(3, seed=0)
    atoms = box + Atoms("H", positions=[[-1.0, -1.0, -1.0]])
    bodies = [list(range(3 * k, 3 * k + 3)) for k in range(27)]  # atom 81 free
    result = relax_bodies(atoms, Springs(), bodies=bodies, fmax=1e-4)
    out = result.atoms
    assert np.array_equal(out.positions[81], [-1.0, -1.0, -1.0])
    x = out.positions[:81].reshape(27, 3, 3)
    assert np.allclose([distances(body) for body in x], (0.9, 0.9, 1.5), atol=1e-4)
    masses = box.get_masses()[:3]
    old = box.positions.reshape(27, 3, 3)
    shift = np.einsum("k,nki->ni", masses, x - old) / masses.sum()
    assert np.abs(shift).max() < 1e-9


def test_isotopes_are_kinds_of_their_own():
    """Bodies were grouped by element only: with a D2O first, every H2O was placed by the
    D2O's masses and its centre of mass moved by up to 0.013 Å.  Measured now 5e-16 Å;
    bound 1e-9 Å."""
    atoms = water_box(2, seed=0)
    masses = atoms.get_masses()
    masses[1:3] = 2.014
    atoms.set_masses(masses)
    result = relax_bodies(atoms, Springs(), fmax=1e-6)
    heavy = "OHH[15.999, 2.014, 2.014]"
    assert result.bodies == {heavy: [0], "OHH": list(range(1, 8))}
    assert np.array_equal(result.templates[heavy].get_masses(), masses[:3])
    assert np.array_equal(result.templates["OHH"].get_masses(), masses[3:6])
    out = result.atoms
    assert np.array_equal(out.get_masses(), masses)
    whole = rigidmd.RigidBodies.resolve(out).whole_positions(out).reshape(8, 3, 3)
    old = rigidmd.RigidBodies.resolve(atoms).whole_positions(atoms).reshape(8, 3, 3)
    m = masses.reshape(8, 3)
    shift = np.einsum("nk,nki->ni", m, whole - old) / m.sum(axis=1)[:, None]
    assert np.abs(shift).max() < 1e-9
