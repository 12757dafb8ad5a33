r"""MDAnalysis interoperability and rigid-water analyses.

This module makes a rigid-body run one call away from `MDAnalysis
<https://www.mdanalysis.org>`_:

* :func:`to_universe` builds an :class:`MDAnalysis.core.universe.Universe`
  from a list of :class:`ase.Atoms`, an ASE trajectory file (``.traj``) or a
  :class:`~rigidmd.RigidVerlet` (or thermostat) object.  Rigid bodies become
  residues; atoms carry names, types, elements, masses and charges; bonds
  inside bodies are present; cell dimensions and times (ps) are set.
* :class:`MDAWriter` is an observer for ``dyn.attach(writer, interval=...)``
  that streams frames to an XTC or DCD trajectory (topology written once, as
  PSF by default), molecules kept whole.
* :class:`RadialDistribution`, :class:`MeanSquaredDisplacement` and
  :class:`RotationalCorrelation` are thin layers over MDAnalysis's analysis
  framework (``run()`` returns the analysis, results live in ``.results``,
  ``plot(path)`` saves a PNG): the O–O radial distribution function, the
  mean-squared displacement with a diffusion coefficient, and the
  rotational correlation :math:`C_\ell(t) = \langle P_\ell(\mathbf u(0)\cdot
  \mathbf u(t))\rangle` (:math:`\ell = 1, 2`) of a molecular axis with its
  relaxation times.

MDAnalysis is an optional dependency (``pip install "rigidmd[analysis]"``).
This module imports without it; every function and class raises an
:class:`ImportError` saying how to install it when it is used.

Conventions.  Residue names: water (one O and two H) is ``"SOL"`` (GROMACS's
name; change it with ``water_resname``), CO₂ is ``"CO2"``, a single atom is
its element in capitals (``"NA"``, ``"CL"``), any other body is its chemical
formula (Hill order).  Water atoms are named ``OW``, ``HW1``, ``HW2``; other
atoms by element, numbered within the residue when the element repeats
(``C``, ``O1``, ``O2``).  Types are the element symbols.  Lengths are Å, times
ps (MDAnalysis's units), diffusion coefficients Å²/ps (also given in cm²/s;
1 Å²/ps = 1e-4 cm²/s).  In ASE time units one picosecond is
``1000 * ase.units.fs`` (:data:`PS`).
"""

import os
import warnings
import weakref
from pathlib import Path

import numpy as np
from ase import Atoms, units
from ase.formula import Formula
from ase.geometry import cell_to_cellpar

from rigidmd import quaternion as quat
from rigidmd.bodies import RigidBodies

try:  # MDAnalysis is optional: everything below checks for it when used.
    import MDAnalysis as mda
    from MDAnalysis.analysis.base import AnalysisBase
    from MDAnalysis.analysis.rdf import InterRDF
    from MDAnalysis.lib.distances import minimize_vectors
except ImportError as _error:  # pragma: no cover - exercised in a subprocess test
    mda = None
    _IMPORT_ERROR = _error

    class AnalysisBase:
        """Placeholder used when MDAnalysis is missing; using it raises ImportError."""

        def __init__(self, *args, **kwargs):
            _require_mdanalysis()

    InterRDF = AnalysisBase
    minimize_vectors = None
else:
    _IMPORT_ERROR = None

__all__ = [
    "PS",
    "to_universe",
    "write_psf",
    "MDAWriter",
    "RadialDistribution",
    "MeanSquaredDisplacement",
    "RotationalCorrelation",
    "mean_squared_displacement",
    "orientational_correlation",
    "relaxation_time",
    "body_dipole_directions",
]

#: One picosecond in ASE time units.
PS = 1000.0 * units.fs

#: Å²/ps expressed in cm²/s.
ANGSTROM2_PER_PS_IN_CM2_PER_S = 1e-4

_INSTALL_HINT = (
    'rigidmd.mdanalysis needs MDAnalysis; install it with pip install "rigidmd[analysis]"'
)


def _require_mdanalysis():
    """Raise a helpful ImportError if MDAnalysis is not installed."""
    if mda is None:
        raise ImportError(_INSTALL_HINT) from _IMPORT_ERROR


# ============================================================================
# Topology: bodies -> residues
# ============================================================================


class _Topology:
    """Per-atom and per-residue labels of a system, built once from one frame.

    Attributes
    ----------
    n_atoms, n_residues : int
    resindex : numpy.ndarray of int, shape (n_atoms,)
        Residue of every atom; residues are numbered in order of their first atom.
    resnames : numpy.ndarray of str, shape (n_residues,)
    names, types, elements : numpy.ndarray of str, shape (n_atoms,)
    masses : numpy.ndarray, shape (n_atoms,)
        amu.
    charges : numpy.ndarray, shape (n_atoms,)
        e.
    bonds : numpy.ndarray of int, shape (n_bonds, 2)
        Atom index pairs ``i < j`` inside one body.
    bodies : RigidBodies
    numbers : numpy.ndarray of int, shape (n_atoms,)
        Atomic numbers, to check later frames against.
    """

    def __init__(self, atoms, bodies, charges=None, water_resname="SOL"):
        n = len(atoms)
        if n == 0:
            raise ValueError("cannot build a topology for zero atoms")
        rigid = RigidBodies.resolve(atoms, bodies)
        self.bodies = rigid
        self.n_atoms = n
        self.numbers = atoms.numbers.copy()
        self.resindex = _residue_index(rigid.body_ids)
        self.n_residues = int(self.resindex.max()) + 1
        symbols = np.array(atoms.get_chemical_symbols(), dtype=object)
        self.elements = symbols.astype(str)
        self.types = self.elements.copy()
        self.masses = atoms.get_masses().astype(float)
        self.charges = _charges(atoms, charges)
        self.resnames, water = _residue_names(self.resindex, atoms.numbers, water_resname)
        self.names = _atom_names(self.resindex, atoms.numbers, symbols, water)
        self.bonds = _body_bonds(atoms, rigid.body_ids)

    def universe(self):
        """An MDAnalysis Universe with this topology and no coordinates yet."""
        u = mda.Universe.empty(self.n_atoms, n_residues=self.n_residues,
                               atom_resindex=self.resindex, trajectory=False)
        u.add_TopologyAttr("names", self.names)
        u.add_TopologyAttr("types", self.types)
        u.add_TopologyAttr("elements", self.elements)
        u.add_TopologyAttr("masses", self.masses)
        u.add_TopologyAttr("charges", self.charges)
        u.add_TopologyAttr("resids", np.arange(1, self.n_residues + 1))
        u.add_TopologyAttr("resnames", self.resnames)
        u.add_TopologyAttr("segids", ["SYS"])
        u.add_TopologyAttr("bonds", [tuple(b) for b in self.bonds.tolist()])
        return u

    def check(self, atoms, where):
        """Raise ValueError if ``atoms`` is not the system this topology describes."""
        if len(atoms) != self.n_atoms:
            raise ValueError(
                f"{where} has {len(atoms)} atoms, the first frame has {self.n_atoms}; "
                "all frames must hold the same atoms"
            )
        if not np.array_equal(atoms.numbers, self.numbers):
            i = int(np.flatnonzero(atoms.numbers != self.numbers)[0])
            raise ValueError(
                f"{where}: atom {i} is element {atoms.numbers[i]}, "
                f"in the first frame {self.numbers[i]}; all frames must hold the same atoms"
            )


