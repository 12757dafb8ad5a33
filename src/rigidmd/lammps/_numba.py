r"""The two per-atom loops of a :class:`~rigidmd.lammps.LAMMPSCalculator` call, compiled.

A call writes the positions into LAMMPS's own image of each atom and reads the
forces back in the ASE order.  In NumPy each is several passes with
temporaries (gather, unpack the image flags, ``image @ cell``, fractional
coordinates, two range tests; scatter by atom ID): together about 90 µs per
call on 648 atoms, a third of rigidmd's own share of a 216-water step under a
barostat.  Compiled, each is one loop: :func:`write_positions` and
:func:`read_forces`.  Their NumPy references, of the same names and
arguments, are in :mod:`rigidmd.lammps._numpy` (the path without numba);
each pair is an operation of the backends (:mod:`rigidmd.core.backend`), and
``tests/lammps/test_numba.py`` and ``tests/core/test_backend.py`` check the two
against each other.

Definitions.  LAMMPS's box is lower triangular, rows
:math:`\mathbf a = (a_x, 0, 0)`, :math:`\mathbf b = (b_x, b_y, 0)`,
:math:`\mathbf c = (c_x, c_y, c_z)`.  An atom at :math:`\mathbf r` (LAMMPS's
frame) with image flags :math:`(i, j, k)` is written at
:math:`\mathbf x = \mathbf r - i\mathbf a - j\mathbf b - k\mathbf c`, whose
fractional coordinates :math:`\mathbf s` (:math:`\mathbf x = s_1\mathbf a +
s_2\mathbf b + s_3\mathbf c`) follow by back substitution:
:math:`s_3 = x_z / c_z`, :math:`s_2 = (x_y - s_3 c_y) / b_y`,
:math:`s_1 = (x_x - s_2 b_x - s_3 c_x) / a_x`.  LAMMPS wraps an atom by one
box at most, so when any :math:`s` lies outside :math:`[-1/2, 3/2)` every atom
is moved by :math:`\lfloor\mathbf s\rfloor` cell vectors into the box and its
image flags take the shift.
"""

import numpy as np

from rigidmd.core._numba import jit

__all__ = ["read_forces", "write_positions"]


@jit
def _write_positions(positions, order, image, shift, shift2, mask, offset, cell, x):
    n = x.shape[0]
    ax, bx, by = cell[0, 0], cell[1, 0], cell[1, 1]
    cx, cy, cz = cell[2, 0], cell[2, 1], cell[2, 2]
    outside = False
    for i in range(n):
        img = np.int64(image[i])
        fi = (img & mask) - offset
        fj = ((img >> shift) & mask) - offset
        fk = (img >> shift2) - offset
        src = order[i]
        xx = positions[src, 0] - (fi * ax + fj * bx + fk * cx)
        xy = positions[src, 1] - (fj * by + fk * cy)
        xz = positions[src, 2] - fk * cz
        x[i, 0], x[i, 1], x[i, 2] = xx, xy, xz
        s3 = xz / cz
        s2 = (xy - s3 * cy) / by
        s1 = (xx - s2 * bx - s3 * cx) / ax
        if (s1 < -0.5 or s1 >= 1.5 or s2 < -0.5 or s2 >= 1.5
                or s3 < -0.5 or s3 >= 1.5):
            outside = True
    if outside:
        for i in range(n):
            img = np.int64(image[i])
            fi = (img & mask) - offset
            fj = ((img >> shift) & mask) - offset
            fk = (img >> shift2) - offset
            xx, xy, xz = x[i, 0], x[i, 1], x[i, 2]
            s3 = xz / cz
            s2 = (xy - s3 * cy) / by
            s1 = (xx - s2 * bx - s3 * cx) / ax
            k1, k2, k3 = np.floor(s1), np.floor(s2), np.floor(s3)
            x[i, 0] = xx - (k1 * ax + k2 * bx + k3 * cx)
            x[i, 1] = xy - (k2 * by + k3 * cy)
            x[i, 2] = xz - k3 * cz
            fi += np.int64(k1)
            fj += np.int64(k2)
            fk += np.int64(k3)
            image[i] = (((fi + offset) & mask) | (((fj + offset) & mask) << shift)
                        | (((fk + offset) & mask) << shift2))
    return outside


@jit
def read_forces(f, ids, order, out):
    """Scatter LAMMPS's forces into the ASE order and refresh ``order``.

    Parameters
    ----------
    f : numpy.ndarray, shape (n, 3)
        LAMMPS's forces (eV/Å), in LAMMPS's order.
    ids : numpy.ndarray of int, shape (n,)
        LAMMPS's atom IDs (1-based indices in the ASE atoms).
    order : numpy.ndarray of int64, shape (n,)
        Written: ``ids - 1``.
    out : numpy.ndarray, shape (n, 3)
        Written: the forces in the ASE order.
    """
    for i in range(f.shape[0]):
        j = ids[i] - 1
        order[i] = j
        out[j, 0], out[j, 1], out[j, 2] = f[i, 0], f[i, 1], f[i, 2]


def write_positions(positions, order, image, bits, cell, x):
    """Write ``positions`` into LAMMPS's positions ``x``, each atom in its LAMMPS image.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n, 3)
        The atoms' positions (Å) in LAMMPS's frame, in the ASE order.
    order : numpy.ndarray of int64, shape (n,)
        Index in ``positions`` of each LAMMPS atom.
    image : numpy.ndarray of int, shape (n,)
        LAMMPS's packed image flags (a view: updated when atoms are shifted).
    bits : tuple of int
        ``(IMGBITS, IMG2BITS, IMGMASK, IMGMAX)`` of the LAMMPS build.
    cell : numpy.ndarray, shape (3, 3)
        LAMMPS's box (Å), lower triangular.
    x : numpy.ndarray, shape (n, 3)
        LAMMPS's positions (a view: written).

    Returns
    -------
    bool
        Whether the atoms were shifted by whole cell vectors (an atom more
        than half a box outside LAMMPS's box in its own image).
    """
    shift, shift2, mask, offset = bits
    return bool(_write_positions(positions, order, image, shift, shift2, mask, offset,
                                 cell, x))
