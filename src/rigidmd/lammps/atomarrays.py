r"""The per-atom arrays of one LAMMPS instance as NumPy views, kept between calls.

Every call of :class:`~rigidmd.lammps.LAMMPSCalculator` reads LAMMPS's atom
IDs, image flags and forces and writes its positions.  LAMMPS's NumPy wrapper
(``lmp.numpy.extract_atom``) asks the library for the array's type and size and
builds a new view at every request (~8 µs each on a quiet core, several times
that right after a LAMMPS step has cooled the caches).  LAMMPS moves an array
only when it reallocates it (more atoms than it has room for), so
:class:`AtomArrays` keeps each view and builds it anew only when the library's
pointer to the data has changed (one raw query, ~2 µs).

LAMMPS keeps its atoms in its own order, which it changes when it sorts them
(for locality) or exchanges them at a re-neighbouring step; :meth:`order` is
the index of each LAMMPS atom in the ASE atoms, read after every step.

Image flags are packed three to an integer with the bit widths of the LAMMPS
build (``IMGBITS``, ``IMG2BITS``, ``IMGMASK``, ``IMGMAX``): :meth:`images`
unpacks them, :meth:`pack_images` packs them.
"""

import ctypes

import numpy as np

from rigidmd.core.backend import resolve_backend
from rigidmd.lammps import _numpy

__all__ = ["AtomArrays"]

_TWO_D = ("x", "f", "v")


class AtomArrays:
    """NumPy views of ``id``, ``image``, ``x`` and ``f`` of a LAMMPS instance's local atoms.

    Parameters
    ----------
    lmp : lammps.lammps
        The instance, with its atoms created (one MPI rank: all atoms local).
    nlocal : int
        Number of atoms; the views have this length.
    """

    def __init__(self, lmp, nlocal: int):
        self._lmp = lmp
        self.nlocal = int(nlocal)
        self._dtypes = {name: lmp.extract_atom_datatype(name)
                        for name in ("id", "image", "x", "f")}
        self._views = {}
        self._bits = tuple(lmp.extract_setting(s)
                           for s in ("IMGBITS", "IMG2BITS", "IMGMASK", "IMGMAX"))
        self._order = None
        #: The backend of the two per-atom loops: compiled when numba is installed.
        self._backend = resolve_backend(None)

    def view(self, name: str) -> np.ndarray:
        """LAMMPS's array ``name`` for the local atoms (a view: writing it writes LAMMPS's).

        Returns
        -------
        numpy.ndarray, shape (nlocal,) or (nlocal, 3)
        """
        ptr = self._lmp.extract_atom(name, self._dtypes[name])
        data = ptr[0] if name in _TWO_D else ptr
        address = ctypes.cast(data, ctypes.c_void_p).value
        kept = self._views.get(name)
        if kept is None or kept[0] != address:
            kept = (address, self._lmp.numpy.extract_atom(name)[:self.nlocal])
            self._views[name] = kept
        return kept[1]

    def order(self, refresh: bool = False) -> np.ndarray:
        """Index (0-based) in the ASE atoms of each LAMMPS atom, shape (nlocal,).

        Parameters
        ----------
        refresh : bool
            Read LAMMPS's IDs anew (after a step: LAMMPS may have sorted its atoms).
        """
        if refresh or self._order is None:
            ids = self.view("id")
            if self._order is None:
                self._order = np.empty(self.nlocal, dtype=np.int64)
            np.subtract(ids, 1, out=self._order)
        return self._order

    def images(self) -> np.ndarray:
        """LAMMPS's image flags of its atoms (in its order), unpacked, shape (nlocal, 3)."""
        return _numpy.unpack_images(self.view("image"), self._bits)

    def pack_images(self, image) -> np.ndarray:
        """Image flags, shape (n, 3) of int, packed as LAMMPS packs them."""
        return _numpy.pack_images(image, self._bits)

    def write_positions(self, positions: np.ndarray, cell: np.ndarray) -> None:
        """Write ``positions`` (ASE order, LAMMPS's frame, Å) into LAMMPS, in its images.

        Each atom goes in LAMMPS's own image of it (so only real motion counts
        against the neighbour skin); when an atom would be more than half a box
        outside the box in that image (a new box without a set-up, or atoms
        given in another image: a restart from unwrapped positions), all atoms
        are shifted by whole vectors of ``cell`` (LAMMPS's box, lower triangular)
        and their image flags with them: LAMMPS wraps by one box only, and would
        lose such atoms.  See :func:`rigidmd.lammps._numba.write_positions` (on the
        default backend: the NumPy reference without numba).
        """
        self._backend.write_positions(positions, self.order(), self.view("image"), self._bits,
                                      cell, self.view("x"))

    def read_forces(self, out: np.ndarray) -> None:
        """LAMMPS's forces into ``out`` (n, 3) in the ASE order; :meth:`order` read anew.

        LAMMPS may have sorted or exchanged its atoms during the step.
        """
        if self._order is None:
            self._order = np.empty(self.nlocal, dtype=np.int64)
        self._backend.read_forces(self.view("f"), self.view("id"), self._order, out)
