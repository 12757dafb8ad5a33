"""From rigid bodies to an MDAnalysis topology: residues, names, charges, bonds.

:func:`to_universe` turns frames (a list of :class:`ase.Atoms`, a trajectory
file or a running dynamics) into an in-memory Universe; :func:`write_psf`
writes its topology as a PSF file.  See :mod:`rigidmd.mdanalysis` for the
naming conventions.
"""

import os
from pathlib import Path

import numpy as np
from ase import Atoms, units
from ase.formula import Formula
from ase.geometry import cell_to_cellpar

from rigidmd.core.bodies import RigidBodies
from rigidmd.mdanalysis._base import PS, mda, require_mdanalysis


class Topology:
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
        check_resname(water_resname)
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
        self.charges = atom_charges(atoms, charges)
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


#: Characters of a residue name in a PSF (the EXT format's A8 column), a GRO file and a PDB
#: file (MDAnalysis cuts longer names to these without a word).
RESNAME_WIDTH = {".psf": 8, ".gro": 5, ".pdb": 4}


def check_resname(name, width=RESNAME_WIDTH[".psf"], where="a PSF"):
    """Refuse a water residue name that topology files cannot hold, naming ``water_resname``.

    An empty name shifts a PSF's columns (its readers take the atom names for
    residue names, the masses for charges), a blank inside one splits it, and
    a name longer than ``width`` does not fit ``where``'s column.
    """
    if not isinstance(name, str) or not name or any(c.isspace() for c in name) or \
            not name.isprintable():
        raise ValueError(f"water_resname must be a residue name without blanks, such as 'SOL' "
                         f"or 'WAT', got {name!r}")
    if len(name) > width:
        raise ValueError(f"water_resname {name!r} has {len(name)} characters; {where} holds "
                         f"{width}: give a shorter name, such as 'SOL' or 'WAT'")


def _residue_index(body_ids):
    """Residue of every atom: one per body, one per free atom, in order of first atom."""
    ids = np.asarray(body_ids, dtype=np.int64).copy()
    free = ids < 0
    ids[free] = ids.max(initial=-1) + 1 + np.arange(int(free.sum()))
    _, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inverse.ravel()]


def atom_charges(atoms, charges):
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
        water = comp in ({"O": 1, "H": 2}, {"O": 1, "H": 2, "X": 1})  # X: TIP4P's M
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
    """Atom names: OW/HW1/HW2 (MW for a four-site model's M) in water, else element plus a
    number if it repeats."""
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
    names[in_water & (numbers == 0)] = "MW"
    # A single atom (an ion) is named as its residue, in capitals (NA, CL), as in GROMACS.
    alone = np.bincount(resindex)[resindex] == 1
    names[alone] = np.char.upper(symbols[alone].astype(str))
    return names.astype(str)


#: How to put each body's atoms together, in Python.
REORDER_ADVICE = ("reorder the atoms so that each body's atoms follow each other, e.g. "
                  "atoms[np.argsort(RigidBodies.resolve(atoms, bodies).body_ids, "
                  "kind='stable')]")


def check_bodies_contiguous(body_ids, what, advice=REORDER_ADVICE):
    """:func:`check_contiguous` on the residues the bodies ``body_ids`` give (a free atom
    is a residue of its own), before anything is written."""
    check_contiguous(_residue_index(np.asarray(body_ids)), what, advice)


def check_contiguous(resindex, what, advice=REORDER_ADVICE):
    """Refuse residues whose atoms are not consecutive (``what`` names the file written).

    PSF, PDB and GRO readers start a new residue wherever the residue id
    changes from one atom to the next, so a body whose atoms are spread out
    (all oxygens first, then all hydrogens) would be read back as several
    residues.
    """
    resindex = np.asarray(resindex)
    breaks = np.flatnonzero(resindex[1:] != resindex[:-1]) + 1
    n_runs = len(breaks) + 1 if len(resindex) else 0
    n_residues = len(np.unique(resindex))
    if n_runs == n_residues:
        return
    starts = np.r_[0, breaks]
    _, first = np.unique(resindex[starts], return_index=True)
    again = np.ones(len(starts), dtype=bool)
    again[first] = False
    atom = int(starts[np.flatnonzero(again)[0]])
    raise ValueError(
        f"{what}: atom {atom} belongs to residue {int(resindex[atom]) + 1} (a rigid body) "
        f"whose atoms are not consecutive, so readers would see {n_runs} residues instead "
        f"of {n_residues}; {advice}")


def _body_bonds(atoms, body_ids):
    """Covalent bonds (natural cut-offs, minimum image) between atoms of the same body."""
    from ase.neighborlist import natural_cutoffs, neighbor_list

    if not np.any(body_ids >= 0):
        return np.zeros((0, 2), dtype=np.int64)
    i, j = neighbor_list("ij", atoms, natural_cutoffs(atoms))
    keep = (i < j) & (body_ids[i] == body_ids[j]) & (body_ids[i] >= 0)
    pairs = np.stack([i[keep], j[keep]], axis=1)
    return np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), dtype=np.int64)


