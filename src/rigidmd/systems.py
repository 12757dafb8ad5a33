r"""Small molecular systems for examples, tests and the demo.

Every builder is deterministic for a given ``seed`` and returns an
:class:`ase.Atoms` whose molecules are contiguous (water as O, H, H, as
ASE's :class:`~ase.calculators.tip3p.TIP3P` expects, or O, H, H, M for a
four-site model of :mod:`rigidmd.water`, M massless) with a ``mol-id`` array
(1-based, one per molecule) as ASE's LAMMPS data reader would give.
"""

import numpy as np
from ase import Atoms, units
from ase.calculators.tip3p import epsilon0, qH, sigma0

from rigidmd import quaternion as quat
from rigidmd.water import water_model

__all__ = ["water_molecule", "co2_molecule", "water_cluster", "water_box",
           "co2_water_mixture", "random_quaternions"]

#: C=O bond length of the TraPPE CO2 model (Å).
R_CO = 1.16


def water_molecule(model="tip3p"):
    """One water of ``model`` (:data:`rigidmd.water.WATER_MODELS`), oxygen at the origin.

    O, H, H (, M) in the xy plane; see :meth:`rigidmd.water.WaterModel.molecule`.
    """
    return water_model(model).molecule()


def co2_molecule():
    """One linear CO2 (C, O, O) along x, carbon at the origin (C=O 1.16 Å)."""
    return Atoms("CO2", positions=[[0.0, 0, 0], [R_CO, 0, 0], [-R_CO, 0, 0]])


def random_quaternions(n, rng):
    """``n`` uniformly distributed unit quaternions (Shoemake's method), shape (n, 4)."""
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    return np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                     b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)], axis=1)


def _place(molecules, centres, rng):
    """Copies of template molecules, randomly rotated about their centres of mass."""
    q = random_quaternions(len(centres), rng)
    symbols, positions, masses, mol_id = [], [], [], []
    for k, (mol, centre) in enumerate(zip(molecules, centres, strict=True)):
        local = mol.positions - mol.get_center_of_mass()
        positions.append(centre + quat.rotate(q[k], local))
        symbols += mol.get_chemical_symbols()
        masses.append(mol.get_masses())
        mol_id += [k + 1] * len(mol)
    atoms = Atoms(symbols, positions=np.concatenate(positions))
    if any(mol.has("masses") for mol in molecules):
        atoms.set_masses(np.concatenate(masses))
    atoms.arrays["mol-id"] = np.array(mol_id)
    return atoms


def _lattice(n_side, spacing):
    g = np.arange(n_side) * spacing
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)


def _tip3p_pair_energy(a, b):
    """TIP3P energy (eV) of candidate waters ``a`` (k, 3, 3) with waters ``b`` (m, 3)."""
    charges = np.array([-2 * qH, qH, qH])
    d = np.linalg.norm(a[:, :, None, :] - b[None, None, :, :], axis=-1)  # (k, 3, m)
    qb = np.tile(charges, len(b) // 3)
    coulomb = (units.Hartree * units.Bohr) * np.einsum("i,kij,j->k", charges, 1 / d, qb)
    r_oo = d[:, 0, 0::3]
    lj = 4 * epsilon0 * ((sigma0 / r_oo) ** 12 - (sigma0 / r_oo) ** 6)
    return coulomb + lj.sum(axis=1)


def water_cluster(n_molecules, seed=0, spacing=3.1, jitter=0.1, tries=64, model="tip3p"):
    """A compact cluster of waters, no periodicity.

    The molecules sit on the simple-cubic lattice sites (``spacing`` Å) closest
    to the lattice centre, displaced by up to ``jitter`` Å.  Each is given, in
    turn, the best of ``tries`` random orientations (lowest TIP3P energy with
    the molecules placed before it), which builds a hydrogen-bonded start
    instead of one that heats by hundreds of kelvin in the first picosecond.

    Parameters
    ----------
    n_molecules : int
    seed : int
    spacing, jitter : float
        Å.
    tries : int
        Orientations tried per molecule; 1 gives uniformly random orientations.
    model : str, default "tip3p"
        Water model (:data:`rigidmd.water.WATER_MODELS`); orientations are
        chosen by the TIP3P energy of the O, H, H sites whatever the model.
    """
    rng = np.random.default_rng(seed)
    n_side = int(np.ceil(n_molecules ** (1 / 3)))
    sites = _lattice(n_side, spacing)
    centre = sites.mean(axis=0)
    sites = sites[np.argsort(np.linalg.norm(sites - centre, axis=1), kind="stable")]
    sites = sites[:n_molecules] + rng.uniform(-jitter, jitter, (n_molecules, 3))
    template = water_molecule(model)
    k = len(template)
    local = template.positions - template.get_center_of_mass()
    placed = np.zeros((0, k, 3))
    for site in sites:
        q = random_quaternions(tries, rng)
        candidates = site + quat.rotate(q[:, None, :], local[None, :, :])
        best = 0 if len(placed) == 0 else int(np.argmin(_tip3p_pair_energy(
            candidates[:, :3], placed[:, :3].reshape(-1, 3))))
        placed = np.concatenate([placed, candidates[best][None]])
    atoms = Atoms(template.get_chemical_symbols() * n_molecules, positions=placed.reshape(-1, 3))
    if template.has("masses"):
        atoms.set_masses(np.tile(template.get_masses(), n_molecules))
    atoms.arrays["mol-id"] = np.repeat(np.arange(1, n_molecules + 1), k)
    return atoms


def water_box(n_side=3, seed=0, spacing=3.1, jitter=0.1, model="tip3p"):
    """A periodic cubic box of ``n_side**3`` randomly oriented waters.

    About liquid density at the default spacing (1.0 g/cm³ at 3.1 Å).  The
    lattice is offset by half a spacing and every atom wrapped into the cell,
    so molecules straddle the boundaries.  ``model`` names the water model
    (:data:`rigidmd.water.WATER_MODELS`; four-site models carry M explicitly).
    """
    rng = np.random.default_rng(seed)
    n = n_side**3
    sites = _lattice(n_side, spacing) + rng.uniform(-jitter, jitter, (n, 3))
    atoms = _place([water_molecule(model)] * n, sites, rng)
    atoms.cell = np.eye(3) * n_side * spacing
    atoms.pbc = True
    atoms.wrap()
    return atoms


def co2_water_mixture(n_co2=4, n_water=4, seed=0, spacing=3.6, box=None):
    """Linear CO2 and water molecules mixed on a lattice.

    Parameters
    ----------
    n_co2, n_water : int
    seed : int
    spacing : float
        Lattice spacing (Å).
    box : bool, optional
        If true, a periodic cubic cell of the lattice's size, atoms wrapped.
    """
    rng = np.random.default_rng(seed)
    n = n_co2 + n_water
    n_side = int(np.ceil(n ** (1 / 3)))
    sites = _lattice(n_side, spacing)[:n] + rng.uniform(-0.1, 0.1, (n, 3))
    kinds = [co2_molecule()] * n_co2 + [water_molecule()] * n_water
    kinds = [kinds[i] for i in rng.permutation(n)]
    atoms = _place(kinds, sites, rng)
    if box:
        atoms.cell = np.eye(3) * n_side * spacing
        atoms.pbc = True
        atoms.wrap()
    return atoms
