"""MDAnalysis interoperability (rigidmd.mdanalysis): universes, streaming, analyses.

Physics checks use systems with exact answers: a simple cubic lattice for
the RDF (shells at a, a√2, a√3, 2a ... with 6, 12, 8, 6 ... neighbours),
ballistic motion for the MSD (MSD = <v²> t² exactly, also for rigid waters
that rotate and cross the periodic boundaries), and free rotors spinning
about the normal of their plane for the dipole correlation (u(0)·u(t) =
cos ωt, so C1 = cos ωt and C2 = (3 cos² ωt − 1)/2).
"""

import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

mda = pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P, rOH
from ase.io import read
from helpers import ZeroForce

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.core import quaternion as quat
from rigidmd.lammps import tip3p_charges
from rigidmd.mdanalysis import (
    PS,
    MDAWriter,
    MeanSquaredDisplacement,
    RadialDistribution,
    RotationalCorrelation,
    body_dipole_directions,
    mean_squared_displacement,
    orientational_correlation,
    relaxation_time,
    to_universe,
    write_psf,
)
from rigidmd.systems import co2_water_mixture, random_quaternions, water_box, water_molecule

pytestmark = pytest.mark.filterwarnings(
    "ignore:DCDReader currently makes independent timesteps:DeprecationWarning")

DATA = Path(__file__).resolve().parents[1] / "data"


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


# ---------------------------------------------------------------------------- Universe


def test_universe_from_atoms_list():
    frames = water_frames()
    straddling = RigidBodies.resolve(frames[0]).whole_positions(frames[0])
    assert np.abs(straddling - frames[0].positions).max() > 1.0  # molecules cross faces
    u = to_universe(frames, dt=0.02)
    assert u.atoms.n_atoms == 24 and len(u.residues) == 8
    assert list(u.residues.resnames) == ["SOL"] * 8
    assert list(u.residues.resids) == list(range(1, 9))
    assert list(u.atoms.names[:3]) == ["OW", "HW1", "HW2"]
    assert list(u.atoms.types[:3]) == ["O", "H", "H"]
    assert list(u.atoms.elements[:3]) == ["O", "H", "H"]
    np.testing.assert_allclose(u.atoms.masses, frames[0].get_masses())
    np.testing.assert_allclose(u.atoms.charges, np.tile([-0.834, 0.417, 0.417], 8))
    assert len(u.bonds) == 16
    assert {tuple(sorted(b.indices % 3)) for b in u.bonds} == {(0, 1), (0, 2)}
    assert u.trajectory.n_frames == 4
    np.testing.assert_allclose([ts.time for ts in u.trajectory], [0, 0.02, 0.04, 0.06])
    for ts, atoms in zip(u.trajectory, frames, strict=True):
        np.testing.assert_allclose(ts.dimensions, [6.2, 6.2, 6.2, 90, 90, 90], rtol=1e-6)
        assert_whole_waters(ts.positions, 8)
        # Each molecule is the minimum image of the wrapped input.
        d = ts.positions - atoms.positions
        np.testing.assert_allclose(d / 6.2, np.round(d / 6.2), atol=1e-5)


def test_universe_names_of_mixture_and_free_atoms():
    atoms = co2_water_mixture(n_co2=2, n_water=2, seed=3)
    atoms += Atoms("Na", positions=[[20.0, 20.0, 20.0]])
    u = to_universe(atoms, bodies="mol-id", charges=np.arange(len(atoms), dtype=float))
    names = dict(zip(u.residues.resids, u.residues.resnames, strict=True))
    assert sorted(names.values()) == ["CO2", "CO2", "NA", "SOL", "SOL"]
    co2 = u.select_atoms("resname CO2").residues[0].atoms
    assert list(co2.names) == ["C", "O1", "O2"]
    assert len(co2.bonds) == 2 and len(u.select_atoms("resname NA").bonds) == 0
    # Residues follow the bodies of the mol-id array, numbered by first atom.
    mol = atoms.arrays["mol-id"]
    for res in u.residues[:-1]:
        assert len(set(mol[res.atoms.indices])) == 1
    assert u.select_atoms("resname NA").n_atoms == 1
    np.testing.assert_allclose(u.atoms.charges, np.arange(len(atoms)))
    assert u.dimensions is None  # no cell


