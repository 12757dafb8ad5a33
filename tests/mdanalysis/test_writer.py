"""Streaming a dynamics to XTC/DCD with whole molecules (rigidmd.mdanalysis.writer).
"""

import os
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


# ---------------------------------------------------------------------------- refusals


def _shifted_box(shift, molecule_shift=0.0):
    """27 waters (81 atoms: compressed XTC) moved by ``shift`` Å, the second by
    ``molecule_shift`` more."""
    from rigidmd.systems import water_box

    atoms = water_box(3)
    atoms.positions += shift
    atoms.positions[3:6] += molecule_shift
    return atoms


def test_an_xtc_coordinate_beyond_the_precision_is_refused(tmp_path):
    """XTC stores round(x[nm] * 10**precision) as 32-bit integers: at precision=7 a molecule
    2500 Å out (an unwrapped run) was written as garbage (read back 4650 Å off), with only
    "Internal overflow compressing coordinates." on stderr."""
    path = tmp_path / "md.xtc"
    with pytest.raises(ValueError, match=r"^MDAWriter precision: atom \d+ is at z = 2507.\d+ Å, "
                                         r"beyond the ±2147.48 Å that XTC holds at precision=7 "
                                         r".*lower the precision \(precision=6 holds it\)"):
        MDAWriter(_shifted_box(2500.0), path, precision=7).write()
    # Nothing of the frame is written (the topology goes with the first frame).
    assert not path.exists() and not (tmp_path / "md.psf").exists()
    # Each coordinate within the limit, but a spread along z beyond it overflows too.
    with pytest.raises(ValueError, match=r"atoms 1 and 5 are 2164.\d+ Å apart along z, beyond "
                                         r"the 2147.48 Å span"):
        MDAWriter(_shifted_box(-1000.0, 2160.0), path, precision=7).write()
    assert not path.exists()
    # The same frames one decimal coarser, and frames just inside the limit, read back.
    for atoms, precision in ((_shifted_box(2500.0), 6), (_shifted_box(-1000.0, 2130.0), 7)):
        with MDAWriter(atoms, path, precision=precision, overwrite=True) as writer:
            writer.write()
        u = mda.Universe(str(tmp_path / "md.psf"), str(path))
        # float32 near 2500 Å is 2.4e-4 Å apart; measured 3.6e-4 Å at most.
        assert np.abs(u.atoms.positions - atoms.positions).max() < 1e-3
    # Up to 9 atoms XTC stores floats: no integer limit.
    small = _shifted_box(2500.0)[:9]
    with MDAWriter(small, tmp_path / "small.xtc", precision=7) as writer:
        writer.write()
    u = mda.Universe(str(tmp_path / "small.psf"), str(tmp_path / "small.xtc"))
    np.testing.assert_allclose(u.atoms.positions, small.positions, atol=1e-3)  # float32


def _xtc(path):
    u = mda.Universe(str(path.with_suffix(".psf")), str(path))
    return [(round(ts.time, 6), int(ts.data["step"])) for ts in u.trajectory]


def test_append_refuses_another_system_and_goes_on_in_time(tmp_path):
    """append=True took 81-atom frames after 24-atom ones (MDAnalysis then read 24 atoms of
    every frame), and with Atoms as the source the times and steps began again at 0."""
    from rigidmd.systems import water_box

    path = tmp_path / "md.xtc"
    with MDAWriter(water_box(2), path, dt=0.5) as writer:
        writer.write()
        writer.write()
    size = path.stat().st_size
    with pytest.raises(ValueError, match=r"^append: '.*md.xtc' holds frames of 24 atoms, the "
                                         "atoms written are 81"):
        MDAWriter(water_box(3), path, append=True)
    assert path.stat().st_size == size
    with MDAWriter(water_box(2), path, dt=0.5, append=True) as writer:
        writer.write()
        writer.write()
    assert _xtc(path) == [(0.0, 0), (0.5, 1), (1.0, 2), (1.5, 3)]
    # The topology kept on append must be this system's too.
    with MDAWriter(water_box(3), tmp_path / "big.xtc") as writer:
        writer.write()
    with pytest.raises(ValueError, match=r"^append: the topology '.*big.psf' kept for the "
                                         "continued trajectory has 81 atoms, the atoms written "
                                         "are 24"):
        MDAWriter(water_box(2), tmp_path / "new.xtc", topology=tmp_path / "big.psf",
                  append=True)
    assert not (tmp_path / "new.xtc").exists()


