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

from rigidmd.core import quaternion as quat
from rigidmd.water import real_argument, water_model, whole_argument

__all__ = ["water_molecule", "co2_molecule", "water_cluster", "water_box",
           "co2_water_mixture", "random_quaternions", "ice_ih"]

#: C=O bond length of the TraPPE CO2 model (Å).
R_CO = 1.16


def water_molecule(model="tip3p"):
    """One water of ``model`` (a :data:`rigidmd.water.WATER_MODELS` name or a
    :class:`~rigidmd.water.WaterModel`), oxygen at the origin.

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
    model : str or rigidmd.water.WaterModel, default "tip3p"
        Water model (a :data:`rigidmd.water.WATER_MODELS` name or the model);
        orientations are chosen by the TIP3P energy of the O, H, H sites
        whatever the model.

    Raises
    ------
    TypeError, ValueError
        ``n_molecules`` or ``tries`` not a whole number >= 1, ``spacing`` not
        positive and finite, ``jitter`` negative, an unknown ``model``.
    """
    n_molecules = whole_argument("water_cluster", "n_molecules", n_molecules, 1)
    tries = whole_argument("water_cluster", "tries", tries, 1)
    spacing = real_argument("water_cluster", "spacing", spacing, unit=" Å")
    jitter = real_argument("water_cluster", "jitter", jitter, strict=False, unit=" Å")
    template = water_molecule(model)
    rng = np.random.default_rng(seed)
    n_side = int(np.ceil(n_molecules ** (1 / 3)))
    sites = _lattice(n_side, spacing)
    centre = sites.mean(axis=0)
    sites = sites[np.argsort(np.linalg.norm(sites - centre, axis=1), kind="stable")]
    sites = sites[:n_molecules] + rng.uniform(-jitter, jitter, (n_molecules, 3))
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


def water_box(n_side=3, seed=0, spacing=3.1, jitter=0.1, model="tip3p", whole=True):
    """A periodic cubic box of ``n_side**3`` randomly oriented waters.

    About liquid density at the default spacing (1.0 g/cm³ at 3.1 Å).  The
    lattice starts at the cell's origin (each site jittered by up to
    ``jitter`` Å).  Every molecule is whole, its atoms up to one molecule's
    size outside the cell: calculators that take intramolecular distances
    without the minimum image need it (ASE's ``TIP3P`` and ``TIP4P``, OpenMM's
    constraints and virtual sites), and every other reads it as well.  With
    ``whole=False`` every atom is wrapped into the cell, so molecules straddle
    the boundaries: ASE's ``TIP3P`` then counts the split molecules' charges
    across the box (+192 eV for ``water_box(4)`` with ``rc=6``, against
    +0.70 eV whole).  ``model`` names the water model
    (a :data:`rigidmd.water.WATER_MODELS` name or a
    :class:`~rigidmd.water.WaterModel`; four-site models carry M explicitly).

    Raises
    ------
    TypeError, ValueError
        ``n_side`` not a whole number >= 1, ``spacing`` not positive and
        finite, ``jitter`` negative, an unknown ``model``.
    """
    n_side = whole_argument("water_box", "n_side", n_side, 1)
    spacing = real_argument("water_box", "spacing", spacing, unit=" Å")
    jitter = real_argument("water_box", "jitter", jitter, strict=False, unit=" Å")
    molecule = water_molecule(model)
    rng = np.random.default_rng(seed)
    n = n_side**3
    sites = _lattice(n_side, spacing) + rng.uniform(-jitter, jitter, (n, 3))
    atoms = _place([molecule] * n, sites, rng)
    atoms.cell = np.eye(3) * n_side * spacing
    atoms.pbc = True
    if not whole:
        atoms.wrap()
    return atoms


