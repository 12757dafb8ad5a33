"""Streaming rigid-body runs to XTC or DCD trajectories with a topology file."""

import os
import warnings
import weakref
from pathlib import Path

import numpy as np
from ase import Atoms

from rigidmd.mdanalysis._base import PS, mda, require_mdanalysis
from rigidmd.mdanalysis.topology import (
    Topology,
    check_contiguous,
    dimensions,
    is_dynamics,
    mdanalysis_positions,
    write_psf,
)


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
        XTC precision: decimal places in nm, 1 to 7 (4 → 1e-3 Å resolution;
        GROMACS uses 3, 1e-2 Å).
    water_resname : str, default "SOL"
    append : bool, default False
        Continue an existing ``.xtc`` file (a resumed run) instead of
        starting it anew; the topology file is kept if it exists.

    Raises
    ------
    ValueError
        Unknown extensions, a precision outside 1 to 7, or a body whose atoms
        are not consecutive (the topology file would split it into several
        residues): reorder the atoms first.  Nothing is written.

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
                 precision=4, water_resname="SOL", append=False):
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
        self.atoms = atoms
        self._topology = Topology(atoms, bodies, charges=charges, water_resname=water_resname)
        check_contiguous(self._topology.resindex,
                         f"MDAWriter topology {str(self.topology_filename)!r}")
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
        positions = mdanalysis_positions(atoms, self._topology.bodies)
        dims = dimensions(atoms)
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