def _residue_index(body_ids):
    """Residue of every atom: one per body, one per free atom, in order of first atom."""
    ids = np.asarray(body_ids, dtype=np.int64).copy()
    free = ids < 0
    ids[free] = ids.max(initial=-1) + 1 + np.arange(int(free.sum()))
    _, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inverse.ravel()]


def _charges(atoms, charges):
    if charges is None:
        if atoms.has("initial_charges"):
            return atoms.get_initial_charges().astype(float)
        return np.zeros(len(atoms))
    q = np.asarray(charges, dtype=float)
    if q.shape != (len(atoms),):
        raise ValueError(
            f"charges: expected one charge per atom ({len(atoms)}), got shape {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        raise ValueError("charges must be finite")
    return q


def _residue_names(resindex, numbers, water_resname):
    """Residue names from compositions (vectorised over residues), and a water mask."""
    n_res = int(resindex.max()) + 1
    elements, column = np.unique(numbers, return_inverse=True)
    counts = np.zeros((n_res, len(elements)), dtype=np.int64)
    np.add.at(counts, (resindex, column.ravel()), 1)
    compositions, which = np.unique(counts, axis=0, return_inverse=True)
    from ase.data import chemical_symbols

    names = []
    is_water = []
    for row in compositions:
        comp = {chemical_symbols[z]: int(c) for z, c in zip(elements, row, strict=True) if c}
        water = comp == {"O": 1, "H": 2}
        is_water.append(water)
        if water:
            names.append(water_resname)
        elif sum(comp.values()) == 1:
            names.append(next(iter(comp)).upper())
        else:
            names.append(Formula.from_list(
                [s for s, c in comp.items() for _ in range(c)]).format("hill"))
    which = which.ravel()
    return np.array(names, dtype=object)[which].astype(str), np.array(is_water)[which]


def _atom_names(resindex, numbers, symbols, water):
    """Atom names: OW/HW1/HW2 in water, else element plus a number if it repeats."""
    n = len(numbers)
    key = resindex * 256 + numbers
    order = np.lexsort((np.arange(n), key))
    sorted_key = key[order]
    new = np.r_[True, sorted_key[1:] != sorted_key[:-1]]
    group = np.cumsum(new) - 1
    starts = np.flatnonzero(new)
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n) - starts[group]
    multiplicity = np.empty(n, dtype=np.int64)
    multiplicity[order] = np.diff(np.r_[starts, n])[group]
    names = np.array([s + (str(k + 1) if m > 1 else "")
                      for s, k, m in zip(symbols, rank, multiplicity, strict=True)], dtype=object)
    in_water = water[resindex]
    names[in_water & (numbers == 8)] = "OW"
    hw = in_water & (numbers == 1)
    names[hw] = np.char.add("HW", (rank[hw] + 1).astype(str))
    return names.astype(str)


def _body_bonds(atoms, body_ids):
    """Covalent bonds (natural cut-offs, minimum image) between atoms of the same body."""
    from ase.neighborlist import natural_cutoffs, neighbor_list

    if not np.any(body_ids >= 0):
        return np.zeros((0, 2), dtype=np.int64)
    i, j = neighbor_list("ij", atoms, natural_cutoffs(atoms))
    keep = (i < j) & (body_ids[i] == body_ids[j]) & (body_ids[i] >= 0)
    pairs = np.stack([i[keep], j[keep]], axis=1)
    return np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), dtype=np.int64)


def _dimensions(atoms):
    """``[a, b, c, alpha, beta, gamma]`` (Å, degrees) or None without a full cell."""
    if atoms.cell.rank < 3:
        return None
    return cell_to_cellpar(atoms.cell.array)


def _whole(atoms, rigid):
    """Positions with every body whole (Å), shape (n_atoms, 3)."""
    if atoms.pbc.any() and rigid.n_bodies:
        return rigid.whole_positions(atoms)
    return atoms.positions.copy()


# ============================================================================
# Universe builder
# ============================================================================


def _is_dynamics(obj):
    return (not isinstance(obj, Atoms) and hasattr(obj, "atoms") and hasattr(obj, "bodies")
            and hasattr(obj, "get_time"))


def _read_traj(path, index):
    """Frames of a trajectory file and, for an ASE ``.traj``, the time between frames (ps)."""
    from ase.io import read
    from ase.io.formats import string2index

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no trajectory file {str(path)!r}")
    frames = read(path, index=index)
    frames = [frames] if isinstance(frames, Atoms) else list(frames)
    dt = None
    if path.suffix == ".traj":
        from ase.io.trajectory import Trajectory

        with Trajectory(path) as traj:
            desc = getattr(traj, "description", None) or {}
        if "timestep" in desc and "interval" in desc:
            selection = string2index(index) if isinstance(index, str) else index
            stride = selection.step if isinstance(selection, slice) and selection.step else 1
            dt = float(desc["timestep"]) * int(desc["interval"]) * stride / PS
    return frames, dt


def to_universe(run, *, bodies=None, charges=None, dt=None, index=":", water_resname="SOL"):
    """Build an MDAnalysis Universe from a run.

    Parameters
    ----------
    run : ase.Atoms, sequence of ase.Atoms, str or os.PathLike, or RigidVerlet
        What to convert:

        * one :class:`ase.Atoms` or a list of frames (same atoms in every frame);
        * a trajectory file that :func:`ase.io.read` reads, e.g. the ``.traj``
          written by ``RigidVerlet(..., trajectory=...)``;
        * a :class:`~rigidmd.RigidVerlet` (or a thermostat): the frames of its
          trajectory file if it writes one, else its current state as one
          frame; its bodies are used.
    bodies : optional
        Which atoms form a body (a residue), as for :class:`~rigidmd.RigidVerlet`
        (default: covalent connectivity of the first frame; ignored for a
        dynamics object, whose own bodies are used).  Atoms in no body are
        residues of their own.  Connectivity can join two molecules that
        came closer than a covalent bond (a hot or freshly quenched liquid):
        for ``.traj`` files prefer ``"tags"`` (tags survive in ``.traj``,
        ``mol-id`` does not) or pass the bodies.
    charges : array_like, shape (n_atoms,), optional
        Atomic charges (e).  Default: the first frame's initial charges (zero
        if unset).
    dt : float, optional
        Time between frames (ps).  Default: from the ``.traj`` header of a
        file written by ASE molecular dynamics (time step × trajectory
        interval × the stride of ``index``); otherwise 1 ps (MDAnalysis's
        default).
    index : str or slice, default ":"
        Which frames of a trajectory file to read (as :func:`ase.io.read`).
    water_resname : str, default "SOL"
        Residue name of water molecules.

    Returns
    -------
    MDAnalysis.Universe
        In-memory coordinates (:class:`~MDAnalysis.coordinates.memory.MemoryReader`,
        float32, Å) with every body whole, dimensions per frame (``None``
        when a frame has no full cell), times in ps.  Residues are numbered from
        1 in order of their first atom.

    Raises
    ------
    ImportError
        MDAnalysis is not installed.
    ValueError
        No frames, frames with different atoms, charges of the wrong shape, or
        a body definition that does not fit the atoms.
    """
    _require_mdanalysis()
    time_offset = 0.0
    if _is_dynamics(run):
        dyn = run
        bodies = dyn.bodies
        traj = getattr(dyn, "trajectory", None)
        if isinstance(traj, (str, os.PathLike)) and Path(traj).exists():
            frames, file_dt = _read_traj(traj, index)
        else:
            frames = [dyn.atoms]
            file_dt = float(dyn.dt) / PS
            time_offset = float(dyn.get_time()) / PS
        dt = file_dt if dt is None else dt
    elif isinstance(run, (str, os.PathLike)):
        frames, file_dt = _read_traj(run, index)
        dt = file_dt if dt is None else dt
    elif isinstance(run, Atoms):
        frames = [run]
    else:
        frames = list(run)
        bad = [k for k, f in enumerate(frames) if not isinstance(f, Atoms)]
        if bad:
            raise TypeError(f"frame {bad[0]} is a {type(frames[bad[0]]).__name__}, not ase.Atoms")
    if not frames:
        raise ValueError("no frames to convert")
    dt = 1.0 if dt is None else float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive time in ps, got {dt!r}")

    topo = _Topology(frames[0], bodies, charges=charges, water_resname=water_resname)
    coords = np.empty((len(frames), topo.n_atoms, 3), dtype=np.float32)
    dims = np.zeros((len(frames), 6), dtype=np.float32)
    for k, atoms in enumerate(frames):
        topo.check(atoms, f"frame {k}")
        coords[k] = _whole(atoms, topo.bodies)
        box = _dimensions(atoms)
        if box is not None:
            dims[k] = box
    from MDAnalysis.coordinates.memory import MemoryReader

    u = topo.universe()
    u.load_new(coords, format=MemoryReader, dimensions=dims, dt=dt, time_offset=time_offset)
    return u


