"""MDAnalysis universes of rigid bodies (rigidmd.mdanalysis.topology), and refusals.

The analyses have files of their own (``test_rdf.py``, ``test_diffusion.py``,
``test_rotation.py``), as has streaming (``test_writer.py``).
"""

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

mda = pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')
from ase import Atoms, units
from ase.calculators.tip3p import TIP3P
from ase.io import read
from helpers import ZeroForce, assert_whole_waters, water_frames

from rigidmd import RigidBodies, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.lammps import tip3p_charges
from rigidmd.mdanalysis import (
    PS,
    MDAWriter,
    RadialDistribution,
    RotationalCorrelation,
    to_universe,
    write_psf,
)
from rigidmd.systems import co2_water_mixture

pytestmark = pytest.mark.filterwarnings(
    "ignore:DCDReader currently makes independent timesteps:DeprecationWarning")

DATA = Path(__file__).resolve().parents[1] / "data"


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


def _all_distances(x, box):
    from MDAnalysis.lib.distances import self_distance_array

    return np.sort(self_distance_array(np.asarray(x, dtype=np.float32), box=box))


@pytest.mark.parametrize("turn", ["rotated", "upper"])
def test_a_cell_oriented_otherwise_is_turned_with_its_positions(tmp_path, turn):
    """MDAnalysis keeps a cell's lengths and angles only, reading them as a along x and b in
    the xy plane.  A sheared cell turned 30° about z, and the upper-triangular cell ASE's NPT
    keeps, gave every minimum-image distance wrong (the first O–O peak at 1.1 Å); written
    through to_universe and MDAWriter their distances are ASE's."""
    from ase.geometry import get_distances
    from scipy.spatial.transform import Rotation

    frames = water_frames(1)
    atoms = frames[0]
    cell = atoms.cell.array.copy()
    cell[1, 0] += 1.2  # sheared
    atoms.set_cell(cell, scale_atoms=True)
    if turn == "rotated":
        turned = Rotation.from_euler("z", 30, degrees=True).as_matrix()
        atoms.set_cell(atoms.cell.array @ turned.T, scale_atoms=True)
    else:
        upper = np.triu(np.array([[6.2, 0.0, 0.0], [1.1, 6.3, 0.0], [0.4, 0.7, 6.1]]).T)
        atoms.set_cell(upper, scale_atoms=True)
    _, d = get_distances(atoms.positions, cell=atoms.cell, pbc=True)
    ase_distances = np.sort(d[np.triu_indices(len(atoms), 1)])
    u = to_universe(atoms)
    # float32 coordinates: 1e-5 Å; XTC at 1e-4 nm: 1e-3 Å
    np.testing.assert_allclose(_all_distances(u.atoms.positions, u.dimensions),
                               ase_distances, atol=2e-5)
    with MDAWriter(atoms, tmp_path / "md.xtc") as writer:
        writer.write()
    xtc = mda.Universe(str(tmp_path / "md.psf"), str(tmp_path / "md.xtc"))
    np.testing.assert_allclose(_all_distances(xtc.atoms.positions, xtc.dimensions),
                               ase_distances, atol=2e-3)


def test_a_traj_read_from_a_later_frame_starts_at_its_time(tmp_path):
    """``index="2:"`` of a .traj with a frame every 5 fs starts at 0.010 ps (before: 0);
    frames read backwards are refused naming ``index``."""
    atoms = read(DATA / "water_box_27.traj")
    atoms.calc = TIP3P(rc=4.5)
    path = tmp_path / "md.traj"
    RigidVerlet(atoms, 1 * units.fs, bodies="tags", trajectory=str(path), loginterval=5).run(20)
    u = to_universe(path, bodies="tags", index="2:")
    assert [round(ts.time, 9) for ts in u.trajectory] == [0.010, 0.015, 0.020]
    assert to_universe(path, bodies="tags", index="1::2").trajectory[0].time == \
        pytest.approx(0.005)
    assert to_universe(path, bodies="tags", index=-1).trajectory[0].time == pytest.approx(0.020)
    with pytest.raises(ValueError, match=r"index: '::-1' reads the frames backwards"):
        to_universe(path, bodies="tags", index="::-1")


