"""The NumPy references of the LAMMPS calculator's kernels, and LAMMPS's image flags.

:func:`write_positions` and :func:`read_forces` are the references of the
kernels of the same names in :mod:`rigidmd.lammps._numba`, with the same
arguments; importing this module makes each pair an operation of the
backends (:mod:`rigidmd.core.backend`).  :class:`rigidmd.lammps.atomarrays.AtomArrays`
runs them on the default backend (the kernels when numba is installed).
:func:`unpack_images` and :func:`pack_images` read and write LAMMPS's packed
image flags.
"""

import numpy as np

from rigidmd.core.backend import reference_of
from rigidmd.lammps import _numba

__all__ = ["unpack_images", "pack_images", "write_positions", "read_forces"]


def unpack_images(image, bits):
    """Image flags (n, 3) of int64 from LAMMPS's packed integers (``IMGBITS``, ... )."""
    shift, shift2, mask, offset = bits
    img = image.astype(np.int64)
    return np.stack([(img & mask) - offset, ((img >> shift) & mask) - offset,
                     (img >> shift2) - offset], axis=1)


def pack_images(flags, bits):
    """LAMMPS's packed image integers from flags (n, 3) of int."""
    shift, shift2, mask, offset = bits
    packed = (np.asarray(flags, dtype=np.int64) + offset) & mask
    return packed[:, 0] | (packed[:, 1] << shift) | (packed[:, 2] << shift2)


@reference_of(_numba.write_positions)
def write_positions(positions, order, image, bits, cell, x):
    """NumPy reference of :func:`rigidmd.lammps._numba.write_positions` (same arguments and
    result): ``positions`` into LAMMPS's ``x``, each atom in its LAMMPS image."""
    flags = unpack_images(image, bits)
    p = positions[order] - flags @ cell
    frac = p @ np.linalg.inv(cell)
    shifted = bool(np.any(frac < -0.5) or np.any(frac >= 1.5))
    if shifted:
        shift = np.floor(frac)
        p -= shift @ cell
        image[:] = pack_images(flags + shift.astype(np.int64), bits)
    x[:] = p
    return shifted


@reference_of(_numba.read_forces)
def read_forces(f, ids, order, out):
    """NumPy reference of :func:`rigidmd.lammps._numba.read_forces` (same arguments):
    LAMMPS's forces into the ASE order, ``order`` refreshed."""
    np.subtract(ids, 1, out=order)
    out[order] = f