def test_universe_from_traj_file_and_dynamics(tmp_path):
    atoms = read(DATA / "water_box_27.traj")
    atoms.set_initial_charges(tip3p_charges(atoms))
    atoms.calc = TIP3P(rc=4.5)
    path = tmp_path / "md.traj"
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="tags", trajectory=str(path), loginterval=5)
    positions = []
    dyn.attach(lambda: positions.append(atoms.positions.copy()), interval=5)
    dyn.run(20)
    for u in (to_universe(path, bodies="tags"), to_universe(dyn)):
        assert u.trajectory.n_frames == 5 and len(u.residues) == 27
        np.testing.assert_allclose(u.trajectory.dt, 5 * units.fs / PS)
        np.testing.assert_allclose(u.trajectory[-1].time, 0.020, atol=1e-12)
        np.testing.assert_allclose(u.atoms.charges, tip3p_charges(atoms))
        for ts, x in zip(u.trajectory, positions, strict=True):
            np.testing.assert_allclose(ts.positions, x, atol=1e-5)  # float32, already whole
    # Every second frame: the time step doubles.
    assert to_universe(path, bodies="tags", index="::2").trajectory.dt == pytest.approx(0.010)
    # Without a trajectory file: the current state, at the dynamics' time.
    current = RigidVerlet(atoms, 1 * units.fs, bodies="tags")
    current.run(3)
    u = to_universe(current)
    assert u.trajectory.n_frames == 1
    assert u.trajectory.ts.time == pytest.approx(3 * units.fs / PS)


def test_inconsistent_input_is_refused(tmp_path):
    frames = water_frames(2)
    with pytest.raises(ValueError, match="same atoms"):
        to_universe([frames[0], frames[1][:-3]])
    other = frames[1].copy()
    other.numbers[1] = 9
    with pytest.raises(ValueError, match="element"):
        to_universe([frames[0], other])
    with pytest.raises(ValueError, match="no frames"):
        to_universe([])
    with pytest.raises(ValueError, match="charges"):
        to_universe(frames[0], charges=[1.0, 2.0])
    with pytest.raises(ValueError, match="dt"):
        to_universe(frames, dt=-1.0)
    with pytest.raises(TypeError, match="frame 1"):
        to_universe([frames[0], "not atoms"])
    with pytest.raises(FileNotFoundError):
        to_universe(tmp_path / "missing.traj")
    with pytest.raises(ValueError, match=".xtc or .dcd"):
        MDAWriter(frames[0], tmp_path / "md.trr")
    with pytest.raises(ValueError, match="topology"):
        MDAWriter(frames[0], tmp_path / "md.xtc", topology=tmp_path / "md.top")
    writer = MDAWriter(frames[0], tmp_path / "md.xtc")
    writer.write()
    writer.atoms = frames[1][:-3]
    with pytest.raises(ValueError, match="atoms"):
        writer.write()
    writer.close()
    with pytest.raises(ValueError, match="closed"):
        writer.write()