# ============================================================================
# PSF topology file
# ============================================================================


def write_psf(universe, path, title="written by rigidmd.mdanalysis"):
    """Write a PSF topology (NAMD/VMD space-separated flavour) that MDAnalysis reads.

    The file carries segment, residue ids and names, atom names, types,
    charges (e), masses (amu) and bonds; no angles or dihedrals (rigid bodies
    need none).  Atoms of one residue should be contiguous: readers split
    residues where the residue id changes.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
        With names, types, resnames, charges, masses and (optionally) bonds.
    path : str or os.PathLike
    title : str
        One-line remark.
    """
    _require_mdanalysis()
    ag = universe.atoms
    n = len(ag)
    segids = ag.segids if hasattr(ag, "segids") else np.full(n, "SYS")
    lines = ["PSF EXT NAMD", "", f"{1:10d} !NTITLE", f" REMARKS {title}", "",
             f"{n:10d} !NATOM"]
    for i, (seg, resid, resname, name, typ, q, m) in enumerate(zip(
            segids, ag.resids, ag.resnames, ag.names, ag.types, ag.charges, ag.masses,
            strict=True)):
        lines.append(f"{i + 1:10d} {seg:<8s} {resid:<8d} {resname:<8s} {name:<8s} "
                     f"{typ:<6s} {q:14.6f} {m:13.4f} {0:11d}")
    bonds = np.asarray(ag.bonds.to_indices()) + 1 if hasattr(ag, "bonds") else np.zeros((0, 2))
    lines += ["", f"{len(bonds):10d} !NBOND: bonds"]
    flat = bonds.reshape(-1).astype(int)
    for start in range(0, len(flat), 8):  # four pairs per line
        lines.append("".join(f"{a:10d}" for a in flat[start:start + 8]))
    for label in ("NTHETA: angles", "NPHI: dihedrals", "NIMPHI: impropers", "NDON: donors",
                  "NACC: acceptors"):
        lines += ["", f"{0:10d} !{label}"]
    Path(path).write_text("\n".join(lines) + "\n\n")


# ============================================================================
# Streaming writer
# ============================================================================


def _drop_offset_cache(path):
    """Remove MDAnalysis's cached frame offsets of a file about to be overwritten."""
    for suffix in ("_offsets.npz", "_offsets.lock"):
        Path(path).with_name(f".{Path(path).name}{suffix}").unlink(missing_ok=True)


class _Handle:
    """Owns the open file or writer so that a finaliser can close it without the observer."""

    def __init__(self):
        self.writer = None
        self.scratch = None

    def close(self):
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        if self.scratch is not None:
            self.scratch.unlink(missing_ok=True)
            self.scratch = None


