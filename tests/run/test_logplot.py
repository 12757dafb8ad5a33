"""Reading and plotting an MD log (rigidmd.run.logplot)."""


import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from ase.md import MDLogger

from rigidmd import RigidVerlet
from rigidmd.core.logger import RigidLogger
from rigidmd.run.logplot import LogError, plot_log, read_log, temperature_curves
from rigidmd.systems import water_cluster


def write_log(path, logger=RigidLogger, steps=4):
    atoms = water_cluster(3, seed=1)
    atoms.calc = TIP3P()
    dyn = RigidVerlet(atoms, 1 * units.fs)
    with open(path, "w") as fh:
        dyn.attach(logger(dyn, fh) if logger is RigidLogger else logger(dyn, atoms, fh),
                   interval=1)
        dyn.run(steps)
    return dyn


def test_a_rigid_log_is_read_by_column(tmp_path):
    dyn = write_log(tmp_path / "md.log")
    columns = read_log(tmp_path / "md.log")
    assert np.allclose(columns["Time[ps]"], np.arange(5) * units.fs / (1000 * units.fs),
                       atol=1e-4)
    assert columns["Epot[eV]"][-1] == pytest.approx(dyn.atoms.get_potential_energy(), abs=1e-6)
    assert [label for label, _ in temperature_curves(columns)] == [
        "T", "T_tr (translation)", "T_rot (rotation)"]


def test_a_line_cut_short_is_left_out_and_the_columns_kept(tmp_path):
    """The last line of a killed run's log may be cut mid-number: before, every row was cut
    to it, the energy columns went, and ``rigidmd plot`` ended in a KeyError."""
    write_log(tmp_path / "md.log")
    with open(tmp_path / "md.log", "a") as fh:
        fh.write("0.0050  -0.51")
    columns = read_log(tmp_path / "md.log")
    assert "Epot[eV]" in columns and "T_rot[K]" in columns
    assert len(columns["Time[ps]"]) == 5  # the five whole lines
    plot_log(tmp_path / "md.log", tmp_path / "md.png")
    assert (tmp_path / "md.png").stat().st_size > 0


def test_ases_log_has_one_temperature(tmp_path):
    write_log(tmp_path / "ase.log", logger=MDLogger)
    columns = read_log(tmp_path / "ase.log")
    assert [label for label, _ in temperature_curves(columns)] == ["T"]


def test_what_is_not_a_log_is_named(tmp_path):
    (tmp_path / "empty.log").write_text("\n")
    (tmp_path / "binary.npz").write_bytes(b"PK\x03\x04\0\0\0")
    (tmp_path / "other.log").write_text("a b\n1 2\n")
    with pytest.raises(LogError, match="empty.log holds no MD log lines"):
        read_log(tmp_path / "empty.log")
    with pytest.raises(LogError, match="binary.npz is not an MD log but a binary file"):
        read_log(tmp_path / "binary.npz")
    with pytest.raises(LogError, match=r"other.log is not an MD log \(no Time\[ps\] column\)"):
        read_log(tmp_path / "other.log")


def test_the_plot_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    write_log(tmp_path / "md.log")
    plot_log(tmp_path / "md.log", tmp_path / "md.png", title="three waters")
    assert (tmp_path / "md.png").read_bytes()[:4] == b"\x89PNG"
