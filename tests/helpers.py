"""Systems, reference calculators and LAMMPS command sets shared by the tests.

Test modules import their builders from here (never from each other), so
every system used in two places is built in one place.
"""

import numpy as np
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P

from rigidmd import rigid_maxwell_boltzmann
from rigidmd.systems import co2_water_mixture, water_cluster

# Coulomb constant in eV Å / e².
KE = units.Hartree * units.Bohr

# TraPPE CO2 (C: 0.70 e, 2.80 Å, 27.0 K; O: -0.35 e, 3.05 Å, 79.0 K), TIP3P water,
# a neon-like neutral point particle and two ions.  (charge e, sigma Å, epsilon eV)
PARAMETERS = {
    "C": (0.70, 2.80, 27.0 * units.kB),
    "O_co2": (-0.35, 3.05, 79.0 * units.kB),
    "O_water": (-0.834, 3.15061, 0.1521 * units.kcal / units.mol),
    "H": (0.417, 1.0, 0.0),
    "Ne": (0.0, 2.78, 36.0 * units.kB),
    # Monovalent ions (roughly Joung-Cheatham sizes) as charged point particles.
    "Na": (1.0, 2.4, 0.1 * units.kcal / units.mol),
    "Cl": (-1.0, 4.4, 0.1 * units.kcal / units.mol),
}


def site_labels(atoms):
    """Force-field label of every atom (O of CO2 told from O of water by its molecule)."""
    mol = atoms.arrays.get("mol-id", np.arange(len(atoms)))
    labels = []
    for i, s in enumerate(atoms.get_chemical_symbols()):
        if s == "O":
            partners = set(np.array(atoms.get_chemical_symbols())[mol == mol[i]])
            labels.append("O_co2" if "C" in partners else "O_water")
        else:
            labels.append(s)
    return labels


class CoulombLJ(Calculator):
    """Charges plus Lennard-Jones between atoms of different molecules, no cutoff.

    O(N²) NumPy, for clusters (no periodicity).  Lorentz–Berthelot mixing.
    Molecules come from the ``mol-id`` array; atoms without one interact
    with everything.  Pairwise central forces, so it conserves linear and
    angular momentum exactly.
    """

    implemented_properties = ["energy", "forces"]

    def __init__(self, wall=None):
        """``wall=(centre, radius)``: a harmonic spherical wall (1 eV/Å² beyond ``radius`` Å)
        on every atom, keeping a droplet from evaporating in long runs."""
        super().__init__()
        self.wall = wall

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        atoms = self.atoms
        labels = site_labels(atoms)
        q, s, e = (np.array([PARAMETERS[lab][k] for lab in labels]) for k in range(3))
        mol = atoms.arrays.get("mol-id", np.arange(len(atoms)) + 10**6)
        x = atoms.positions
        d = x[:, None, :] - x[None, :, :]
        r2 = np.einsum("ijk,ijk->ij", d, d)
        mask = mol[:, None] != mol[None, :]
        r2 = np.where(mask, r2, 1.0)
        sig = 0.5 * (s[:, None] + s[None, :])
        eps = np.sqrt(e[:, None] * e[None, :])
        sr6 = (sig**2 / r2) ** 3
        r = np.sqrt(r2)
        energy_pair = 4 * eps * (sr6**2 - sr6) + KE * q[:, None] * q[None, :] / r
        # -dE/dr / r
        fr = (24 * eps * (2 * sr6**2 - sr6) / r2) + KE * q[:, None] * q[None, :] / (r2 * r)
        energy_pair = np.where(mask, energy_pair, 0.0)
        fr = np.where(mask, fr, 0.0)
        self.results["energy"] = 0.5 * energy_pair.sum()
        self.results["forces"] = np.einsum("ij,ijk->ik", fr, d)
        if self.wall is not None:
            centre, radius = self.wall
            out = x - centre
            dist = np.linalg.norm(out, axis=1)
            excess = np.maximum(dist - radius, 0.0)
            self.results["energy"] += 0.5 * np.sum(excess**2)
            self.results["forces"] -= (excess / np.where(dist > 0, dist, 1.0))[:, None] * out


def coulomb_lj_lammps(atoms, cutoff=60.0):
    """LAMMPS commands, charges and type labels that reproduce :class:`CoulombLJ`.

    ``lj/cut/coul/cut`` with a cut-off beyond the cluster, Lorentz–Berthelot
    mixing and intramolecular pairs excluded (molecules are the bodies).
    """
    labels = site_labels(atoms)
    charges = np.array([PARAMETERS[lab][0] for lab in labels])
    cmds = [f"pair_style lj/cut/coul/cut {cutoff}", "pair_modify mix arithmetic"]
    for lab in sorted(set(labels)):
        _, sigma, epsilon = PARAMETERS[lab]
        cmds.append(f"pair_coeff {lab} {lab} {epsilon!r} {sigma!r}")
    cmds.append("neigh_modify exclude molecule/intra all")
    return cmds, charges, labels


class ZeroForce(Calculator):
    """No interactions: zero energy and forces (a free rigid body)."""

    implemented_properties = ["energy", "forces"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.results = {"energy": 0.0, "forces": np.zeros((len(self.atoms), 3))}


def waters(n=8, seed=1, temperature_K=250):
    """A TIP3P water cluster (``TIP3P(rc=40)``) with rigid velocities at ``temperature_K``."""
    atoms = water_cluster(n, seed=seed)
    atoms.calc = TIP3P(rc=40)
    rigid_maxwell_boltzmann(atoms, temperature_K, rng=np.random.default_rng(seed))
    return atoms


def mixture(seed=3):
    """4 CO2 (linear), 4 waters and 2 neon atoms (point particles), CoulombLJ, 250 K."""
    atoms = co2_water_mixture(4, 4, seed=seed)
    ne = Atoms("Ne2", positions=[[-3.5, 0.5, 0.3], [1.0, -3.6, 2.0]])
    ne.arrays["mol-id"] = np.array([100, 101])
    atoms += ne
    atoms.calc = CoulombLJ()
    rigid_maxwell_boltzmann(atoms, 250, bodies="mol-id", rng=np.random.default_rng(seed))
    return atoms


def total_momenta(atoms):
    """Total linear momentum and angular momentum about the origin of the atoms."""
    p = atoms.get_momenta()
    return p.sum(axis=0), np.cross(atoms.positions, p).sum(axis=0)