class MDAWriter:
    r"""Stream frames of a run to an XTC or DCD trajectory that MDAnalysis reads.

    Use it as an observer::

        dyn = RigidVerlet(atoms, 2 * units.fs)
        with MDAWriter(dyn, "md.xtc") as writer:      # topology: md.psf
            dyn.attach(writer, interval=10)
            dyn.run(5000)
        u = MDAnalysis.Universe("md.psf", "md.xtc")

    Every call writes the current positions of the atoms with each body whole
    (the dynamics already keeps molecules whole and unwrapped: their centres
    may leave the cell, atoms are never wrapped one by one), the cell, the
    time (ps) and the step.  The topology is written once, at the first frame.
    Frames written are kept if the run stops with an exception: close the
    writer (``with`` does) and the file is readable up to the last frame.  A
    writer left open is closed when the interpreter exits.

    Parameters
    ----------
    source : RigidVerlet or ase.Atoms
        A dynamics object (its atoms, bodies, time and step are used) or the
        Atoms to write (then frame ``k`` is at time ``k * dt`` and step ``k``).
    filename : str or os.PathLike
        Trajectory file; the format follows the extension: ``.xtc`` (GROMACS
        compressed, ``precision`` decimals in nm) or ``.dcd`` (CHARMM/NAMD,
        float32, evenly spaced frames).
    topology : str or os.PathLike, optional
        Topology file written at the first frame; default ``filename`` with
        the extension ``.psf``.  ``.psf`` is written by :func:`write_psf`
        (charges, masses, bonds, residues); ``.pdb`` and ``.gro`` by MDAnalysis
        from the first frame (PDB keeps bonds as CONECT records, not charges).
    bodies : optional
        Body definition when ``source`` is Atoms (see :func:`to_universe`).
    charges : array_like, shape (n_atoms,), optional
        Charges (e) for the topology; default the initial charges.
    dt : float, default 1.0
        Time between frames (ps) when ``source`` is Atoms.
    precision : int, default 4
        XTC precision: decimal places in nm (4 → 1e-3 Å resolution; GROMACS
        uses 3, 1e-2 Å).
    water_resname : str, default "SOL"

    Attributes
    ----------
    n_frames : int
        Frames written so far.
    filename, topology_filename : pathlib.Path
    universe : MDAnalysis.Universe
        A one-frame in-memory Universe holding the topology and the last frame.

    Notes
    -----
    DCD stores a start step, a time step and a frame interval in its header
    instead of a time per frame, so the file is opened at the second frame
    (the first is held until then, or written at :meth:`close`).  Frames
    must be evenly spaced; a warning says when they are not.
    """

    _FORMATS = ("XTC", "DCD")
    #: An observer that only reads the atoms (the dynamics need not look for changes).
    modifies_atoms = False

    def __init__(self, source, filename, topology=None, *, bodies=None, charges=None, dt=1.0,
                 precision=4, water_resname="SOL", append=False):
        _require_mdanalysis()
        if _is_dynamics(source):
            self.dynamics, atoms, bodies = source, source.atoms, source.bodies
        elif isinstance(source, Atoms):
            self.dynamics, atoms = None, source
        else:
            raise TypeError("source must be a rigidmd dynamics object or ase.Atoms, "
                            f"got {type(source).__name__}")
        self.filename = Path(filename)
        self.format = self.filename.suffix.lstrip(".").upper()
        if self.format not in self._FORMATS:
            raise ValueError(
                f"MDAWriter writes .xtc or .dcd trajectories, not {self.filename.suffix!r}"
            )
        self.topology_filename = (self.filename.with_suffix(".psf") if topology is None
                                  else Path(topology))
        if self.topology_filename.suffix.lower() not in (".psf", ".pdb", ".gro"):
            raise ValueError(
                f"topology must be a .psf, .pdb or .gro file, got {str(self.topology_filename)!r}"
            )
        if self.topology_filename.resolve() == self.filename.resolve():
            raise ValueError("topology and trajectory must be different files")
        self.append = bool(append)
        if self.append and self.format != "XTC":
            raise ValueError(f"MDAWriter: a {self.format} file cannot be continued (its header "
                             "counts the frames); write .xtc to append to a trajectory")
        self.dt = float(dt)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive time in ps, got {dt!r}")
        self.precision = int(precision)
        self.atoms = atoms
        self._topology = _Topology(atoms, bodies, charges=charges, water_resname=water_resname)
        self.universe = self._topology.universe()
        from MDAnalysis.coordinates.memory import MemoryReader

        self.universe.load_new(np.zeros((1, len(atoms), 3), dtype=np.float32),
                               format=MemoryReader)
        self.n_frames = 0
        self._pending = None  # DCD: first frame, held until the spacing is known
        self._spacing = None
        self._warned = False
        self._closed = False
        self._handle = _Handle()
        self._finalizer = weakref.finalize(self, self._handle.close)

    # -------------------------------------------------------------- protocol
    def __call__(self):
        """Write the current frame (the observer entry point)."""
        self.write()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return (f"MDAWriter({str(self.filename)!r}, topology={str(self.topology_filename)!r}, "
                f"n_frames={self.n_frames})")

    # -------------------------------------------------------------- writing
    def _frame(self):
        atoms = self.atoms
        self._topology.check(atoms, "the atoms")
        positions = _whole(atoms, self._topology.bodies)
        dims = _dimensions(atoms)
        if self.dynamics is not None:
            time = float(self.dynamics.get_time()) / PS
            step = int(self.dynamics.nsteps)
        else:
            time, step = self.n_frames * self.dt, self.n_frames
        return positions, dims, time, step

    def _load(self, positions, dims, time, step):
        ts = self.universe.trajectory.ts
        ts.positions = positions
        ts.dimensions = dims
        ts.time = time
        ts.data["step"] = step

    def write(self):
        """Write the current state of the atoms as the next frame.

        Raises
        ------
        ValueError
            The writer is closed, or the atoms changed in number or elements.
        """
        if self._closed:
            raise ValueError(f"{self!r} is closed")
        frame = self._frame()
        self._load(*frame)
        if self.n_frames == 0 and not (self.append and self.topology_filename.exists()):
            self._write_topology()
        if self.format == "XTC":
            self._write_xtc(*frame)
        else:
            self._write_dcd(frame)
        self.n_frames += 1

    def _write_xtc(self, positions, dims, time, step):
        """Append one whole frame: encoded through a scratch file, then written in one call.

        The file is an ordinary Python file opened for appending, flushed after
        every frame, so a killed run loses no finished frame, a continued run
        appends, and :meth:`flush` can sync it to disk for a checkpoint.
        """
        from MDAnalysis.lib.formats.libmdaxdr import XTCFile
        from MDAnalysis.lib.mdamath import triclinic_vectors

        if self._handle.writer is None:
            _drop_offset_cache(self.filename)
            self._handle.writer = open(self.filename, "ab" if self.append else "wb")
            self._handle.scratch = self.filename.with_name(f".{self.filename.name}.frame")
        box = (triclinic_vectors(dims) if dims is not None else np.zeros((3, 3))) / 10.0
        with XTCFile(str(self._handle.scratch), "w") as scratch:
            scratch.write(np.asarray(positions, dtype=np.float32) / 10.0,
                          box.astype(np.float32), int(step), float(time),
                          float(10**self.precision))
        self._handle.writer.write(self._handle.scratch.read_bytes())
        self._handle.writer.flush()

    def flush(self):
        """Make every frame written so far durable (``fsync``), e.g. before a checkpoint."""
        fh = self._handle.writer
        if fh is not None and self.format == "XTC":
            fh.flush()
            os.fsync(fh.fileno())

    def _write_topology(self):
        path = self.topology_filename
        if path.suffix.lower() == ".psf":
            write_psf(self.universe, path)
            return
        u = self.universe
        if path.suffix.lower() == ".pdb":
            n = len(u.atoms)
            for attr, value in (("altLocs", " "), ("icodes", " "), ("chainIDs", "X"),
                                ("occupancies", 1.0), ("tempfactors", 0.0),
                                ("record_types", "ATOM"), ("formalcharges", 0)):
                if not hasattr(u.atoms, attr):
                    size = len(u.residues) if attr == "icodes" else n
                    u.add_TopologyAttr(attr, [value] * size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            u.atoms.write(str(path))

    def _write_dcd(self, frame):
        positions, dims, time, step = frame
        if self._handle.writer is None and self._pending is None:
            self._pending = (positions.copy(), dims, time, step)
            return
        if self._handle.writer is None:
            first = self._pending
            self._spacing = (time - first[2], step - first[3])
            self._open_dcd(first[2], first[3], *self._spacing)
            self._load(*first)
            self._handle.writer.write(self.universe)
            self._pending = None
            self._load(*frame)
        elif not self._warned:
            expected = self._first_time + self.n_frames * self._spacing[0]
            if not np.isclose(time, expected, rtol=1e-6, atol=1e-9):
                warnings.warn(
                    f"MDAWriter: frame {self.n_frames} is at {time:.6g} ps, but DCD frames must "
                    f"be evenly spaced ({expected:.6g} ps expected); readers will report "
                    "wrong times", stacklevel=3)
                self._warned = True
        self._handle.writer.write(self.universe)

    def _open_dcd(self, t0, step0, dt_frame, dsteps):
        """Open the DCD with a header whose times reproduce ours: t = (istart + k nsavc) delta."""
        if dt_frame <= 0:
            dt_frame, dsteps = (self.dynamics.dt / PS if self.dynamics is not None
                                else self.dt), 1
        nsavc = max(int(dsteps), 1)
        delta = dt_frame / nsavc
        istart = int(round(t0 / delta)) if delta > 0 else 0
        self._first_time = t0
        _drop_offset_cache(self.filename)
        self._handle.writer = mda.Writer(str(self.filename), n_atoms=len(self.atoms),
                                         dt=dt_frame, nsavc=nsavc, istart=istart)

    def close(self):
        """Finish the file (flush a held DCD frame); further writes raise ValueError."""
        if self._closed:
            return
        if self._pending is not None:
            first = self._pending
            self._open_dcd(first[2], first[3], 0.0, 1)
            self._load(*first)
            self._handle.writer.write(self.universe)
            self._pending = None
        self._handle.close()
        self._closed = True

    @property
    def closed(self):
        return self._closed


# ============================================================================
# Shared helpers for the analyses
# ============================================================================


def _group(universe_or_group, select):
    """AtomGroup from a Universe or AtomGroup and a selection string (None: all of it)."""
    _require_mdanalysis()
    atoms = universe_or_group.atoms
    group = atoms if select is None else atoms.select_atoms(select)
    if len(group) == 0:
        raise ValueError(f"the selection {select!r} matches no atoms")
    return group


class _ResidueLayout:
    """Compact residue index of the atoms of a group, for whole-molecule arithmetic."""

    def __init__(self, group):
        _, self.index = np.unique(group.resindices, return_inverse=True)
        self.index = self.index.ravel()
        self.n = int(self.index.max()) + 1
        first = np.full(self.n, len(group), dtype=np.int64)
        np.minimum.at(first, self.index, np.arange(len(group)))
        self.first = first
        self.masses = group.masses.astype(float)
        self.mass = np.bincount(self.index, weights=self.masses, minlength=self.n)

    def whole(self, positions, box):
        """Positions (Å, shape (n_atoms, 3)) with every residue whole: each atom at its
        minimum image from the residue's first atom.  ``box`` is ``ts.dimensions``
        (None: no periodicity)."""
        x = np.asarray(positions, dtype=np.float64)
        if box is None:
            return x
        anchor = x[self.first][self.index]
        return anchor + minimize_vectors(x - anchor, np.asarray(box, dtype=np.float64))

    def centres_of_mass(self, positions):
        """Mass-weighted centre of every residue (Å), shape (n_residues, 3)."""
        x = np.asarray(positions, dtype=float)
        return np.stack([np.bincount(self.index, weights=self.masses * x[:, k],
                                     minlength=self.n) for k in range(3)], axis=1) \
            / self.mass[:, None]


def _frame_spacing(times):
    """Time between analysed frames (ps); ValueError if they are not evenly spaced.

    Trajectory formats store times in single precision, so steps may differ
    by a few float32 spacings of the largest time.
    """
    times = np.asarray(times, dtype=float)
    if len(times) < 2:
        return 1.0
    spacing = (times[-1] - times[0]) / (len(times) - 1)
    roundoff = 8 * np.finfo(np.float32).eps * max(1.0, float(np.abs(times).max()))
    if spacing <= 0 or np.abs(np.diff(times) - spacing).max() > 1e-3 * spacing + roundoff:
        raise ValueError("frames must be evenly spaced in time for a time correlation")
    return float(spacing)


def _autocorrelation(x, max_lag):
    """Multiple-origin autocorrelation of series along axis 0, summed over nothing else.

    ``x`` has shape (n_frames, ...); returns shape (max_lag + 1, ...) with
    ``c[m] = mean over t of x[t] * x[t + m]`` (all available origins).
    """
    n = x.shape[0]
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, n=size, axis=0)
    acf = np.fft.irfft(f * np.conj(f), n=size, axis=0)[:max_lag + 1]
    counts = (n - np.arange(max_lag + 1)).reshape((-1,) + (1,) * (x.ndim - 1))
    return acf / counts