def co2_water_mixture(n_co2=4, n_water=4, seed=0, spacing=3.6, box=None):
    """Linear CO2 and water molecules mixed on a lattice.

    Parameters
    ----------
    n_co2, n_water : int
        Molecules of each kind, whole numbers >= 0, at least one in all.
    seed : int
    spacing : float
        Lattice spacing (Å).
    box : bool, optional
        If true, a periodic cubic cell of the lattice's size, atoms wrapped.

    Raises
    ------
    TypeError, ValueError
        ``n_co2`` or ``n_water`` not a whole number >= 0, or both 0;
        ``spacing`` not positive and finite.
    """
    n_co2 = whole_argument("co2_water_mixture", "n_co2", n_co2, 0)
    n_water = whole_argument("co2_water_mixture", "n_water", n_water, 0)
    if n_co2 + n_water == 0:
        raise ValueError("co2_water_mixture: n_co2 + n_water must be at least 1, got 0 and 0")
    spacing = real_argument("co2_water_mixture", "spacing", spacing, unit=" Å")
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


def _ice_oxygens(repeat, a, c):
    """Oxygens of hexagonal ice (the wurtzite lattice, u = 3/8) in an orthorhombic cell."""
    from ase.build import bulk

    lattice = bulk("OO", "wurtzite", a=a, c=c, u=0.375, orthorhombic=True)
    return lattice.repeat(repeat)


