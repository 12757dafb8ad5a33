r"""Rigid bodies in the geometry the calculator prefers.

A rigid body keeps the internal geometry it starts with.  A water built with
the TIP3P geometry (0.9572 Å, 104.52°) and run with GFN2-xTB or a
machine-learned potential is strained: its atoms feel internal forces that a
rigid body never relaxes, and its dipole is the model's, not the
calculator's.  :func:`relax_bodies` relaxes one isolated molecule of every
kind with the calculator and gives every body of that kind the relaxed
geometry, each superposed on the body as it was (same centre of mass, best
fit orientation), so the start is the calculator's own rigid molecule.
"""

from dataclasses import dataclass, field

import numpy as np
from ase import Atoms
from ase.optimize import BFGS

from rigidmd.core.bodies import RigidBodies
from rigidmd.core.model import describe_atoms

__all__ = ["relax_bodies", "BodyRelaxation"]


@dataclass
class BodyRelaxation:
    """What :func:`relax_bodies` did (:func:`~rigidmd.relax.filter.relax` returns another
    class, :class:`rigidmd.relax.filter.Relaxation`).

    Attributes
    ----------
    atoms : ase.Atoms
        A copy of the input with every body in its kind's relaxed geometry
        (no momenta, no calculator).
    templates : dict
        Relaxed isolated molecule (:class:`ase.Atoms`) per kind, keyed by
        the kind's chemical symbols in atom order (``"OHH"`` for water),
        followed by its masses in brackets where they are not ASE's defaults
        (``"OHH[15.999, 2.014, 2.014]"`` for D2O).
    strain_energies : dict
        Per kind: energy of the isolated molecule as given minus relaxed (eV),
        what each rigid body of that kind would have carried.
    bodies : dict
        Per kind: the body indices that got its geometry.
    """

    atoms: Atoms
    templates: dict = field(default_factory=dict)
    strain_energies: dict = field(default_factory=dict)
    bodies: dict = field(default_factory=dict)



def _kabsch(reference, target, weights):
    r"""Rotations :math:`R` minimising :math:`\sum_i w_i |R a_i - b_i|^2` for centred sets.

    Parameters
    ----------
    reference, target : numpy.ndarray, shape (n, k, 3)
        ``n`` pairs of centred point sets.
    weights : numpy.ndarray, shape (k,)

    Returns
    -------
    numpy.ndarray, shape (n, 3, 3)
        Proper rotations (det +1).
    """
    h = np.einsum("k,nki,nkj->nij", weights, reference, target)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("nij,njk->nik", u, vt)))
    fix = np.ones((len(h), 3))
    fix[:, 2] = d
    return np.einsum("nji,nj,nkj->nik", vt, fix, u)


def relax_bodies(atoms, calculator, bodies=None, *, fmax=1e-3, steps=500, optimizer=BFGS):
    """Give every body the geometry ``calculator`` relaxes its molecule to.

    Bodies are grouped into kinds by their atoms' chemical symbols and
    masses in order (every water O, H, H is one kind; a D2O, its hydrogens
    given 2.014 amu, another).  One body of each kind is cut out,
    made whole, relaxed in vacuum with ``calculator`` (``optimizer`` to
    ``fmax``), and the relaxed molecule is superposed on every body of that
    kind: its centre of mass where the body's was, rotated to the best fit
    of the body's atoms (mass-weighted).  Each body comes back whole, about
    its centre of mass as :meth:`~rigidmd.RigidBodies.whole_positions` places
    it (its first atom's side of a periodic boundary); nothing is wrapped
    into the cell, and free atoms are left where they are.

    Parameters
    ----------
    atoms : ase.Atoms
    calculator : ase.calculators.calculator.Calculator
        Used on the isolated molecules only (one at a time; it is the
        caller's to attach to the system afterwards).
    bodies : optional
        Body specification, as for :class:`~rigidmd.RigidVerlet`.
    fmax : float, default 1e-3
        Largest force left on a relaxed atom (eV/Å).
    steps : int, default 500
        Optimizer steps allowed per kind.
    optimizer : ase.optimize.Optimizer subclass, default BFGS

    Returns
    -------
    BodyRelaxation
        The new atoms and, per kind, the relaxed molecule and its strain
        energy.

    Raises
    ------
    ValueError
        A body with a massless atom (a virtual site is a force-field
        construct; no electronic-structure calculator places one), or a
        relaxation that does not reach ``fmax`` in ``steps`` (naming the
        kind).
    """
    rigid = RigidBodies.resolve(atoms, bodies)
    geometry = rigid.geometry(atoms)
    model = geometry.model
    massless = model.order[model.atom_masses == 0]
    if massless.size:
        raise ValueError(f"relax_bodies: atom {int(massless[0])} is massless (a virtual "
                         "site); relax the molecule without it and place the site by its "
                         "model's rule")
    whole = rigid.whole_positions(atoms)
    numbers = atoms.numbers
    masses = atoms.get_masses()
    out = atoms.copy()
    out.calc = None
    if "momenta" in out.arrays:
        del out.arrays["momenta"]
    result = BodyRelaxation(out)
    kinds = {}
    for b in range(model.n_bodies):
        index = model.atoms_of(b)
        kinds.setdefault((tuple(numbers[index]), tuple(masses[index])), []).append(b)
    positions = out.positions
    for (symbols, kind_masses), members in kinds.items():
        first = model.atoms_of(members[0])
        molecule = Atoms(numbers=list(symbols), positions=whole[first],
                         masses=list(kind_masses))
        name = molecule.get_chemical_formula(mode="all")
        if not np.array_equal(molecule.get_masses(), Atoms(numbers=list(symbols)).get_masses()):
            name += f"[{', '.join(repr(float(m)) for m in kind_masses)}]"
        molecule.calc = calculator
        before = molecule.get_potential_energy()
        opt = optimizer(molecule, logfile=None)
        if not opt.run(fmax=fmax, steps=steps):
            raise ValueError(f"relax_bodies: {name} (body {members[0]}, atoms "
                             f"{describe_atoms(first)}) did not relax to fmax={fmax:g} eV/Å "
                             f"in {steps} steps")
        result.strain_energies[name] = float(before - molecule.get_potential_energy())
        molecule.calc = None
        result.templates[name] = molecule
        result.bodies[name] = list(members)
        # Superpose the relaxed molecule on every body of this kind at once.
        index = np.array([model.atoms_of(b) for b in members])  # (n, k)
        weights = molecule.get_masses()
        template = molecule.positions - molecule.get_center_of_mass()
        target = whole[index]
        com = np.einsum("k,nki->ni", weights, target) / weights.sum()
        rotation = _kabsch(np.broadcast_to(template, target.shape), target - com[:, None],
                           weights)
        positions[index] = com[:, None] + np.einsum("nij,kj->nki", rotation, template)
    out.positions = positions
    return result