def _unwrap_series(x, boxes):
    """Remove periodic jumps from trajectories of points (nojump), vectorised over points.

    ``x`` (n_frames, n, 3) Å, ``boxes`` (n_frames, 6) or None.  Each step is
    replaced by its minimum image in the box of the later frame.
    """
    if boxes is None or len(x) < 2:
        return x
    steps = np.diff(x, axis=0)
    boxes = np.asarray(boxes, dtype=float)
    if np.allclose(boxes[:, 3:], 90.0):
        lengths = boxes[1:, None, :3]
        steps = steps - lengths * np.round(steps / lengths)
    else:
        steps = np.stack([minimize_vectors(s.astype(np.float32), b.astype(np.float32))
                          for s, b in zip(steps, boxes[1:], strict=True)]).astype(float)
    return np.concatenate([x[:1], x[:1] + np.cumsum(steps, axis=0)])


def _new_figure(figsize=(5.0, 3.6)):
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def _finish(fig, path):
    if path is not None:
        fig.savefig(path, dpi=150)
    return fig


# ============================================================================
# Radial distribution function
# ============================================================================


def _first_shell(bins, rdf, cumulative):
    """First peak (position, height), first minimum and coordination number of g(r)."""
    nan = float("nan")
    above = np.flatnonzero(rdf > 1.0)
    if above.size == 0:
        return nan, nan, nan, nan
    start = above[0]
    below = np.flatnonzero(rdf[start:] < 1.0)
    stop = start + (below[0] if below.size else len(rdf) - start)
    k = start + int(np.argmax(rdf[start:stop]))
    position, height = float(bins[k]), float(rdf[k])
    if 0 < k < len(rdf) - 1:  # parabola through the three highest bins
        y0, y1, y2 = rdf[k - 1], rdf[k], rdf[k + 1]
        denom = y0 - 2 * y1 + y2
        if denom < 0:
            h = bins[1] - bins[0]
            shift = 0.5 * (y0 - y2) / denom
            position = float(bins[k] + shift * h)
            height = float(y1 - 0.25 * (y0 - y2) * shift)
    # First minimum: lowest point after the peak before g(r) climbs back above 1.
    after = np.flatnonzero(rdf[stop:] > 1.0)
    end = stop + (after[0] if after.size else len(rdf) - stop)
    if end <= stop:
        return position, height, nan, nan
    m = stop + int(np.argmin(rdf[stop:end]))
    return position, height, float(bins[m]), float(cumulative[m])


