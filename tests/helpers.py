"""Systems, reference calculators and LAMMPS command sets shared by the tests.

Test modules import their builders from here (never from each other), so
every system used in two places is built in one place.
"""

import functools
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P, rOH
from ase.io import write

from rigidmd import rigid_maxwell_boltzmann
from rigidmd.lammps import _numpy as lammps_numpy
from rigidmd.lammps import tip3p_charges
from rigidmd.run import cli
from rigidmd.systems import co2_water_mixture, water_box, water_cluster

#: The tests' data files.
DATA = Path(__file__).with_name("data")
#: TIP3P with PPPM for the stored 27-water box (:func:`water_box_27`), as LAMMPS commands.
PPPM_27 = ["pair_style lj/cut/coul/long 4.5", "pair_coeff * * 0.0 1.0",
           "pair_coeff O O 0.0065956819 3.15061", "kspace_style pppm 1e-5"]

#: A ``rigidmd run``/``rigidmd relax`` configuration with a ``relax:`` section (STEPS: its
#: steps): 6 waters of a cluster, TIP3P, 20 MD steps after the relaxation.
RELAX_CONFIG = """
structure: {builtin: water_cluster, n_molecules: 6, seed: 2}
calculator: {name: tip3p, options: {rc: 40.0}}
velocities: {temperature: 50 K, seed: 1}
timestep: 1 fs
steps: 20
outputs: {directory: out, trajectory: md.traj, log: md.log, interval: 10}
relax: {fmax: 0.01, steps: STEPS, optimizer: FIRE}
"""


def tip3p_calls(monkeypatch):
    """Count every evaluation of ASE's TIP3P (any instance: one a configuration builds too).

    Returns the list that grows by one item per evaluation (``len`` is the count; ``clear``
    starts again).
    """
    calls, original = [], TIP3P.calculate

    def calculate(self, *args, **kwargs):
        calls.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(TIP3P, "calculate", calculate)
    return calls


def water_box_27(temperature_K=None):
    """The stored periodic box of 27 waters (``data/water_box_27.traj``), TIP3P charges.

    With ``temperature_K`` the molecules are made whole and given rigid
    velocities drawn at that temperature (a fixed seed).
    """
    from ase.io import read

    from rigidmd import RigidBodies
    from rigidmd.water import tip3p_charges

    atoms = read(DATA / "water_box_27.traj")
    atoms.set_initial_charges(tip3p_charges(atoms))
    if temperature_K is not None:
        atoms.positions = RigidBodies.resolve(atoms, "tags").whole_positions(atoms)
        rigid_maxwell_boltzmann(atoms, temperature_K, bodies="tags",
                                rng=np.random.default_rng(3))
    return atoms


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

    def __init__(self, wall=None, parameters=None):
        """``wall=(centre, radius)``: a harmonic spherical wall (1 eV/Å² beyond ``radius`` Å)
        on every atom, keeping a droplet from evaporating in long runs.  ``parameters``:
        (charge, sigma, epsilon) per label (:func:`site_labels`), default ``PARAMETERS``."""
        super().__init__()
        self.wall = wall
        self.parameters = PARAMETERS if parameters is None else parameters

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        atoms = self.atoms
        labels = site_labels(atoms)
        q, s, e = (np.array([self.parameters[lab][k] for lab in labels]) for k in range(3))
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


def water_parameters(model):
    """:class:`CoulombLJ` parameters of a water model of :mod:`rigidmd.water` (M labelled X)."""
    on_m = model.sites == 4  # the negative charge sits on M, else on O
    return {"O_water": (0.0 if on_m else -2 * model.q_h, model.sigma, model.epsilon),
            "H": (model.q_h, 1.0, 0.0), "X": (-2 * model.q_h if on_m else 0.0, 1.0, 0.0)}


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


class ZeroStress(Calculator):
    """No interactions, with stress: an ideal gas of rigid bodies (nothing resists a cell
    shrinking under pressure)."""

    implemented_properties = ["energy", "forces", "stress"]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.results = {"energy": 0.0, "forces": np.zeros((len(self.atoms), 3)),
                        "stress": np.zeros(6)}


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


