"""Streaming rigid-body runs to XTC or DCD trajectories with a topology file."""

import os
import warnings
import weakref
from pathlib import Path

import numpy as np
from ase import Atoms

from rigidmd.mdanalysis._base import PS, mda, require_mdanalysis
from rigidmd.mdanalysis.topology import (
    RESNAME_WIDTH,
    Topology,
    check_contiguous,
    check_resname,
    dimensions,
    is_dynamics,
    mdanalysis_positions,
    write_psf,
)

#: The largest integer XTC compresses (nm × 10**precision, the xdrfile library's INT_MAX - 2),
#: less a margin for the library's float32 arithmetic (1e-4 Å at precision 7).
XTC_INT_LIMIT = 2**31 - 3 - 1024
#: XTC stores frames of up to this many atoms as plain floats (no integer limit).
XTC_FLOAT_ATOMS = 9
_XTC_MAGIC = 1995


def _drop_offset_cache(path):
    """Remove MDAnalysis's cached frame offsets of a file about to be overwritten."""
    for suffix in ("_offsets.npz", "_offsets.lock"):
        Path(path).with_name(f".{Path(path).name}{suffix}").unlink(missing_ok=True)


def _xtc_last_frame(path):
    """``(n_atoms, time, step)`` of the last frame of an XTC file; None when it holds none.

    Raises ValueError, naming the file and how to repair it, when the file is
    not an XTC or ends in an incomplete frame (a run killed while writing):
    nothing can be appended after it.
    """
    from MDAnalysis.lib.formats.libmdaxdr import XTCFile

    size = path.stat().st_size
    if size == 0:
        return None
    with open(path, "rb") as fh:
        magic = int.from_bytes(fh.read(4), "big")
    whole, n_whole = 0, 0
    if magic == _XTC_MAGIC:
        try:
            with XTCFile(str(path)) as xtc:
                offsets = np.asarray(xtc.offsets)
                whole, n_whole = int(offsets[-1]), len(offsets) - 1
                xtc.seek(len(offsets) - 1)
                frame = xtc.read()  # fails on a cut frame
                n_atoms = int(xtc.n_atoms)
        except OSError:
            pass
        else:
            with open(path, "rb") as fh:  # the frame's length, from its header
                fh.seek(whole)
                head = fh.read(92)
            if n_atoms <= XTC_FLOAT_ATOMS:
                end = whole + 56 + 12 * n_atoms
            else:
                end = whole + 92 + -(-int.from_bytes(head[88:92], "big") // 4) * 4
            if end == size:
                return n_atoms, float(frame.time), int(frame.step)
            whole, n_whole = end, n_whole + 1  # bytes after the last whole frame
    elif size >= 4:
        raise ValueError(f"append: {str(path)!r} is not an XTC file (it does not start as "
                         "one); give another file name, or overwrite=True to replace it")
    raise ValueError(
        f"append: the last frame of {str(path)!r} is incomplete (a run killed while writing "
        f"it?), so nothing can follow it; cut the file back to its {n_whole} whole frames "
        f"with os.truncate({str(path)!r}, {whole}), or write a new file")


def _topology_atoms(path):
    """Number of atoms of a topology file (PSF, PDB or GRO), read by MDAnalysis."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return len(mda.Universe(str(path)).atoms)
    except Exception as err:  # any reader error: say which file, in one line
        raise ValueError(f"append: cannot read the topology {str(path)!r} kept for the "
                         f"continued trajectory ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''}); give topology= "
                         "another file or remove it") from None


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
        XTC precision: decimal places in nm, 1 to 7 (4 → 1e-3 Å resolution;
        GROMACS uses 3, 1e-2 Å).
        A frame with a coordinate beyond what XTC's 32-bit integers hold
        (:math:`2^{31}` units of :math:`10^{-p}` nm: 2147 Å at 7, 21 474 Å at
        6) is refused (frames of up to 9 atoms are stored as floats).
    water_resname : str, default "SOL"
        Residue name of water molecules: no blanks, and as many characters
        as the topology file holds (PSF 8, GRO 5, PDB 4).
    append : bool, default False
        Continue an existing ``.xtc`` file (a resumed run) instead of
        starting it anew; the topology file is kept if it exists.  Both must
        hold as many atoms as ``source``, and the file must end in a whole
        frame.  With Atoms as ``source`` the times and steps go on from the
        file's last frame (``dt`` later, one step on).
    overwrite : bool, default False
        Replace an existing trajectory or topology file; without it (and
        without ``append``) an existing one is refused, so that a
        topology of one's own next to the trajectory is never replaced.

    Raises
    ------
    ValueError
        Unknown extensions, a precision outside 1 to 7, a ``water_resname``
        the topology file cannot hold, a body whose atoms are not consecutive
        (the topology file would split it into several residues: reorder the
        atoms first), ``append`` onto a file of another number of atoms or
        one that ends in an incomplete frame, or ``append`` with
        ``overwrite``.  Nothing is written.
    FileExistsError
        The trajectory or topology file exists (give ``overwrite=True``, or
        ``append=True`` to continue it).

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

    Positions are written with every body whole, in MDAnalysis's orientation of
    the cell (:func:`~rigidmd.mdanalysis.topology.mdanalysis_orientation`): as
    they are for an orthorhombic or lower-triangular cell, turned with the cell
    otherwise (MDAnalysis keeps only its lengths and angles).
    """

    _FORMATS = ("XTC", "DCD")
    #: An observer that only reads the atoms (the dynamics need not look for changes).
    modifies_atoms = False

    def __init__(self, source, filename, topology=None, *, bodies=None, charges=None, dt=1.0,
                 precision=4, water_resname="SOL", append=False, overwrite=False):
        require_mdanalysis()
        if is_dynamics(source):
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
        if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) or \
                not 1 <= precision <= 7:
            raise ValueError(f"MDAWriter: precision must be a whole number of decimals in nm "
                             f"from 1 to 7 (XTC's 32-bit integers overflow beyond), got "
                             f"{precision!r}")
        self.precision = int(precision)
        suffix = self.topology_filename.suffix.lower()
        check_resname(water_resname, RESNAME_WIDTH[suffix],
                      f"a {suffix[1:].upper()} topology ({str(self.topology_filename)!r})")
        if self.append and overwrite:
            raise ValueError("MDAWriter: append=True continues the files and overwrite=True "
                             "replaces them; give one of the two")
        self.atoms = atoms
        self._topology = Topology(atoms, bodies, charges=charges, water_resname=water_resname)
        check_contiguous(self._topology.resindex,
                         f"MDAWriter topology {str(self.topology_filename)!r}")
        self._time0, self._step0 = 0.0, 0  # of the first frame written (Atoms as source)
        if self.append:
            self._check_continued(len(atoms))
        elif not overwrite:
            for name, path in (("filename", self.filename),
                               ("topology", self.topology_filename)):
                if path.exists():
                    raise FileExistsError(
                        f"MDAWriter {name}: {str(path)!r} exists; give overwrite=True to "
                        "replace it, append=True to continue it, or another file name")
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

    def _check_continued(self, n_atoms):
        """Refuse to continue files of another system or a trajectory cut mid-frame."""
        if self.filename.exists():
            last = _xtc_last_frame(self.filename)
            if last is not None:
                if last[0] != n_atoms:
                    raise ValueError(
                        f"append: {str(self.filename)!r} holds frames of {last[0]} atoms, the "
                        f"atoms written are {n_atoms}; continue only the same system (or "
                        "write another file)")
                self._time0, self._step0 = last[1] + self.dt, last[2] + 1
        if self.topology_filename.exists():
            kept = _topology_atoms(self.topology_filename)
            if kept != n_atoms:
                raise ValueError(
                    f"append: the topology {str(self.topology_filename)!r} kept for the "
                    f"continued trajectory has {kept} atoms, the atoms written are {n_atoms}; "
                    "give topology= the file of this system")

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
        positions = mdanalysis_positions(atoms, self._topology.bodies)
        dims = dimensions(atoms)
        if self.dynamics is not None:
            time = float(self.dynamics.get_time()) / PS
            step = int(self.dynamics.nsteps)
        else:
            time, step = self._time0 + self.n_frames * self.dt, self._step0 + self.n_frames
        return positions, dims, time, step

    def _check_xtc_range(self, positions):
        """Refuse a frame whose coordinates XTC's 32-bit integers cannot hold.

        XTC stores ``round(x[nm] * 10**precision)`` and its spread along each
        axis as 32-bit integers; beyond them the library writes garbage (with
        only a message on stderr).
        """
        if len(positions) <= XTC_FLOAT_ATOMS:
            return
        scale = 10.0 ** self.precision
        ints = np.rint((np.asarray(positions, dtype=np.float32) / 10.0).astype(np.float64)
                       * scale)
        largest = np.abs(ints).max(axis=0)
        spread = ints.max(axis=0) - ints.min(axis=0)
        if largest.max() <= XTC_INT_LIMIT and spread.max() <= XTC_INT_LIMIT:
            return
        limit = XTC_INT_LIMIT / scale * 10.0  # Å
        axis = int(np.argmax(np.maximum(largest, spread)))
        if largest[axis] >= spread[axis]:
            atom = int(np.argmax(np.abs(ints[:, axis])))
            where = (f"atom {atom} is at {'xyz'[axis]} = {positions[atom, axis]:.6g} Å, beyond "
                     f"the ±{limit:.6g} Å")
            need = largest[axis] / scale
        else:
            hi, lo = int(np.argmax(ints[:, axis])), int(np.argmin(ints[:, axis]))
            where = (f"atoms {lo} and {hi} are {positions[hi, axis] - positions[lo, axis]:.6g} "
                     f"Å apart along {'xyz'[axis]}, beyond the {limit:.6g} Å span")
            need = spread[axis] / scale
        fits = int(np.floor(np.log10(XTC_INT_LIMIT / need)))
        fix = (f"precision={fits} holds it" if fits >= 1 else "no precision holds it")
        raise ValueError(
            f"MDAWriter precision: {where} that XTC holds at precision={self.precision} "
            f"(32-bit integers of nm × 10^{self.precision}); the frame was not written: lower "
            f"the precision ({fix}) or wrap the molecules into the cell")

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
            The writer is closed, the atoms changed in number or elements, or
            (XTC) a coordinate is beyond what the precision holds; nothing of
            the frame is written.
        """
        if self._closed:
            raise ValueError(f"{self!r} is closed")
        frame = self._frame()
        if self.format == "XTC":
            self._check_xtc_range(frame[0])
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