class RadialDistribution(InterRDF):
    r"""Radial distribution function between two selections, e.g. O–O in water.

    A thin layer over :class:`MDAnalysis.analysis.rdf.InterRDF`: pairs inside
    one residue (one rigid body) are excluded and the normalisation counts
    only the pairs that remain, so :math:`g(r) \to 1` at large :math:`r` for
    a selection with one atom per molecule.  After :meth:`run` the results
    also hold the first peak, the first minimum and the coordination number.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "name OW"
        First selection (water oxygens as named by :func:`to_universe`).
    select2 : str, optional
        Second selection; default the first.
    r_max : float, optional
        Largest distance (Å); default 10 Å or half the narrowest width of the
        first frame's box, whichever is smaller.  Rounded down to whole bins.
    bin_width : float, default 0.05
        Å.
    exclude_same_residue : bool, default True
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase` (e.g. ``verbose``).

    Attributes
    ----------
    results.bins : numpy.ndarray, shape (n_bins,)
        Bin centres (Å).
    results.edges : numpy.ndarray, shape (n_bins + 1,)
    results.rdf : numpy.ndarray, shape (n_bins,)
        :math:`g(r)`.
    results.count : numpy.ndarray, shape (n_bins,)
        Ordered pairs counted per bin, summed over frames.
    results.cumulative_number : numpy.ndarray, shape (n_bins,)
        Mean number of selection-2 atoms within the upper edge of each bin of
        a selection-1 atom.
    results.first_peak_position, results.first_peak_height : float
        Å and dimensionless (parabola through the highest three bins of the
        first region where :math:`g > 1`).
    results.first_minimum_position : float
        Å.
    results.coordination_number : float
        Neighbours within the first minimum.
    """

    def __init__(self, universe, select="name OW", select2=None, r_max=None, bin_width=0.05,
                 exclude_same_residue=True, **kwargs):
        g1 = _group(universe, select)
        g2 = g1 if select2 is None else _group(universe, select2)
        if r_max is None:
            r_max = 10.0
            box = g1.universe.trajectory.ts.dimensions
            if box is not None:
                from ase.cell import Cell

                cell = Cell.fromcellpar(box).array
                widths = abs(np.linalg.det(cell)) / np.linalg.norm(
                    np.cross(cell[[1, 2, 0]], cell[[2, 0, 1]]), axis=1)
                r_max = min(r_max, 0.5 * float(widths.min()))
        r_max = float(r_max)
        if not (r_max > 0 and bin_width > 0):
            raise ValueError("r_max and bin_width must be positive (Å)")
        # Whole bins of the requested width, not beyond r_max (the minimum image
        # counts every pair only up to half the box).
        nbins = max(int(np.floor(r_max / bin_width + 1e-9)), 1)
        self._exclude = bool(exclude_same_residue)
        super().__init__(g1, g2, nbins=nbins, range=(0.0, nbins * bin_width),
                         exclude_same="residue" if self._exclude else None, **kwargs)

    def _conclude(self):
        super()._conclude()
        res = self.results
        n1, n2 = len(self.g1), len(self.g2)
        if self._exclude and self.norm == "rdf":
            # Ordered pairs in different residues, instead of MDAnalysis's n1 * n2.
            r1, c1 = np.unique(self.g1.resindices, return_counts=True)
            r2, c2 = np.unique(self.g2.resindices, return_counts=True)
            _, i1, i2 = np.intersect1d(r1, r2, return_indices=True)
            pairs = n1 * n2 - float(np.sum(c1[i1] * c2[i2]))
            res.rdf = res.rdf * (n1 * n2) / pairs if pairs > 0 else res.rdf * np.nan
        res.cumulative_number = np.cumsum(res.count) / (self.n_frames * n1)
        (res.first_peak_position, res.first_peak_height, res.first_minimum_position,
         res.coordination_number) = _first_shell(res.bins, res.rdf, res.cumulative_number)

    def plot(self, path=None, label="O–O"):
        """Plot g(r) and the running coordination number; save a PNG if ``path``.

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        fig, ax = _new_figure()
        ax.plot(res.bins, res.rdf, color="C0", label=f"g(r) {label}")
        ax.axhline(1.0, color="0.7", lw=0.8)
        if np.isfinite(res.first_peak_position):
            ax.plot([res.first_peak_position], [res.first_peak_height], "o", color="C3",
                    label=f"peak {res.first_peak_position:.2f} Å, {res.first_peak_height:.2f}")
        ax.set_xlabel("r (Å)")
        ax.set_ylabel("g(r)")
        twin = ax.twinx()
        twin.plot(res.bins, res.cumulative_number, color="C2", ls="--", label="n(r)")
        twin.set_ylabel("n(r)")
        ax.legend(loc="upper right", fontsize=8)
        return _finish(fig, path)


# ============================================================================
# Mean-squared displacement
# ============================================================================


def mean_squared_displacement(x):
    r"""Multiple-origin mean-squared displacement of unwrapped trajectories (FFT).

    :math:`\mathrm{MSD}(m) = \langle |x(t+m) - x(t)|^2 \rangle_t`, averaged
    over all time origins, computed as :math:`S_1(m) - 2 S_2(m)` with
    :math:`S_2` the position autocorrelation (by FFT) and :math:`S_1` from
    cumulative sums of :math:`|x|^2`.

    Parameters
    ----------
    x : array_like, shape (n_frames, n_particles, d)
        Unwrapped positions (Å).

    Returns
    -------
    numpy.ndarray, shape (n_frames, n_particles)
        Å², lag 0 to ``n_frames - 1`` frames.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 3:
        raise ValueError(f"positions must have shape (n_frames, n_particles, d), got {x.shape}")
    n = x.shape[0]
    x = x - x.mean(axis=0)  # the MSD does not change; roundoff does
    sq = np.sum(x * x, axis=2)  # (n, p)
    cum = np.concatenate([np.zeros((1,) + sq.shape[1:]), np.cumsum(sq, axis=0)])
    m = np.arange(n)
    s1 = (cum[n - m] + cum[n] - cum[m]) / (n - m)[:, None]
    s2 = _autocorrelation(x, n - 1).sum(axis=2)
    return np.maximum(s1 - 2.0 * s2, 0.0)