@numba.njit(cache=True)
def _lj_pairs(positions, tags, cell, inverse, sigma, epsilon, rc):
    """Shifted-force LJ energy, forces and virial over minimum-image pairs (compiled)."""
    n = positions.shape[0]
    forces = np.zeros((n, 3))
    virial = np.zeros((3, 3))
    energy = 0.0
    src6 = (sigma / rc) ** 6
    force_rc = 24.0 * epsilon * (2.0 * src6 * src6 - src6) / rc
    energy_rc = 4.0 * epsilon * (src6 * src6 - src6)
    d = np.empty(3)
    for i in range(n - 1):
        for j in range(i + 1, n):
            if tags[i] == tags[j] and tags[i] > 0:
                continue
            for k in range(3):
                d[k] = positions[i, k] - positions[j, k]
            s0 = d[0] * inverse[0, 0] + d[1] * inverse[1, 0] + d[2] * inverse[2, 0]
            s1 = d[0] * inverse[0, 1] + d[1] * inverse[1, 1] + d[2] * inverse[2, 1]
            s2 = d[0] * inverse[0, 2] + d[1] * inverse[1, 2] + d[2] * inverse[2, 2]
            s0 -= np.round(s0)
            s1 -= np.round(s1)
            s2 -= np.round(s2)
            for k in range(3):
                d[k] = s0 * cell[0, k] + s1 * cell[1, k] + s2 * cell[2, k]
            r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            if r2 >= rc * rc:
                continue
            r = np.sqrt(r2)
            sr6 = (sigma * sigma / r2) ** 3
            energy += 4.0 * epsilon * (sr6 * sr6 - sr6) - energy_rc + force_rc * (r - rc)
            fr = (24.0 * epsilon * (2.0 * sr6 * sr6 - sr6) / r - force_rc) / r
            for k in range(3):
                forces[i, k] += fr * d[k]
                forces[j, k] -= fr * d[k]
                for m in range(3):
                    virial[k, m] += d[k] * fr * d[m]
    return energy, forces, virial


class PeriodicLJ(Calculator):
    """Lennard-Jones between atoms of different molecules in a periodic cell, with stress.

    Shifted-force cut at ``rc`` (energy and force go to zero there, so the
    energy is smooth), minimum image in fractional coordinates: ``rc`` must be
    at most half the cell's smallest width.  Molecules come from the tags (as
    the bodies); atoms with tag 0 or below interact with everything.  An
    O(N²) compiled pair loop, for test systems of a few hundred atoms
    (128 atoms: about 0.05 ms per call).

    Parameters
    ----------
    sigma, epsilon : float
        Å and eV, one pair of values for every atom pair.
    rc : float
        Cut-off (Å).
    """

    implemented_properties = ["energy", "forces", "stress"]

    def __init__(self, sigma=3.3, epsilon=0.006, rc=7.0):
        super().__init__()
        self.sigma, self.epsilon, self.rc = sigma, epsilon, rc

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        atoms = self.atoms
        cell = atoms.cell.array
        widths = atoms.cell.volume / np.linalg.norm(np.cross(cell[[1, 2, 0]], cell[[2, 0, 1]]),
                                                    axis=1)
        if self.rc > 0.5 * widths.min():
            raise ValueError(f"PeriodicLJ: rc = {self.rc} Å exceeds half the cell's smallest "
                             f"width ({0.5 * widths.min():.3f} Å)")
        energy, forces, virial = _lj_pairs(atoms.positions, atoms.get_tags(), cell,
                                           np.linalg.inv(cell), self.sigma, self.epsilon,
                                           self.rc)
        self.results["energy"] = energy
        self.results["forces"] = forces
        stress = -virial / atoms.cell.volume
        self.results["stress"] = stress[[0, 1, 2, 1, 0, 0], [0, 1, 2, 2, 2, 1]]


