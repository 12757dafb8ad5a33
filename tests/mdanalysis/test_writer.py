"""Streaming a dynamics to XTC/DCD with whole molecules (rigidmd.mdanalysis.writer).
"""

from pathlib import Path

import numpy as np
import pytest

mda = pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')
from ase import units
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.tip3p import TIP3P
from ase.io import read
from helpers import ZeroForce, assert_whole_waters, water_frames

from rigidmd import RigidVerlet
from rigidmd.lammps import tip3p_charges
from rigidmd.mdanalysis import PS, MDAWriter

pytestmark = pytest.mark.filterwarnings(
    "ignore:DCDReader currently makes independent timesteps:DeprecationWarning")

DATA = Path(__file__).resolve().parents[1] / "data"


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