def dimensions(atoms):
    """``[a, b, c, alpha, beta, gamma]`` (Å, degrees) or None without a full cell."""
    if atoms.cell.rank < 3:
        return None
    return cell_to_cellpar(atoms.cell.array)


def mdanalysis_orientation(cell):
    r"""The rotation that takes positions into MDAnalysis's orientation of ``cell``.

    MDAnalysis (and XTC, DCD) keep only a cell's lengths and angles and read
    them as the cell with :math:`\mathbf a` along x and :math:`\mathbf b` in the
    xy plane (lower-triangular rows).  Positions in a cell oriented otherwise
    (a rotated or upper-triangular one, as ASE's NPT keeps) must be turned with
    it, or every distance MDAnalysis computes is wrong.  Returns ``Q``, shape
    (3, 3), with ``cell @ Q`` that cell (ASE's ``Cell.standard_form``), so that
    positions (rows) go to ``positions @ Q``; None when ``cell`` is in that form
    already (any orthorhombic cell: positions are written as they are) or not full.
    """
    from ase.cell import Cell

    cell = np.asarray(cell, dtype=float)
    if abs(np.linalg.det(cell)) < 1e-12:
        return None
    if cell[0, 1] == cell[0, 2] == cell[1, 2] == 0.0 and np.all(np.diag(cell) > 0):
        return None
    return Cell(cell).standard_form()[1].T


def mdanalysis_positions(atoms, rigid):
    """Positions (Å) with every body whole, in MDAnalysis's orientation of the cell
    (:func:`mdanalysis_orientation`), shape (n_atoms, 3)."""
    positions = whole_positions(atoms, rigid)
    turn = mdanalysis_orientation(atoms.cell.array) if atoms.cell.rank == 3 else None
    return positions if turn is None else positions @ turn


def whole_positions(atoms, rigid):
    """Positions with every body whole (Å), shape (n_atoms, 3)."""
    if atoms.pbc.any() and rigid.n_bodies:
        return rigid.whole_positions(atoms)
    return atoms.positions.copy()


def is_dynamics(obj):
    return (not isinstance(obj, Atoms) and hasattr(obj, "atoms") and hasattr(obj, "bodies")
            and hasattr(obj, "get_time"))


#: Trajectory formats of coordinates without atoms, which ASE cannot read.
_COORDINATES_ONLY = (".xtc", ".dcd", ".trr")


def _read_traj(path, index, timestep=None):
    """Frames of a trajectory file and, for an ASE ``.traj`` written by ASE molecular
    dynamics, the time between the frames read and the time of the first (ps); else
    ``(frames, None, 0.0)``.  Frames read backwards are refused (times run forward), and
    so is a file whose recorded time step is not ``timestep`` (ASE units; the time step of
    the dynamics writing it, changed by ``set_timestep`` after the file was started)."""
    from ase.io import read
    from ase.io.formats import string2index

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no trajectory file {str(path)!r}")
    if path.suffix.lower() in _COORDINATES_ONLY:
        raise ValueError(
            f"run: {str(path)!r} holds coordinates only (no elements, charges or bodies); read "
            f"it with its topology: MDAnalysis.Universe({str(path.with_suffix('.psf'))!r}, "
            f"{str(path)!r})")
    selection = string2index(index) if isinstance(index, str) else index
    if isinstance(selection, slice) and selection.step is not None and selection.step < 0:
        raise ValueError(f"index: {index!r} reads the frames backwards; times run forward, "
                         "so give a positive step")
    frames = read(path, index=index)
    frames = [frames] if isinstance(frames, Atoms) else list(frames)
    dt, first = None, 0.0
    if path.suffix == ".traj":
        from ase.io.trajectory import Trajectory

        with Trajectory(path) as traj:
            desc = getattr(traj, "description", None) or {}
            count = len(traj)
        if "timestep" in desc and "interval" in desc:
            if timestep is not None and not np.isclose(float(desc["timestep"]), timestep,
                                                       rtol=1e-9, atol=0.0):
                raise ValueError(
                    f"run: the dynamics' time step is {timestep / units.fs:g} fs, but its "
                    f"trajectory {str(path)!r} was started at "
                    f"{float(desc['timestep']) / units.fs:g} fs (set_timestep since?), so "
                    "the times of its frames are unknown; read the frames of one time step and "
                    "give their spacing: to_universe(ase.io.read(file, index), dt=...)")
            frame_dt = float(desc["timestep"]) * int(desc["interval"]) / PS
            if isinstance(selection, slice):
                start, _, stride = selection.indices(count)
            else:
                start, stride = int(selection) % count if count else 0, 1
            dt, first = frame_dt * stride, frame_dt * start
    return frames, dt, first