def test_missing_mdanalysis_gives_install_hint():
    code = textwrap.dedent("""
        import sys
        sys.modules["MDAnalysis"] = None  # as if not installed
        import rigidmd
        import rigidmd.mdanalysis as m
        from rigidmd.systems import water_box
        for call in (lambda: m.to_universe(water_box(1)),
                     lambda: m.MDAWriter(water_box(1), "x.xtc"),
                     lambda: m.RadialDistribution(None)):
            try:
                call()
            except ImportError as err:
                print(err)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.count('pip install "rigidmd[analysis]"') == 3


# ---------------------------------------------------------------------------- streaming


@pytest.fixture
def box_run():
    """27 equilibrated TIP3P waters in a 9.3 Å box, molecules across the faces."""
    atoms = read(DATA / "water_box_27.traj")
    atoms.set_initial_charges(tip3p_charges(atoms))
    atoms.calc = TIP3P(rc=4.5)
    return atoms


@pytest.mark.parametrize("ext, tol", [(".xtc", 1e-3), (".dcd", 2e-5)])
@pytest.mark.parametrize("topology", [None, "top.pdb"])
def test_writer_round_trip(tmp_path, box_run, ext, tol, topology):
    atoms = box_run
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="tags")
    dyn.run(7)  # the first frame is at step 7, 7 fs
    frames = []
    path = tmp_path / f"md{ext}"
    top = None if topology is None else tmp_path / topology
    with MDAWriter(dyn, path, topology=top) as writer:
        dyn.attach(writer, interval=4)
        dyn.attach(lambda: frames.append((atoms.positions.copy(), dyn.get_time() / PS)),
                   interval=4)
        dyn.run(40)
    assert writer.n_frames == len(frames) == 10
    topology_file = tmp_path / (topology or "md.psf")
    assert writer.topology_filename == topology_file
    u = mda.Universe(str(topology_file), str(path))
    assert u.trajectory.n_frames == 10
    assert len(u.residues) == 27 and set(u.residues.resnames) == {"SOL"}
    np.testing.assert_array_equal(u.residues.resids, np.arange(1, 28))
    assert list(u.atoms.names[:3]) == ["OW", "HW1", "HW2"]
    assert len(u.bonds) == 54
    if topology is None:  # the PSF carries charges and masses
        np.testing.assert_allclose(u.atoms.charges, tip3p_charges(atoms), atol=1e-6)
        np.testing.assert_allclose(u.atoms.masses, atoms.get_masses(), atol=1e-4)
    for ts, (x, t) in zip(u.trajectory, frames, strict=True):
        assert np.abs(ts.positions - x).max() < tol
        np.testing.assert_allclose(ts.dimensions, [9.3, 9.3, 9.3, 90, 90, 90], rtol=1e-6)
        assert ts.time == pytest.approx(t, abs=1e-5)
        assert_whole_waters(ts.positions, 27, atol=2 * tol)
    assert frames[0][1] == pytest.approx(0.008)  # steps 8, 12, ... (observers at nsteps % 4)


def test_writer_keeps_frames_of_an_interrupted_run(tmp_path, box_run):
    class Failing(Calculator):
        """TIP3P that raises on its 23rd call."""

        implemented_properties = ["energy", "forces"]

        def __init__(self):
            super().__init__()
            self.inner, self.calls = TIP3P(rc=4.5), 0

        def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
            super().calculate(atoms, properties, system_changes)
            self.calls += 1
            if self.calls == 23:
                raise RuntimeError("calculator crashed")
            self.results = {"energy": self.inner.get_potential_energy(self.atoms),
                            "forces": self.inner.get_forces(self.atoms)}

    atoms = box_run
    atoms.calc = Failing()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="tags")
    written = []
    with pytest.raises(RuntimeError, match="crashed"):
        with MDAWriter(dyn, tmp_path / "md.xtc") as writer:
            dyn.attach(writer, interval=5)
            dyn.attach(lambda: written.append(atoms.positions.copy()), interval=5)
            dyn.run(100)
    assert dyn.nsteps == 21  # the 22nd step failed
    assert writer.closed and writer.n_frames == len(written) == 5  # steps 0, 5, ..., 20
    u = mda.Universe(str(tmp_path / "md.psf"), str(tmp_path / "md.xtc"))
    assert u.trajectory.n_frames == 5
    np.testing.assert_allclose(u.trajectory[-1].positions, written[-1], atol=1e-3)


def test_writer_from_atoms_and_dcd_spacing(tmp_path):
    frames = water_frames(3)
    writer = MDAWriter(frames[0], tmp_path / "a.dcd", dt=0.5)
    for atoms in frames:
        writer.atoms = atoms
        writer()
    writer.close()
    u = mda.Universe(str(tmp_path / "a.psf"), str(tmp_path / "a.dcd"))
    np.testing.assert_allclose([ts.time for ts in u.trajectory], [0.0, 0.5, 1.0], atol=1e-6)
    # DCD frames must be evenly spaced: irregular calls are reported.
    atoms = read(DATA / "water_box_27.traj")
    atoms.calc = ZeroForce()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="tags")
    with MDAWriter(dyn, tmp_path / "b.dcd") as writer:
        dyn.attach(writer, interval=2)
        dyn.attach(writer, interval=-3)  # an extra frame at step 3
        with pytest.warns(UserWarning, match="evenly spaced"):
            dyn.run(6)
    # A single held frame is written at close.
    with MDAWriter(frames[0], tmp_path / "c.dcd") as writer:
        writer()
    assert mda.Universe(str(tmp_path / "c.psf"), str(tmp_path / "c.dcd")).trajectory.n_frames == 1


# ---------------------------------------------------------------------------- RDF


def lattice(n=5, a=3.01, symbol="Ar"):
    """Simple cubic lattice of free atoms in a periodic cube of edge n a."""
    g = np.arange(n) * a
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    return Atoms(symbol * len(x), positions=x, cell=[n * a] * 3, pbc=True)


def test_rdf_of_simple_cubic_lattice(tmp_path):
    a = 3.01
    atoms = lattice(5, a)
    shifted = atoms.copy()
    shifted.positions += [0.3, -0.7, 1.1]  # a second frame, translated and wrapped
    shifted.wrap()
    u = to_universe([atoms, shifted])
    rdf = RadialDistribution(u, "name AR", bin_width=0.05).run()
    res = rdf.results
    assert res.edges[-1] == pytest.approx(7.5)  # whole bins within half the 15.05 Å box
    shells = a * np.sqrt([1, 2, 3, 4, 5, 6])
    neighbours = [6, 12, 8, 6, 24, 24]
    # Pairs only in the bins of the shells, with the lattice's coordination numbers.
    occupied = res.bins[res.count > 0]
    np.testing.assert_allclose(occupied, shells, atol=0.025 + 1e-9)
    per_atom = res.count[res.count > 0] / (2 * 125)
    np.testing.assert_allclose(per_atom, neighbours)
    np.testing.assert_allclose(res.cumulative_number[-1], np.sum(neighbours))
    # The first shell: peak at a, six neighbours within the first minimum.
    assert res.first_peak_position == pytest.approx(a, abs=0.025)
    assert res.coordination_number == pytest.approx(6.0)
    # g in the first-shell bin: 6 neighbours over the shell volume times the density.
    k = np.flatnonzero(res.count)[0]
    shell = 4 / 3 * np.pi * (res.edges[k + 1] ** 3 - res.edges[k] ** 3)
    density = 124 / atoms.get_volume()  # pairs with the other 124 atoms
    assert res.rdf[k] == pytest.approx(6 / (shell * density), rel=1e-6)
    assert res.first_peak_height == pytest.approx(res.rdf[k])
    rdf.plot(tmp_path / "rdf.png")
    assert (tmp_path / "rdf.png").stat().st_size > 0


def test_rdf_of_random_molecules_tends_to_one():
    """Waters placed at random: g = 1 between atoms of different molecules.

    With 10 molecules of 3 atoms, counting intramolecular pairs in the
    normalisation (as MDAnalysis's exclude_same does) would give g = 0.9.
    """
    rng = np.random.default_rng(5)
    template = water_molecule()
    local = template.positions - template.get_center_of_mass()
    frames = []
    for _ in range(400):
        centres = rng.uniform(0, 10.0, (10, 3))
        x = centres[:, None, :] + quat.rotate(random_quaternions(10, rng)[:, None, :], local)
        frames.append(Atoms("OH2" * 10, positions=x.reshape(-1, 3), cell=[10.0] * 3, pbc=True))
    u = to_universe(frames, bodies=np.repeat(np.arange(10), 3))
    res = RadialDistribution(u, "all", r_max=5.0, bin_width=0.1).run().results
    window = (res.bins > 2.5) & (res.bins < 5.0)
    assert np.mean(res.rdf[window]) == pytest.approx(1.0, abs=0.03)  # noise ~1 %
    oxygen = RadialDistribution(u, "name OW", r_max=5.0, bin_width=0.5).run().results
    assert np.mean(oxygen.rdf[oxygen.bins > 2.5]) == pytest.approx(1.0, abs=0.05)


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


# ---------------------------------------------------------------------------- rotation


@pytest.fixture
def spinning_waters():
    """Waters spinning at omega about the normal of their plane (a principal axis)."""
    rng = np.random.default_rng(3)
    atoms = water_box(2, seed=3, spacing=8.0)  # far apart: no interactions anyway
    atoms.set_initial_charges(tip3p_charges(atoms))
    omega = 2 * np.pi / (0.4 * PS)  # one turn in 0.4 ps
    atoms.positions = RigidBodies.resolve(atoms, "mol-id").whole_positions(atoms)
    atoms.pbc, atoms.cell = False, None  # isolated molecules
    x = atoms.positions.reshape(-1, 3, 3)
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    m = atoms.get_masses().reshape(-1, 3)
    com = np.einsum("ni,nij->nj", m, x) / m.sum(axis=1, keepdims=True)
    v = rng.normal(scale=0.01, size=(len(x), 1, 3)) + omega * np.cross(
        normal[:, None, :], x - com[:, None, :])
    atoms.set_momenta((m[..., None] * v).reshape(-1, 3))
    atoms.calc = ZeroForce()
    return atoms, omega


def test_dipole_correlation_of_free_rotors(spinning_waters):
    atoms, omega = spinning_waters
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="mol-id")
    frames, dipoles = [], []

    def record():
        frames.append(atoms.copy())
        dipoles.append(body_dipole_directions(dyn))

    dyn.attach(record, interval=4)
    dyn.run(400)  # 0.4 ps: one turn; frames every 4 fs
    t = np.arange(len(frames)) * 4 * units.fs
    expected1 = np.cos(omega * t)
    expected2 = 1.5 * expected1**2 - 0.5
    # From the bodies' orientations (quaternions): exact up to roundoff.
    c1, c2 = orientational_correlation(np.array(dipoles))
    np.testing.assert_allclose(c1, expected1, atol=1e-9)
    np.testing.assert_allclose(c2, expected2, atol=1e-9)
    # From atom positions through MDAnalysis (float32 coordinates).
    u = to_universe(frames, bodies="mol-id", dt=0.004)
    for vector in ("dipole", "bisector"):
        rot = RotationalCorrelation(u, vector=vector, max_lag=0.4).run()
        assert rot.results.vector == vector
        np.testing.assert_allclose(rot.results.times, t / PS, atol=1e-12)
        np.testing.assert_allclose(rot.results.c1, expected1, atol=2e-5)
        np.testing.assert_allclose(rot.results.c2, expected2, atol=2e-5)


def test_rotational_relaxation_times(tmp_path):
    t = np.arange(0, 10, 0.01)
    c = 0.9 * np.exp(-t / 2.0)
    tau, integral, amplitude = relaxation_time(t, c)
    assert tau == pytest.approx(2.0, rel=1e-10) and amplitude == pytest.approx(0.9)
    assert integral == pytest.approx(1.8, rel=1e-4)
    assert np.isnan(relaxation_time(t[:3], c[:3])[0])  # too few points in the window
    # Molecules that diffuse in orientation: C1 = exp(-2 Dr t), C2 = exp(-6 Dr t).
    rng = np.random.default_rng(11)
    Dr, dt, n = 0.5, 0.01, 2000
    u = np.tile([0.0, 0.0, 1.0], (300, 1))
    vectors = np.empty((n, 300, 3))
    for k in range(n):  # small random rotations (Euler-Maruyama on the sphere)
        vectors[k] = u
        kick = rng.normal(scale=np.sqrt(2 * Dr * dt), size=u.shape)
        u = u + np.cross(kick, u)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
    c1, c2 = orientational_correlation(vectors, max_lag=200)
    lag = np.arange(201) * dt
    assert relaxation_time(lag, c1)[0] == pytest.approx(1 / (2 * Dr), rel=0.1)
    assert relaxation_time(lag, c2)[0] == pytest.approx(1 / (6 * Dr), rel=0.1)
    with pytest.raises(ValueError, match="shape"):
        orientational_correlation(np.zeros((5, 3)))


def test_rotational_correlation_needs_charges_for_dipoles(tmp_path):
    frames = water_frames(6)
    for f in frames:
        f.set_initial_charges(None)
    u = to_universe(frames, dt=0.01)
    with pytest.raises(ValueError, match="charges"):
        RotationalCorrelation(u, vector="dipole")
    rot = RotationalCorrelation(u).run()  # auto: no charges, so the bisector
    assert rot.results.vector == "bisector"
    np.testing.assert_allclose(rot.results.c1, 1.0, atol=1e-5)  # rigid translation only
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert rot.plot(tmp_path / "rot.png") is not None
    assert (tmp_path / "rot.png").stat().st_size > 0
    with pytest.raises(ValueError, match="matches no atoms"):
        RotationalCorrelation(u, select="resname XYZ")


# ---------------------------------------------------------------------------- refusals and labels


@pytest.mark.filterwarnings("ignore:No coordinate reader found")
def test_bodies_with_scattered_atoms_are_refused_for_psf_and_writer(tmp_path):
    """All oxygens first, then all hydrogens: readers would see 3 residues per water."""
    atoms = water_frames(1)[0]
    order = np.r_[np.arange(0, len(atoms), 3), np.arange(1, len(atoms), 3),
                  np.arange(2, len(atoms), 3)]
    scattered = atoms[order]
    scattered.set_array("mol-id", atoms.get_array("mol-id")[order])
    with pytest.raises(ValueError, match=r"atom 8 belongs to residue 1 .* 24 residues inst"):
        write_psf(to_universe(scattered, bodies="mol-id"), tmp_path / "md.psf")
    with pytest.raises(ValueError, match="not consecutive"):
        MDAWriter(scattered, tmp_path / "md.xtc", bodies="mol-id")
    assert not (tmp_path / "md.psf").exists() and not (tmp_path / "md.xtc").exists()
    # The reordering named in the message gives a file that reads back as 8 waters.
    ids = RigidBodies.resolve(scattered, "mol-id").body_ids
    fixed = scattered[np.argsort(ids, kind="stable")]
    write_psf(to_universe(fixed, bodies="mol-id"), tmp_path / "md.psf")
    assert len(mda.Universe(str(tmp_path / "md.psf")).residues) == 8


def test_rdf_of_a_cluster_is_refused():
    cluster = water_frames(1)[0]
    cluster.pbc, cluster.cell = False, None
    # The box's molecules were wrapped, so without the cell some are in pieces: the
    # default rule (mol-id) says so.
    with pytest.warns(UserWarning, match="falls into 3 pieces that no covalent bond joins"):
        u = to_universe(cluster)
    with pytest.raises(ValueError, match="needs a periodic cell"):
        RadialDistribution(u, "element O")


def test_ions_are_left_out_of_rotation_and_named_like_their_residue(tmp_path):
    frames = water_frames(6)
    with_ions = []
    for f in frames:
        ions = Atoms("NaCl", positions=[[0.5, 0.5, 0.5], [3.0, 3.0, 3.0]], charges=[1.0, -1.0])
        g = f + ions
        g.set_array("mol-id", np.r_[f.get_array("mol-id"), [100, 101]])
        with_ions.append(g)
    u = to_universe(with_ions, bodies="mol-id", dt=0.01)
    assert list(u.residues.resnames[-2:]) == ["NA", "CL"]
    assert list(u.atoms.names[-2:]) == ["NA", "CL"]  # atom name = residue name, as in PSFs
    rot = RotationalCorrelation(u, "all", vector="dipole").run()
    assert rot.results.n_molecules == 8  # the two ions have no orientation
    np.testing.assert_allclose(rot.results.c1, 1.0, atol=1e-5)
    with pytest.raises(ValueError, match="single atoms have no orientation"):
        RotationalCorrelation(u, "resname NA CL")


def test_plot_labels_say_what_is_shown(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    # RDF of a carbon lattice: the label names C–C, and n(r) is in the legend.
    a, n = 3.0, 5
    grid = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) * a
    lattice = Atoms(f"C{n**3}", positions=grid, cell=[n * a] * 3, pbc=True)
    u = to_universe(lattice, bodies=np.full(len(lattice), -1))
    fig = RadialDistribution(u, "element C", r_max=6.0).run().plot()
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts[0] == "g(r) C–C" and "n(r)" in texts
    # A correlation that never decays into the fit window: no τ, and the label says why.
    rot = RotationalCorrelation(to_universe(water_frames(6), dt=0.01)).run()
    fig = rot.plot()
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert all("no τ" in label and "nan" not in label for label in labels)
    assert fig.axes[0].get_ylabel().startswith("$C_\\ell(t)$")


def test_four_site_water_topology(tmp_path):
    """M of a four-site model: named MW, mass 0, its charge; the molecule is still SOL."""
    from rigidmd.mdanalysis import MDAWriter
    from rigidmd.systems import water_cluster
    from rigidmd.water import water_model

    model = water_model("tip4p2005")
    atoms = water_cluster(4, seed=1, model="tip4p2005")
    atoms.set_initial_charges(model.charges(4))
    atoms.calc = ZeroForce()
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(0))
    dyn = RigidVerlet(atoms, units.fs)
    with MDAWriter(dyn, tmp_path / "w.xtc") as writer:
        dyn.attach(writer, interval=5)
        dyn.run(10)
    u = mda.Universe(str(tmp_path / "w.psf"), str(tmp_path / "w.xtc"))
    assert list(u.residues.resnames) == ["SOL"] * 4
    assert list(u.atoms.names[:4]) == ["OW", "HW1", "HW2", "MW"]
    mw = u.select_atoms("name MW")
    assert mw.n_atoms == 4 and np.all(mw.masses == 0)
    np.testing.assert_allclose(mw.charges, -2 * model.q_h, atol=1e-6)
    # Centres of mass ignore M: the last frame's are the dynamics' own, to the XTC's
    # precision (positions rounded to 0.01 Å, so centres of mass to 0.005 Å).
    u.trajectory[-1]
    com = np.array([r.atoms.center_of_mass() for r in u.residues])
    np.testing.assert_allclose(com, dyn.com_positions, atol=5e-3)