@pytest.mark.parametrize("precision", [0, 8, 2.7, True, -1])
def test_an_xtc_precision_outside_what_xtc_holds_is_refused(tmp_path, precision):
    """8 decimals in nm overflow XTC's integers (positions 200 Å off, in silence)."""
    with pytest.raises(ValueError, match="precision must be a whole number of decimals"):
        MDAWriter(water_frames(1)[0], tmp_path / "md.xtc", precision=precision)
    assert not (tmp_path / "md.xtc").exists()


def test_a_dynamics_writing_through_a_trajectory_object_gives_its_frames(tmp_path):
    """``trajectory=Trajectory(path, "w", atoms)`` (an open writer, not a file name) gave only
    the current state, one frame, in silence; a writer on an open file is refused."""
    from ase.io.trajectory import Trajectory

    atoms = read(DATA / "water_box_27.traj")
    atoms.calc = ZeroForce()
    path = tmp_path / "md.traj"
    with Trajectory(path, "w", atoms) as traj:
        dyn = RigidVerlet(atoms, 2 * units.fs, bodies="tags", trajectory=traj, loginterval=5)
        dyn.run(20)
        u = to_universe(dyn)
    assert u.trajectory.n_frames == 5
    np.testing.assert_allclose([ts.time for ts in u.trajectory], [0, 0.01, 0.02, 0.03, 0.04],
                               atol=1e-12)
    np.testing.assert_allclose(u.trajectory[-1].positions, atoms.positions, atol=1e-5)  # float32
    with open(tmp_path / "fh.traj", "wb") as fh:
        dyn = RigidVerlet(atoms, 2 * units.fs, bodies="tags",
                          trajectory=Trajectory(fh, "w", atoms), loginterval=5)
        dyn.run(5)
        with pytest.raises(ValueError, match="^run: the dynamics writes its trajectory through "
                                             "a TrajectoryWriter whose file cannot be read back"):
            to_universe(dyn)


def test_a_time_step_changed_during_the_run_is_refused(tmp_path):
    """After ``set_timestep`` the times came from the .traj header's first time step: the
    frames at 0.02 and 0.03 ps were said to be at 0.015 and 0.02 ps."""
    atoms = read(DATA / "water_box_27.traj")
    atoms.calc = ZeroForce()
    dyn = RigidVerlet(atoms, 1 * units.fs, bodies="tags", trajectory=str(tmp_path / "md.traj"),
                      loginterval=5)
    dyn.run(10)
    assert to_universe(dyn).trajectory.n_frames == 3  # one time step: taken
    dyn.set_timestep(2 * units.fs)
    dyn.run(10)
    with pytest.raises(ValueError, match=r"^run: the dynamics' time step is 2 fs, but its "
                                         r"trajectory '.*md.traj' was started at 1 fs"):
        to_universe(dyn)


def test_an_xtc_is_read_with_its_topology(tmp_path):
    """``to_universe("md.xtc")`` failed with only ``UnknownFileTypeError: 'xtc'``."""
    with MDAWriter(water_frames(1)[0], tmp_path / "md.xtc") as writer:
        writer.write()
    with pytest.raises(ValueError, match=r"^run: '.*md.xtc' holds coordinates only .* "
                                         r"MDAnalysis.Universe\('.*md.psf', '.*md.xtc'\)"):
        to_universe(tmp_path / "md.xtc")


@pytest.mark.parametrize("name", ["", "MY WAT", "WATERMOLECULE", 3])
def test_a_water_resname_a_psf_cannot_hold_is_refused(tmp_path, name):
    """"" shifted the columns of a PSF written from the Universe (24 residues read back, the
    masses as charges) and "MY WAT" made it unreadable; write_psf refuses such names from
    any Universe, nothing written."""
    with pytest.raises(ValueError, match=r"^water_resname"):
        to_universe(water_frames(1)[0], water_resname=name)
    if name in ("", "MY WAT"):
        u = to_universe(water_frames(1)[0])
        u.residues.resnames = [name] * len(u.residues)
        with pytest.raises(ValueError, match=rf"^write_psf .*the residue name '{name}' is "
                                             "empty or holds a blank"):
            write_psf(u, tmp_path / "md.psf")
        assert not (tmp_path / "md.psf").exists()