def _trajectory_file(dyn):
    """The file a dynamics writes its trajectory to (None without a trajectory).

    ASE keeps a file name (str or Path) or the open writer it was given: an
    :class:`ase.io.trajectory.TrajectoryWriter` is read through its file name;
    any other writer is refused (its frames cannot be read back).
    """
    from ase.io.trajectory import TrajectoryWriter

    traj = getattr(dyn, "trajectory", None)
    if traj is None or isinstance(traj, (str, os.PathLike)):
        return traj
    name = getattr(traj, "filename", None) if isinstance(traj, TrajectoryWriter) else None
    if isinstance(name, (str, os.PathLike)):
        return name
    raise ValueError(
        f"run: the dynamics writes its trajectory through a {type(traj).__name__} whose file "
        "cannot be read back; pass that file (to_universe('md.traj', bodies=dyn.bodies)) or "
        "give the dynamics a file name (trajectory='md.traj')")


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
          trajectory file if it writes one (given as a file name or as an
          :class:`ase.io.Trajectory` opened for writing), else its current
          state as one frame; its bodies are used.
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
        Residue name of water molecules: up to 8 characters (a PSF's column),
        no blanks.

    Returns
    -------
    MDAnalysis.Universe
        In-memory coordinates (:class:`~MDAnalysis.coordinates.memory.MemoryReader`,
        float32, Å) with every body whole, in MDAnalysis's orientation of the cell
        (:func:`mdanalysis_orientation`: a cell oriented otherwise is turned, with
        its positions), dimensions per frame (``None`` when a frame has no full
        cell), times in ps (a ``.traj`` read from a later frame starts at that
        frame's time).  Residues are numbered from 1 in order of their first atom.

    Raises
    ------
    ImportError
        MDAnalysis is not installed.
    ValueError
        No frames, frames with different atoms, charges of the wrong shape, a
        body definition that does not fit the atoms, an empty ``water_resname``
        or one with blanks or of more than 8 characters (a PSF's column), an
        XTC, DCD or TRR file (coordinates only: read it with its topology,
        ``MDAnalysis.Universe("md.psf", "md.xtc")``), a dynamics whose time
        step changed (``set_timestep``) after its ``.traj`` was started (the
        times of its frames are unknown), or one that writes its trajectory
        through a writer whose file cannot be read back.
    """
    require_mdanalysis()
    time_offset = 0.0
    if is_dynamics(run):
        dyn = run
        bodies = dyn.bodies
        traj = _trajectory_file(dyn)
        if traj is not None and Path(traj).exists():
            frames, file_dt, time_offset = _read_traj(traj, index, float(dyn.dt))
        else:
            frames = [dyn.atoms]
            file_dt = float(dyn.dt) / PS
            time_offset = float(dyn.get_time()) / PS
        dt = file_dt if dt is None else dt
    elif isinstance(run, (str, os.PathLike)):
        frames, file_dt, time_offset = _read_traj(run, index)
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

    topo = Topology(frames[0], bodies, charges=charges, water_resname=water_resname)
    coords = np.empty((len(frames), topo.n_atoms, 3), dtype=np.float32)
    dims = np.zeros((len(frames), 6), dtype=np.float32)
    for k, atoms in enumerate(frames):
        topo.check(atoms, f"frame {k}")
        coords[k] = mdanalysis_positions(atoms, topo.bodies)
        box = dimensions(atoms)
        if box is not None:
            dims[k] = box
    from MDAnalysis.coordinates.memory import MemoryReader

    u = topo.universe()
    u.load_new(coords, format=MemoryReader, dimensions=dims, dt=dt, time_offset=time_offset)
    return u


def write_psf(universe, path, title="written by rigidmd.mdanalysis"):
    """Write a PSF topology (NAMD/VMD space-separated flavour) that MDAnalysis reads.

    The file carries segment, residue ids and names, atom names, types,
    charges (e), masses (amu) and bonds; no angles or dihedrals (rigid bodies
    need none).  The atoms of every residue must be consecutive: readers
    split residues where the residue id changes.

    Parameters
    ----------
    universe : MDAnalysis.Universe or AtomGroup
        With names, types, resnames, charges, masses and (optionally) bonds.
    path : str or os.PathLike
    title : str
        One-line remark.

    Raises
    ------
    ValueError
        The atoms of a residue are not consecutive, or a residue name, atom
        name or type is empty or holds a blank (nothing is written).
    """
    require_mdanalysis()
    ag = universe.atoms
    check_contiguous(ag.resindices, f"write_psf {str(path)!r}")
    for label, values in (("residue name", ag.residues.resnames), ("atom name", ag.names),
                          ("atom type", ag.types)):
        for value in np.unique(np.asarray(values, dtype=str)).tolist():  # a few distinct names
            if not value or any(c.isspace() for c in value):
                raise ValueError(f"write_psf {str(path)!r}: the {label} {value!r} is empty or "
                                 "holds a blank, which shifts the PSF's columns (readers "
                                 "would take one field for the next); rename it")
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