def dimer_fluid(n_side=4, spacing=4.2, bond=1.1, seed=0, temperature_K=80, **lj):
    """A periodic liquid of rigid LJ dimers (N2-like, 28 amu), tags = molecules.

    ``n_side**3`` dimers on a simple cubic lattice (``spacing`` Å, about
    liquid-nitrogen density at 4.2 Å), random orientations, rigid velocities
    at ``temperature_K``, with :class:`PeriodicLJ` (keyword arguments ``lj``).
    """
    from rigidmd.core import quaternion as quat
    from rigidmd.systems import random_quaternions

    rng = np.random.default_rng(seed)
    g = np.arange(n_side) * spacing
    sites = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    half = quat.rotate(random_quaternions(len(sites), rng), np.array([0.5 * bond, 0, 0]))
    positions = np.concatenate([sites + half, sites - half], axis=1).reshape(-1, 3)
    atoms = Atoms(f"N{2 * len(sites)}", positions=positions,
                  cell=np.eye(3) * n_side * spacing, pbc=True)
    atoms.set_tags(np.repeat(np.arange(1, len(sites) + 1), 2))
    atoms.wrap()
    atoms.calc = PeriodicLJ(**lj)
    rigid_maxwell_boltzmann(atoms, temperature_K, bodies="tags", rng=rng)
    return atoms


def argon_crystal(n=3, a=5.3, temperature_K=20, shear=0.0, seed=0):
    """An fcc LJ argon crystal of free atoms (point particles), ``4 n³`` atoms, PeriodicLJ.

    ``shear`` tilts the cell's second vector along x by that fraction of its
    length (atoms moved with the cell): a crystal under shear stress.
    """
    from ase.build import bulk

    atoms = bulk("Ar", "fcc", a=a, cubic=True).repeat(n)
    atoms.calc = PeriodicLJ(sigma=3.4, epsilon=0.0104, rc=7.5)
    rigid_maxwell_boltzmann(atoms, temperature_K, bodies=[], rng=np.random.default_rng(seed))
    if shear:
        cell = atoms.cell.array.copy()
        cell[1, 0] += shear * cell[1, 1]
        atoms.set_cell(cell, scale_atoms=True)
    return atoms


def lammps_instances(monkeypatch, module):
    """Count the LAMMPS instances ``module`` (which imported ``load_lammps``) creates.

    Returns a function that gives the count so far.
    """
    created = []
    original = module.load_lammps

    def counting(*args, **kwargs):
        created.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, "load_lammps", counting)
    return lambda: len(created)


def water_dimer(seed, model="tip3p"):
    """Two waters of ``model`` in random orientations, centres 3-4 Å apart, ``mol-id`` set."""
    from rigidmd.core import quaternion as quat
    from rigidmd.systems import random_quaternions, water_molecule

    rng = np.random.default_rng(seed)
    molecule = water_molecule(model)
    local = molecule.positions - molecule.get_center_of_mass()
    q = random_quaternions(2, rng)
    shift = rng.normal(size=3)
    shift *= (3.0 + rng.random()) / np.linalg.norm(shift)
    atoms = Atoms(molecule.get_chemical_symbols() * 2,
                  positions=np.concatenate([quat.rotate(q[0], local),
                                            shift + quat.rotate(q[1], local)]))
    atoms.set_masses(np.tile(molecule.get_masses(), 2))
    atoms.arrays["mol-id"] = np.repeat([1, 2], len(molecule))
    return atoms