@pytest.mark.parametrize("damage", ["cut", "tail", "first"])
def test_append_refuses_a_trajectory_whose_last_frame_is_incomplete(tmp_path, damage):
    """A run killed while writing leaves part of a frame; frames appended after it made the
    whole file unreadable ("XTC couldn't calculate offsets").  The refusal says how to cut
    the file back, and that works."""
    from rigidmd.systems import water_box

    atoms = water_box(2)
    path = tmp_path / "md.xtc"
    with MDAWriter(atoms, path) as writer:
        writer.write()
    frame = path.stat().st_size  # 212 bytes for 24 atoms
    with MDAWriter(atoms, path, overwrite=True) as writer:
        for _ in range(3):
            writer.write()
    if damage == "cut":  # half of the last frame
        os.truncate(path, 3 * frame - 50)
        whole = 2
    elif damage == "tail":  # the start of a fourth frame's header
        with open(path, "ab") as fh:
            fh.write(b"\x00\x00\x07\xcb\x00")
        whole = 3
    else:  # the first frame cut in its header
        os.truncate(path, 10)
        whole = 0
    size = path.stat().st_size
    with pytest.raises(ValueError, match=rf"^append: the last frame of '.*md.xtc' is incomplete "
                                         rf".*its {whole} whole frames with "
                                         rf"os.truncate\('.*md.xtc', {whole * frame}\)"):
        MDAWriter(atoms, path, append=True)
    assert path.stat().st_size == size
    os.truncate(path, whole * frame)  # as the message says
    with MDAWriter(atoms, path, append=True) as writer:
        writer.write()
    assert _xtc(path) == [(float(k), k) for k in range(whole + 1)]


def test_small_frames_are_appended_too(tmp_path):
    """Up to 9 atoms an XTC frame holds floats (a header of another length)."""
    from rigidmd.systems import water_box

    path = tmp_path / "md.xtc"
    with MDAWriter(water_box(1), path, dt=0.5) as writer:
        writer.write()
        writer.write()
    with MDAWriter(water_box(1), path, dt=0.5, append=True) as writer:
        writer.write()
    assert _xtc(path) == [(0.0, 0), (0.5, 1), (1.0, 2)]


def test_existing_files_are_replaced_only_when_asked(tmp_path):
    """MDAWriter(atoms, "system.xtc") replaced a system.psf of one's own without a word."""
    atoms = water_frames(1)[0]
    own = tmp_path / "system.psf"
    own.write_text("PSF\n\n       1 !NTITLE\n REMARKS my own topology\n")
    with pytest.raises(FileExistsError, match=r"^MDAWriter topology: '.*system.psf' exists; "
                                              "give overwrite=True"):
        MDAWriter(atoms, tmp_path / "system.xtc")
    assert own.read_text().endswith("my own topology\n")
    assert not (tmp_path / "system.xtc").exists()
    (tmp_path / "md.xtc").write_bytes(b"not mine to replace")
    with pytest.raises(FileExistsError, match=r"^MDAWriter filename: '.*md.xtc' exists"):
        MDAWriter(atoms, tmp_path / "md.xtc")
    with pytest.raises(ValueError, match="give one of the two"):
        MDAWriter(atoms, tmp_path / "md.xtc", append=True, overwrite=True)
    with MDAWriter(atoms, tmp_path / "system.xtc", overwrite=True) as writer:
        writer.write()
    assert len(mda.Universe(str(own), str(tmp_path / "system.xtc")).residues) == 8


@pytest.mark.parametrize("name, topology, match", [
    ("", "md.psf", "without blanks"),
    ("MY WAT", "md.psf", "without blanks"),
    ("WATERMOLECULE", "md.psf", "has 13 characters; a PSF topology .* holds 8"),
    ("WATER", "md.pdb", "has 5 characters; a PDB topology .* holds 4"),
    ("WATERS", "md.gro", "has 6 characters; a GRO topology .* holds 5"),
])
def test_a_water_resname_the_topology_cannot_hold_is_refused(tmp_path, name, topology, match):
    """"" shifted the PSF's columns (24 residues read back, the masses as charges), "MY WAT"
    made it unreadable, and PDB and GRO cut long names without a word."""
    with pytest.raises(ValueError, match=rf"^water_resname.*{match}"):
        MDAWriter(water_frames(1)[0], tmp_path / "md.xtc", topology=tmp_path / topology,
                  water_resname=name)
    assert not any(tmp_path.iterdir())
    with MDAWriter(water_frames(1)[0], tmp_path / "md.xtc", water_resname="WATERMOL") as writer:
        writer.write()
    u = mda.Universe(str(tmp_path / "md.psf"), str(tmp_path / "md.xtc"))
    assert set(u.residues.resnames) == {"WATERMOL"} and len(u.residues) == 8