class MeanSquaredDisplacement(AnalysisBase):
    r"""Mean-squared displacement and self-diffusion coefficient.

    Follows molecules by their centres of mass (``compound="residues"``, each
    residue made whole first) or single atoms (``compound="atoms"``).  The
    positions of rigidmd runs are unwrapped already; with ``unwrap=True``
    (default) any jump of more than half a box between frames is undone, so
    wrapped trajectories work too (sample often enough that nothing moves
    half a box between frames).  The diffusion coefficient comes from a
    straight-line fit :math:`\mathrm{MSD} = 2 d\, D\, t + c` over
    ``fit_range``.

    A drift of the whole system adds :math:`V_\mathrm{cm}^2 t^2` to the MSD.
    Stochastic thermostats (Langevin) leave the system with a random total
    momentum of thermal size, which over tens of picoseconds moves the centre
    by more than the molecules diffuse: zero the total momentum before the
    production run, or pass ``remove_com_motion=True``.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "all"
    compound : {"residues", "atoms"}, default "residues"
    msd_type : {"xyz", "xy", "yz", "xz", "x", "y", "z"}, default "xyz"
        Cartesian components included; :math:`d` is their number.
    unwrap : bool, default True
    remove_com_motion : bool, default False
        Subtract, frame by frame, the displacement of the mass-weighted centre
        of the selection.
    fit_range : (float, float), optional
        Lag times (ps) of the linear fit.  Default: 10 % to 40 % of the
        longest lag (the first excludes the ballistic and caging regime,
        the second the noisy long lags).
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase`.

    Attributes
    ----------
    results.lagtimes : numpy.ndarray, shape (n_frames,)
        ps.
    results.timeseries : numpy.ndarray, shape (n_frames,)
        MSD (Å²), averaged over particles.
    results.msds_by_particle : numpy.ndarray, shape (n_frames, n_particles)
        Å².
    results.diffusion_coefficient : float
        Å²/ps.
    results.diffusion_coefficient_cm2_s : float
        cm²/s.
    results.fit_range : tuple of float
        ps.
    results.fit_slope, results.fit_intercept : float
        Å²/ps and Å².
    """

    _AXES = {"xyz": [0, 1, 2], "xy": [0, 1], "yz": [1, 2], "xz": [0, 2],
             "x": [0], "y": [1], "z": [2]}

    def __init__(self, universe, select="all", compound="residues", msd_type="xyz",
                 unwrap=True, remove_com_motion=False, fit_range=None, **kwargs):
        group = _group(universe, select)
        super().__init__(group.universe.trajectory, **kwargs)
        if compound not in ("residues", "atoms"):
            raise ValueError(f"compound must be 'residues' or 'atoms', got {compound!r}")
        if msd_type not in self._AXES:
            raise ValueError(f"msd_type must be one of {sorted(self._AXES)}, got {msd_type!r}")
        self.group = group
        self.compound = compound
        self.msd_type = msd_type
        self.dim_fac = len(self._AXES[msd_type])
        self.unwrap = bool(unwrap)
        self.remove_com_motion = bool(remove_com_motion)
        self.fit_range = fit_range
        self._layout = _ResidueLayout(group) if compound == "residues" else None

    def _prepare(self):
        n = self._layout.n if self._layout is not None else len(self.group)
        self._x = np.zeros((self.n_frames, n, 3))
        self._boxes = np.zeros((self.n_frames, 6))
        self._has_box = True

    def _single_frame(self):
        box = self._ts.dimensions
        positions = self.group.positions
        if self._layout is not None:
            positions = self._layout.centres_of_mass(self._layout.whole(positions, box))
        self._x[self._frame_index] = positions
        if box is None:
            self._has_box = False
        else:
            self._boxes[self._frame_index] = box

    def _conclude(self):
        res = self.results
        spacing = _frame_spacing(self.times)
        x = self._x
        if self.unwrap and self._has_box:
            x = _unwrap_series(x, self._boxes)
        if self.remove_com_motion:
            w = self._layout.mass if self._layout is not None else self.group.masses
            centre = np.einsum("p,fpk->fk", w, x) / np.sum(w)
            x = x - (centre - centre[0])[:, None, :]
        x = x[:, :, self._AXES[self.msd_type]]
        res.msds_by_particle = mean_squared_displacement(x)
        res.timeseries = res.msds_by_particle.mean(axis=1)
        res.lagtimes = np.arange(self.n_frames) * spacing
        t_max = res.lagtimes[-1]
        lo, hi = (0.1 * t_max, 0.4 * t_max) if self.fit_range is None else self.fit_range
        res.fit_range = (float(lo), float(hi))
        window = (res.lagtimes >= lo) & (res.lagtimes <= hi)
        if np.count_nonzero(window) >= 2:
            slope, intercept = np.polyfit(res.lagtimes[window], res.timeseries[window], 1)
        else:
            slope = intercept = float("nan")
        res.fit_slope, res.fit_intercept = float(slope), float(intercept)
        res.diffusion_coefficient = float(slope) / (2 * self.dim_fac)
        res.diffusion_coefficient_cm2_s = res.diffusion_coefficient * ANGSTROM2_PER_PS_IN_CM2_PER_S

    def plot(self, path=None):
        """Plot MSD(t) with the fitted line; save a PNG if ``path``.

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        fig, ax = _new_figure()
        ax.plot(res.lagtimes, res.timeseries, color="C0", label="MSD")
        lo, hi = res.fit_range
        t = np.array([0.0, res.lagtimes[-1]])
        ax.plot(t, res.fit_intercept + res.fit_slope * t, color="C3", ls="--",
                label=f"D = {res.diffusion_coefficient_cm2_s * 1e5:.2f}e-5 cm²/s")
        ax.axvspan(lo, hi, color="C3", alpha=0.1, lw=0)
        ax.set_xlabel("lag time (ps)")
        ax.set_ylabel("MSD (Å²)")
        ax.legend(loc="upper left", fontsize=8)
        return _finish(fig, path)


# ============================================================================
# Rotational correlation
# ============================================================================


def orientational_correlation(vectors, max_lag=None):
    r"""Legendre orientational correlations :math:`C_1(t)`, :math:`C_2(t)`.

    :math:`C_\ell(m) = \langle P_\ell(\mathbf u_i(t) \cdot \mathbf u_i(t+m))
    \rangle_{i,t}` with :math:`P_1(x) = x`, :math:`P_2(x) = (3x^2 - 1)/2`,
    averaged over molecules and all time origins.  Computed by FFT from the
    autocorrelations of the components :math:`u_a` (for :math:`P_1`) and of
    the products :math:`u_a u_b` (for :math:`(\mathbf u \cdot \mathbf u')^2`).

    Parameters
    ----------
    vectors : array_like, shape (n_frames, n_molecules, 3)
        Orientation vectors; normalised here.
    max_lag : int, optional
        Largest lag (frames); default ``n_frames - 1``.

    Returns
    -------
    c1, c2 : numpy.ndarray, shape (max_lag + 1,)
    """
    u = np.asarray(vectors, dtype=float)
    if u.ndim != 3 or u.shape[2] != 3:
        raise ValueError(f"vectors must have shape (n_frames, n_molecules, 3), got {u.shape}")
    norm = np.linalg.norm(u, axis=2, keepdims=True)
    if np.any(norm == 0):
        raise ValueError("an orientation vector has zero length")
    u = u / norm
    n = u.shape[0]
    max_lag = n - 1 if max_lag is None else min(int(max_lag), n - 1)
    c1 = np.zeros(max_lag + 1)
    cos2 = np.zeros(max_lag + 1)
    for a in range(3):
        c1 += _autocorrelation(u[:, :, a], max_lag).mean(axis=1)
        for b in range(a, 3):
            weight = 1.0 if a == b else 2.0
            cos2 += weight * _autocorrelation(u[:, :, a] * u[:, :, b], max_lag).mean(axis=1)
    return c1, 1.5 * cos2 - 0.5


def relaxation_time(t, c, window=(0.1, 0.5)):
    r"""Relaxation time of a correlation function, by fit and by integral.

    The fit is :math:`\ln C = \ln A - t/\tau` over the points with
    ``window[0] <= C <= window[1]`` before :math:`C` first falls below
    ``window[0]`` (after the fast librational drop, before the noise).  The
    integral is :math:`\int_0^{t_c} C\,dt` (trapezoids) up to that crossing
    :math:`t_c`, plus the fitted exponential's tail :math:`A\tau
    e^{-t_c/\tau}`.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times (ps).
    c : array_like, shape (n,)
    window : (float, float)

    Returns
    -------
    tau_fit, tau_integral, amplitude : float
        ps, ps and dimensionless; NaN when fewer than three points fit the window.
    """
    t = np.asarray(t, dtype=float)
    c = np.asarray(c, dtype=float)
    low, high = window
    below = np.flatnonzero(c < low)
    cut = below[0] if below.size else len(c)
    sel = np.flatnonzero((c[:cut] >= low) & (c[:cut] <= high))
    tau = amplitude = float("nan")
    if sel.size >= 3:
        slope, intercept = np.polyfit(t[sel], np.log(c[sel]), 1)
        if slope < 0:
            tau, amplitude = -1.0 / slope, float(np.exp(intercept))
    end = min(cut, len(c) - 1)
    integral = float(np.sum(0.5 * (c[1:end + 1] + c[:end]) * np.diff(t[:end + 1])))
    if np.isfinite(tau):
        integral += amplitude * tau * np.exp(-t[end] / tau)
    return float(tau), integral, amplitude


def _residue_vectors(positions, layout, charges, kind):
    """Dipole (sum q_i r_i) or heavy-atom-to-centroid vector per residue, shape (n_res, 3)."""
    idx = layout.index
    if kind == "dipole":
        return np.stack([np.bincount(idx, weights=charges * positions[:, k], minlength=layout.n)
                         for k in range(3)], axis=1)
    # "bisector": from the heaviest atom (first if tied) to the centroid of the others.
    m = layout.masses
    order = np.lexsort((np.arange(len(m)), -m, idx))  # by residue, heaviest first
    _, first = np.unique(idx[order], return_index=True)
    heavy = order[first]
    others = np.ones(len(m), dtype=bool)
    others[heavy] = False
    count = np.bincount(idx[others], minlength=layout.n).astype(float)
    if np.any(count == 0):
        raise ValueError("vector='bisector' needs residues of at least two atoms")
    centroid = np.stack([np.bincount(idx[others], weights=positions[others, k],
                                     minlength=layout.n) for k in range(3)], axis=1)
    centroid /= count[:, None]
    return centroid - positions[heavy]


class RotationalCorrelation(AnalysisBase):
    r"""Rotational correlation of a molecular axis (the dipole of water) and its times.

    :math:`C_\ell(t) = \langle P_\ell(\mathbf u(0) \cdot \mathbf u(t))\rangle`
    for :math:`\ell = 1, 2`, with :math:`\mathbf u` the unit vector of each
    selected residue, averaged over residues and time origins
    (:func:`orientational_correlation`), and relaxation times
    :math:`\tau_1, \tau_2` (:func:`relaxation_time`).  For rigid bodies the
    vector is fixed in the body, so this is the correlation of the bodies'
    orientations (:func:`body_dipole_directions` gives the same vectors from
    the quaternions of a running dynamics).

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
    select : str, default "resname SOL"
        Whole residues are used.
    vector : {"auto", "dipole", "bisector"}, default "auto"
        ``"dipole"``: :math:`\sum_i q_i \mathbf r_i` per residue (needs
        charges); ``"bisector"``: from the heaviest atom to the centroid of
        the others (for water, O to the H–H midpoint: the dipole direction);
        ``"auto"``: dipole if every residue has charges giving a nonzero
        dipole, else bisector.
    max_lag : float, optional
        Longest lag (ps); default half the analysed time.
    window : (float, float), default (0.1, 0.5)
        Correlation values fitted by an exponential (see :func:`relaxation_time`).
    **kwargs
        Passed to :class:`~MDAnalysis.analysis.base.AnalysisBase`.

    Attributes
    ----------
    results.times : numpy.ndarray, shape (n_lags,)
        ps.
    results.c1, results.c2 : numpy.ndarray, shape (n_lags,)
    results.tau1, results.tau2 : float
        Exponential-fit relaxation times (ps).
    results.tau1_integral, results.tau2_integral : float
        Integrated relaxation times (ps).
    results.vector : str
        The vector used ("dipole" or "bisector").
    """

    def __init__(self, universe, select="resname SOL", vector="auto", max_lag=None,
                 window=(0.1, 0.5), **kwargs):
        group = _group(universe, select).residues.atoms
        super().__init__(group.universe.trajectory, **kwargs)
        if vector not in ("auto", "dipole", "bisector"):
            raise ValueError(f"vector must be 'auto', 'dipole' or 'bisector', got {vector!r}")
        self.group = group
        self._layout = _ResidueLayout(group)
        self._charges = (group.charges.astype(float) if hasattr(group, "charges")
                         else np.zeros(len(group)))
        if vector == "auto":
            probe = _residue_vectors(self._layout.whole(group.positions,
                                                        group.universe.trajectory.ts.dimensions),
                                     self._layout, self._charges, "dipole")
            vector = "dipole" if np.all(np.linalg.norm(probe, axis=1) > 1e-6) else "bisector"
        elif vector == "dipole" and not np.any(self._charges):
            raise ValueError("vector='dipole' needs charges; the atoms have none "
                             "(pass charges to to_universe or use vector='bisector')")
        self.vector = vector
        self.max_lag = max_lag
        self.window = window

    def _prepare(self):
        self._u = np.zeros((self.n_frames, self._layout.n, 3))

    def _single_frame(self):
        x = self._layout.whole(self.group.positions, self._ts.dimensions)
        self._u[self._frame_index] = _residue_vectors(x, self._layout, self._charges, self.vector)

    def _conclude(self):
        res = self.results
        spacing = _frame_spacing(self.times)
        n = self.n_frames
        lag = (n - 1) // 2 if self.max_lag is None else int(round(self.max_lag / spacing))
        res.c1, res.c2 = orientational_correlation(self._u, max(lag, 0))
        res.times = np.arange(len(res.c1)) * spacing
        res.tau1, res.tau1_integral, res.amplitude1 = relaxation_time(res.times, res.c1,
                                                                      self.window)
        res.tau2, res.tau2_integral, res.amplitude2 = relaxation_time(res.times, res.c2,
                                                                      self.window)
        res.vector = self.vector

    def plot(self, path=None):
        """Plot C1(t), C2(t) and their exponential fits; save a PNG if ``path``.

        Returns
        -------
        matplotlib.figure.Figure
        """
        res = self.results
        fig, ax = _new_figure()
        for name, c, tau, amp, color in (("C₁", res.c1, res.tau1, res.amplitude1, "C0"),
                                         ("C₂", res.c2, res.tau2, res.amplitude2, "C1")):
            ax.plot(res.times, c, color=color, label=f"{name}(t), τ = {tau:.2f} ps")
            if np.isfinite(tau):
                ax.plot(res.times, amp * np.exp(-res.times / tau), color=color, ls=":", lw=1)
        ax.axhline(0.0, color="0.7", lw=0.8)
        ax.set_xlabel("t (ps)")
        ax.set_ylabel(f"C_ℓ(t), {res.vector} vector")
        ax.legend(loc="upper right", fontsize=8)
        return _finish(fig, path)


def body_dipole_directions(dyn, charges=None):
    r"""Unit dipole direction of every rigid body of a dynamics, from its quaternions.

    The body-frame dipole :math:`\mathbf d_b = \sum_{i \in b} q_i \mathbf d_i`
    (charges times body-frame coordinates) is rotated to the lab frame by the
    body's orientation, :math:`R(q_b)\,\mathbf d_b`.  Attach a recorder to
    collect them during a run and pass the array to
    :func:`orientational_correlation`::

        frames = []
        dyn.attach(lambda: frames.append(body_dipole_directions(dyn)), interval=5)

    Parameters
    ----------
    dyn : RigidVerlet
    charges : array_like, shape (n_atoms,), optional
        e; default the atoms' initial charges.

    Returns
    -------
    numpy.ndarray, shape (n_bodies, 3)
        Unit vectors.

    Raises
    ------
    ValueError
        A body with no dipole (all charges zero).
    """
    g = dyn.model
    q = _charges(dyn.atoms, charges)[g.order]
    d_body = np.stack([np.bincount(g.atom_body, weights=q * g.body_coordinates[:, k],
                                   minlength=g.n_bodies) for k in range(3)], axis=1)
    norm = np.linalg.norm(d_body, axis=1)
    if np.any(norm <= 1e-12):
        b = int(np.flatnonzero(norm <= 1e-12)[0])
        raise ValueError(f"body {b} has no dipole: give charges (e.g. tip3p_charges(atoms))")
    return quat.rotate(dyn.quaternions, d_body / norm[:, None])