def benchmark_module(script="water_models"):
    """``validation/<script>.py``, ``benchmarks/<script>.py`` or ``examples/<script>.py`` as
    a module (not a package)."""
    import importlib.util

    root = Path(__file__).resolve().parents[1]
    paths = [root / folder / f"{script}.py" for folder in ("validation", "benchmarks",
                                                           "examples")]
    path = next((p for p in paths if p.exists()), paths[0])
    spec = importlib.util.spec_from_file_location(script, path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def whole_water_box(model, n_side=5, seed=1):
    """:func:`rigidmd.systems.water_box` of ``model``, molecules whole, charges set (no tags)."""
    from rigidmd.systems import water_box
    from rigidmd.water import water_model

    model = water_model(model)
    atoms = water_box(n_side, seed=seed, model=model.name, whole=True)
    atoms.set_initial_charges(model.charges(len(atoms) // model.sites))
    return atoms


# ---------------------------------------------------------------- barostats and ensembles
def npt(atoms, kind, dt=5 * units.fs, couple="iso", pressure=units.bar, temperature_K=80.0,
        **kwargs):
    """A barostatted dynamics of tagged bodies, by ``kind``.

    ``"mtk"``: RigidNPT (tdamp 100 fs, pdamp 1 ps); ``"crescale"``: RigidCRescale
    (taut 100 fs, taup 0.5 ps, 1e-4 per bar); ``"mc"``: RigidMCBarostat (Bussi
    taut 100 fs, a move every 5 steps, sizes from 2 % adapting over 100 moves).
    """
    from rigidmd import RigidCRescale, RigidMCBarostat, RigidNPT

    if kind == "mc":
        return RigidMCBarostat(atoms, dt, temperature_K, pressure, 100 * units.fs,
                               couple=couple, every=5, rng=np.random.default_rng(7),
                               adapt_moves=100, step=0.02, bodies=kwargs.pop("bodies", "tags"),
                               **kwargs)
    if kind == "mtk":
        return RigidNPT(atoms, dt, temperature_K, pressure, 100 * units.fs, 1000 * units.fs,
                        couple=couple, bodies=kwargs.pop("bodies", "tags"), **kwargs)
    return RigidCRescale(atoms, dt, temperature_K, pressure, 100 * units.fs, 500 * units.fs,
                         1e-4 / units.bar, couple=couple, bodies=kwargs.pop("bodies", "tags"),
                         rng=np.random.default_rng(7), **kwargs)


def block_mean(values, n=10):
    """Mean and standard error from ``n`` blocks."""
    blocks = np.array([b.mean() for b in np.array_split(np.asarray(values), n)])
    return blocks.mean(), blocks.std(ddof=1) / np.sqrt(n)


def block_variance(values, n=10):
    """Variance and its standard error from ``n`` blocks."""
    blocks = np.array([b.var() for b in np.array_split(np.asarray(values), n)])
    return np.var(values), blocks.std(ddof=1) / np.sqrt(n)


def ideal_gas_start(calc, temperature_K, pressure):
    """64 rigid dimers (``dimer_fluid(n_side=4)``) with ``calc`` (no interactions) at the
    ideal gas's mean volume, 65 k_B T/P; returns the atoms and k_B T/P (Å³)."""
    atoms = dimer_fluid(n_side=4)
    kT_P = units.kB * temperature_K / pressure
    atoms.set_cell(atoms.cell * (65 * kT_P / atoms.get_volume()) ** (1 / 3), scale_atoms=True)
    atoms.calc = calc
    return atoms, kT_P


def assert_ideal_gas_volumes(volumes):
    """Volumes (in k_B T/P) of N = 64 bodies distributed as Gamma(N + 1, 1).

    Mean and variance N + 1 = 65, each within 4 standard errors of 20 blocks,
    the first 10 % dropped; returns the four numbers (for the caller's comment).
    """
    volumes = np.asarray(volumes)[len(volumes) // 10:]
    mean, mean_error = block_mean(volumes, 20)
    variance, variance_error = block_variance(volumes, 20)
    assert abs(mean - 65) < 4 * mean_error, (mean, mean_error)
    assert abs(variance - 65) < 4 * variance_error, (variance, variance_error)
    return mean, mean_error, variance, variance_error


# 125 dimers at 130 K and 500 bar: a diffusive liquid of 0.75 g/cm³ (the
# centres of mass move 130 Å² in 30 ps), compressibility about 1.7e-4 per bar.
# (At 80 K with a deeper well the "liquid" was glassy, below the model's
# triple point: volumes at 1 and 101 bar came out equal within error.)
LIQUID = {"epsilon": 0.006, "rc": 7.0}
T_LIQUID, P_LIQUID = 130.0, 500.0


@functools.cache
def liquid_start(n_side=5):
    """The ``n_side``³-dimer liquid (125 by default) after 20 ps of C-rescale at 130 K and
    500 bar."""
    atoms = dimer_fluid(n_side=n_side, spacing=3.9, seed=3, temperature_K=T_LIQUID, **LIQUID)
    npt(atoms, "crescale", pressure=P_LIQUID * units.bar, temperature_K=T_LIQUID).run(4000)
    return atoms


def restart(atoms, scale=1.0):
    copy = atoms.copy()
    copy.set_cell(copy.cell * scale, scale_atoms=False)
    copy.positions += (scale - 1.0) * np.repeat(  # centres of mass with the cell
        0.5 * (atoms.positions[0::2] + atoms.positions[1::2]), 2, axis=0)
    copy.calc = PeriodicLJ(**LIQUID)
    return copy


@functools.cache
def sample(kind, pressure_bar=None, scale=1.0, steps=12000):
    """Volumes, pressures and temperatures every 5 steps of a 60 ps run from ``liquid_start``.

    ``kind`` "nvt" is Bussi at the start volume times ``scale**3``; else a
    barostat at ``pressure_bar``.
    """
    from rigidmd import RigidBussi

    atoms = restart(liquid_start(), scale)
    if kind == "nvt":
        dyn = RigidBussi(atoms, 5 * units.fs, T_LIQUID, 100 * units.fs, bodies="tags",
                         rng=np.random.default_rng(11))
    else:
        dyn = npt(atoms, kind, pressure=pressure_bar * units.bar, temperature_K=T_LIQUID)
    rows = []
    dyn.attach(lambda: rows.append((
        dyn.get_volume(), dyn.get_pressure() / units.bar,
        2 * dyn.get_translational_kinetic_energy() / (units.kB * dyn.translational_dof),
        2 * dyn.get_rotational_kinetic_energy() / (units.kB * dyn.rotational_dof))), interval=5)
    dyn.run(steps)
    return np.array(rows)


def processes_named(name):
    """PIDs of running processes whose executable is ``name`` (zombies excluded)."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        comm, state = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2]
        if comm == name and state != "Z":
            found.append(int(pid))
    return found


# ---------------------------------------------------------------------------------------
# ``rigidmd run`` projects: 8 TIP3P waters (ASE's TIP3P, deterministic), 2 fs steps, run as a
# subprocess (start, finish) or in this process (run_here).
# ---------------------------------------------------------------------------------------

THERMOSTATS = {
    "nve": "",
    "nose_hoover": "thermostat: {kind: nose_hoover, temperature: 250 K, tdamp: 50 fs}",
    "langevin": "thermostat: {kind: langevin, temperature: 250 K, friction: 0.02 1/fs, seed: 2}",
    "bussi": "thermostat: {kind: bussi, temperature: 250 K, taut: 50 fs, seed: 3}",
    "langevin_baoab": "thermostat: {kind: langevin_baoab, temperature: 250 K, "
                      "friction: 1 1/ps, seed: 4}",
}
STEPS = 1500


def config_text(thermostat, xtc=True):
    outputs = "{directory: out, trajectory: md.traj, log: md.log, interval: 10, "
    outputs += "checkpoint_interval: 50" + (", mdanalysis: md.xtc}" if xtc else "}")
    return (f"structure: cluster.xyz\nread_options: {{format: extxyz}}\nbodies: mol-id\n"
            f"calculator: {{name: tip3p, options: {{rc: 40.0}}}}\n"
            f"velocities: {{temperature: 250 K, seed: 1}}\n{THERMOSTATS[thermostat]}\n"
            f"timestep: 2 fs\nsteps: {STEPS}\noutputs: {outputs}\n")


def project(path, thermostat, xtc=True):
    path.mkdir(parents=True, exist_ok=True)
    write(path / "cluster.xyz", water_cluster(8, seed=4), format="extxyz")
    (path / "run.yaml").write_text(config_text(thermostat, xtc))
    return path


def start(path, *args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "rigidmd.run.cli", "run", "run.yaml", *args],
                            cwd=path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def start_cli_run(path, config, *args):
    """``rigidmd run run.yaml ARGS`` in ``path`` (created) with ``config`` as run.yaml.

    Returns the :class:`subprocess.Popen` (text pipes for stdout and stderr).
    """
    path.mkdir(exist_ok=True)
    (path / "run.yaml").write_text(config)
    return start(path, *args)


def free_port():
    """A TCP port on localhost that nobody listens on now."""
    import socket

    with socket.socket() as probe:
        probe.bind(("localhost", 0))
        return probe.getsockname()[1]


def start_by_hand(engine, directory):
    """Start ``engine``'s command in ``directory`` once its input is written there, as a
    user would on another node; returns the thread and the list it puts the process in."""
    import subprocess
    import threading
    import time

    started = []

    def start():
        while not (directory / "in.engine").exists():
            time.sleep(0.05)
        time.sleep(0.2)
        cmd, env = engine.command_line()
        started.append(subprocess.Popen(cmd, cwd=directory, env=env))

    thread = threading.Thread(target=start)
    thread.start()
    return thread, started


def finish(proc, timeout=600):
    """Wait for ``proc`` (text pipes) and return ``(returncode, stdout, stderr)``; killed
    and reaped if it outlives ``timeout``."""
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, stdout, stderr


def wait_for_lines(log, n, proc, timeout=120):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if log.exists() and len(log.read_text().splitlines()) > n:
            return
        if proc.poll() is not None:
            raise AssertionError("the run ended before it could be stopped")
        time.sleep(0.05)
    raise AssertionError("the run produced no log lines")


def short_project(path, steps=40, checkpoint_interval=20, thermostat="nve"):
    project(path, thermostat, xtc=False)
    text = config_text(thermostat, xtc=False).replace(f"steps: {STEPS}", f"steps: {steps}")
    (path / "run.yaml").write_text(text.replace("checkpoint_interval: 50",
                                                f"checkpoint_interval: {checkpoint_interval}"))
    return path


def run_here(path, monkeypatch, capsys, *args):
    """``rigidmd run run.yaml ARGS`` in this process: (status, stdout, stderr)."""
    monkeypatch.chdir(path)
    status = cli.main(["run", "run.yaml", *map(str, args)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def messages(err):
    """stderr without the progress lines."""
    return [line for line in err.splitlines() if not line.startswith("[")]


def file_bytes(path):
    """The bytes of a project's ``out/md.traj`` and ``out/md.log``."""
    return {name: (path / "out" / name).read_bytes() for name in ("md.traj", "md.log")}


# ---------------------------------------------------------------- LAMMPS image flags
#: LAMMPS's default image packing (``-DLAMMPS_SMALLBIG``): IMGBITS, IMG2BITS, IMGMASK, IMGMAX.
LAMMPS_IMAGE_BITS = (10, 20, 1023, 512)


def lammps_image_case(seed, n, tilt, outside):
    """A lower-triangular cell, positions given in random images, LAMMPS's packed images.

    Fractional coordinates stay 0.02 away from the integers and from -1/2 and 3/2, where
    the two formulas (an inverse matrix; back substitution) may round to either side.
    ``outside``: one atom is put 1.6-3 boxes out in its image (so every atom is shifted).
    """
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(5.0, 30.0, 3)
    cell = np.diag(lengths)
    cell[1, 0], cell[2, 0], cell[2, 1] = tilt * rng.uniform(-0.5, 0.5, 3) * lengths[[0, 0, 1]]
    frac = rng.integers(0, 2, (n, 3)) - 0.5 + rng.uniform(0.02, 0.48, (n, 3))  # [-.48, .98]
    if outside:
        frac[rng.integers(n), rng.integers(3)] = rng.choice([-1, 1]) * rng.uniform(1.62, 2.98)
    frac += np.where(np.abs(frac - np.round(frac)) < 0.02, 0.05, 0.0)
    flags = rng.integers(-3, 4, (n, 3))
    order = rng.permutation(n)
    positions = np.empty((n, 3))
    positions[order] = (frac + flags) @ cell  # LAMMPS atom i is ASE atom order[i]
    image = lammps_numpy.pack_images(flags, LAMMPS_IMAGE_BITS).astype(np.int32)
    return positions, order.astype(np.int64), image, cell


class NoStressLJ(PeriodicLJ):
    """PeriodicLJ with energy and forces only (as ASE's TIP4P, ML wrappers); counts calls."""

    implemented_properties = ["energy", "forces"]

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.calls = 0

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        self.calls += 1
        super().calculate(atoms, properties, system_changes)
        del self.results["stress"]


def free_waters(n=8, seed=1, temperature_K=250):
    """:func:`waters` without interactions (:class:`ZeroForce`): free rigid tops."""
    atoms = waters(n, seed=seed, temperature_K=temperature_K)
    atoms.calc = ZeroForce()
    return atoms


def checkpoint_continues(build, calculator, path, before=4, after=4):
    """``build()`` run ``before + after`` steps, and ``build()`` run ``before``, saved in a
    checkpoint at ``path``, loaded with ``calculator`` and run ``after``: asserts the same
    bits (positions, momenta, cell, conserved energy), the same class and the same parts
    (a checkpoint comes back as the class saved, built around them: the same ``todict()``);
    returns ``(reference, resumed)``."""
    from rigidmd import load_checkpoint

    reference = build()
    reference.run(before + after)
    first = build()
    first.run(before)
    first.save_checkpoint(path)
    resumed = load_checkpoint(path, calculator)
    assert resumed.nsteps == before
    assert type(resumed) is type(first)
    assert [type(part) for part in resumed.couplings] == [type(part) for part in first.couplings]
    assert resumed.todict() == first.todict()
    resumed.run(after)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(resumed.atoms.get_momenta(), reference.atoms.get_momenta())
    np.testing.assert_array_equal(resumed.atoms.cell.array, reference.atoms.cell.array)
    assert resumed.get_conserved_energy() == reference.get_conserved_energy()
    return reference, resumed


def rigid_temperature(atoms, n_bodies):
    """The temperature of ``n_bodies`` rigid molecules with the total momentum held
    (6 n_bodies - 3 degrees of freedom), K."""
    return 2 * atoms.get_kinetic_energy() / ((6 * n_bodies - 3) * units.kB)


# ---------------------------------------------------------------- water frames (analysis)
def water_frames(n_frames=4, seed=0):
    """A wrapped 8-water box (molecules across the faces) and rigidly moved copies."""
    atoms = water_box(2, seed=seed, whole=False)
    atoms.set_initial_charges(tip3p_charges(atoms))
    rng = np.random.default_rng(seed)
    frames = [atoms]
    for _ in range(n_frames - 1):
        new = frames[-1].copy()
        new.positions += rng.normal(scale=0.05, size=(1, 3))
        new.wrap()
        frames.append(new)
    return frames


def assert_whole_waters(positions, n_water, atol=2e-5):
    """O–H distances of every water equal TIP3P's (default: float32 precision)."""
    x = np.asarray(positions, dtype=float).reshape(n_water, 3, 3)
    d = np.linalg.norm(x[:, 1:] - x[:, :1], axis=2)
    np.testing.assert_allclose(d, rOH, atol=atol)


def count_calls(method: str, **calculators) -> dict:
    """Wrap ``method`` (``"calculate"``, ``"get_forces"``) of each named calculator so that
    its calls are counted; returns the counts by name, updated as they are called."""
    counts = dict.fromkeys(calculators, 0)
    for name, calc in calculators.items():
        inner = getattr(calc, method)

        def counted(*args, _inner=inner, _name=name, **kwargs):
            counts[_name] += 1
            return _inner(*args, **kwargs)

        setattr(calc, method, counted)
    return counts



def sigterm_once_written(proc, path, timeout=200):
    """SIGTERM ``proc`` as soon as ``path`` exists (a run's first checkpoint), or when it
    ended or ``timeout`` passed; returns :func:`finish`'s result."""
    import signal

    deadline = time.monotonic() + timeout
    while not Path(path).exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    return finish(proc)


def stopped_by_sigterm(call, after_s):
    """Call ``call()`` under a run's stop handling (``StopSignals``) while this process gets
    a SIGTERM after ``after_s`` seconds; it must end as a ``StopRequest`` naming SIGTERM.
    Returns the seconds it took."""
    import signal
    import threading

    import pytest

    from rigidmd.run.signals import StopRequest, StopSignals

    timer = threading.Timer(after_s, os.kill, (os.getpid(), signal.SIGTERM))
    start = time.monotonic()
    try:
        with StopSignals(), pytest.raises(StopRequest, match="SIGTERM"):
            timer.start()
            call()
        return time.monotonic() - start
    finally:
        timer.cancel()
        timer.join()