def _hydrogen_bonds(oxygens, distance):
    """Each oxygen's four neighbours: the bonds (i, j) with i < j and their vectors i -> j."""
    from ase.neighborlist import neighbor_list

    # The next shell of the wurtzite lattice is 1.63 times as far as the first.
    n = len(oxygens)
    i, j, d = neighbor_list("ijD", oxygens, 1.3 * distance)
    keep = i < j
    i, j, d = i[keep], j[keep], d[keep]
    counts = np.bincount(np.concatenate([i, j]), minlength=n)
    # In a cell one lattice cell thick, two bonds join one pair of oxygens (two images).
    pairs = np.unique(i * n + j)
    distinct = np.bincount(np.concatenate([pairs // n, pairs % n]), minlength=n)
    if np.any(counts != 4) or np.any(distinct != 4):
        raise ValueError("ice_ih: the cell is too small for four distinct neighbours per "
                         "oxygen; repeat it more")
    return i, j, d


def _out_degree(donor, n):
    return np.bincount(donor, minlength=n)


def ice_ih(repeat=(3, 2, 2), seed=0, a=4.50, c=7.33, model="tip4p2005", sweeps=20):
    r"""Proton-disordered hexagonal ice Ih with zero net dipole, in an orthorhombic cell.

    Oxygens sit on the wurtzite lattice (8 per orthorhombic cell of
    :math:`a \times \sqrt3 a \times c`, repeated ``repeat`` times).  Every
    hydrogen bond gets a direction (which oxygen donates) obeying the
    Bernal–Fowler ice rules, two donated and two accepted bonds per oxygen
    (J. D. Bernal and R. H. Fowler, J. Chem. Phys. 1, 515 (1933)): random
    directions first, then each defect (an oxygen donating more than two) is
    walked off along its bonds, reversing them, until it meets its opposite
    (Rick and Haymet's defect annihilation).  Closed loops of bonds, each
    reversed as a whole (which keeps the ice rules), then disorder the
    protons further and bring the net dipole, the sum of the donated bond
    vectors, to zero: a loop is kept when it does not raise the dipole's
    length (loops that wind around the periodic cell change the dipole,
    local ones do not).  Each molecule of ``model`` is then placed with its
    oxygen on the site, its bisector along the sum of its two donated bond
    directions and its hydrogens in their plane (the model's angle, not the
    tetrahedral one).

    Parameters
    ----------
    repeat : tuple of int, or int
        Orthorhombic cells along x, y, z (8 molecules each), whole numbers
        >= 1; one number repeats alike along all three.  One repeat along x
        (4.5 Å at the default ``a``) gives oxygens two bonds to one neighbour
        (two of its images), and is refused.
    seed : int
    a, c : float
        Hexagonal lattice constants (Å); the oxygen-oxygen distance is
        :math:`3c/8`.
    model : str
        Water model of :mod:`rigidmd.water` (four-site models carry M).
    sweeps : int
        Loop moves per bond, at least, while disordering.

    Returns
    -------
    ase.Atoms
        Periodic, molecules O, H, H (, M) with ``mol-id``.

    Raises
    ------
    TypeError, ValueError
        A ``repeat`` that is not three whole numbers >= 1, ``a`` or ``c`` not
        positive and finite, an unknown ``model``, a cell too small for four
        distinct neighbours per oxygen, or a dipole that the loop moves did
        not bring to zero.
    """
    counts = np.ravel(np.array(repeat, dtype=object))
    if counts.size == 1:
        counts = np.repeat(counts, 3)
    if counts.size != 3:
        raise ValueError(f"ice_ih: repeat must be three whole numbers >= 1 (or one), "
                         f"got {repeat!r}")
    repeat = tuple(whole_argument("ice_ih", "repeat", r, 1) for r in counts)
    a = real_argument("ice_ih", "a", a, unit=" Å")
    c = real_argument("ice_ih", "c", c, unit=" Å")
    water = water_model(model)
    rng = np.random.default_rng(seed)
    oxygens = _ice_oxygens(repeat, a, c)
    n = len(oxygens)
    i, j, vectors = _hydrogen_bonds(oxygens, 3 * c / 8)
    bonds = np.stack([i, j], axis=1)
    flip = rng.random(len(bonds)) < 0.5
    donor = np.where(flip, j, i)
    acceptor = np.where(flip, i, j)
    # Bonds of each oxygen, for the walks.
    incident = [[] for _ in range(n)]
    for b, (p, q) in enumerate(bonds):
        incident[p].append(b)
        incident[q].append(b)
    incident = np.array(incident)
    # Defect annihilation: walk from an oxygen donating more than two.
    out = _out_degree(donor, n)
    while np.any(out > 2):
        v = int(np.flatnonzero(out > 2)[0])
        while out[v] > 2:
            mine = incident[v][donor[incident[v]] == v]
            b = int(rng.choice(mine))
            w = int(acceptor[b])
            donor[b], acceptor[b] = w, v
            out[v] -= 1
            out[w] += 1
            v = w
    sign = np.where(donor == i, 1.0, -1.0)
    dipole = (sign[:, None] * vectors).sum(axis=0)
    scale = np.linalg.norm(vectors, axis=1).mean()
    moves = 0
    while moves < sweeps * len(bonds) or np.linalg.norm(dipole) > 1e-6 * scale:
        moves += 1
        if moves > 1000 * len(bonds):
            raise ValueError(f"ice_ih: no zero-dipole proton arrangement found in {moves} loop "
                             f"moves (dipole {np.linalg.norm(dipole) / scale:.2f} bonds); try "
                             "another seed or a larger repeat")
        # A directed loop: follow donated bonds until an oxygen repeats.
        start = int(rng.integers(n))
        seen = {start: 0}
        path = []
        v = start
        while True:
            mine = incident[v][donor[incident[v]] == v]
            b = int(rng.choice(mine))
            path.append(b)
            v = int(acceptor[b])
            if v in seen:
                loop = np.array(path[seen[v]:])
                break
            seen[v] = len(path)
        change = -2.0 * (sign[loop, None] * vectors[loop]).sum(axis=0)
        if np.linalg.norm(dipole + change) <= np.linalg.norm(dipole) + 1e-9 * scale:
            donor[loop], acceptor[loop] = acceptor[loop], donor[loop]
            sign[loop] *= -1.0
            dipole = dipole + change
    # Molecules: each oxygen's two donated bond directions.
    unit = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    directions = sign[:, None] * unit  # from donor to acceptor
    order = np.argsort(donor, kind="stable")
    pairs = directions[order].reshape(n, 2, 3)
    bisector = pairs.sum(axis=1)
    bisector /= np.linalg.norm(bisector, axis=1, keepdims=True)
    across = pairs[:, 0] - pairs[:, 1]
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    half = np.radians(water.angle_hoh) / 2
    o = oxygens.positions
    h1 = o + water.r_oh * (np.cos(half) * bisector + np.sin(half) * across)
    h2 = o + water.r_oh * (np.cos(half) * bisector - np.sin(half) * across)
    sites = [o, h1, h2] + ([o + water.d_om * bisector] if water.sites == 4 else [])
    atoms = Atoms(water.symbols * n, positions=np.stack(sites, axis=1).reshape(-1, 3),
                  cell=oxygens.cell, pbc=True)
    atoms.set_masses(np.tile(water.masses(), n))
    atoms.arrays["mol-id"] = np.repeat(np.arange(1, n + 1), water.sites)
    atoms.wrap()
    return atoms
