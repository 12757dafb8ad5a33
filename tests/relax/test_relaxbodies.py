"""Each kind of molecule in the geometry a calculator prefers (rigidmd.relax.relaxbodies).

A flexible stand-in with a known minimum: harmonic springs between every pair of atoms of
a molecule, O–H at 0.9 Å and H–H at 1.5 Å (a triangle, so all springs are relaxed at
once).  GFN2-xTB's geometry is checked in ``tests/physics/test_tight_binding.py``."""


import numpy as np
import pytest
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
    # Each body's centre of mass stays where it was (up to a whole box: out is wrapped).
    masses = atoms.get_masses()[:3]
    old = rigidmd.RigidBodies.resolve(atoms).whole_positions(atoms).reshape(8, 3, 3)
    shift = np.einsum("k,nki->ni", masses, whole - old) / masses.sum()
    box = np.diag(atoms.cell)
    assert np.allclose(shift - box * np.round(shift / box), 0.0, atol=1e-9)


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
