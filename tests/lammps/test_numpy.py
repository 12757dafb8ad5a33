"""The NumPy references of the LAMMPS calculator's kernels (:mod:`rigidmd.lammps._numpy`).

Direct cases with known answers: LAMMPS's packed image flags, positions written into
LAMMPS's arrays and read back, forces put back into the ASE order.  (The kernels against
these references: ``tests/lammps/test_numba.py`` and ``tests/core/test_backend.py``.)
"""

import numpy as np
import pytest

from rigidmd.lammps import _numpy

#: LAMMPS's default image packing (``-DLAMMPS_SMALLBIG``): IMGBITS, IMG2BITS, IMGMASK, IMGMAX.
BITS = (10, 20, 1023, 512)
#: ``-DLAMMPS_BIGBIG``: 21 bits a direction.
BIGBITS = (21, 42, 2**21 - 1, 2**20)


def test_packing_is_lammps_s_formula():
    """(x + IMGMAX) | (y + IMGMAX) << IMGBITS | (z + IMGMAX) << IMG2BITS; no image is
    IMGMAX in every field."""
    assert _numpy.pack_images([[0, 0, 0]], BITS)[0] == 512 | 512 << 10 | 512 << 20
    assert _numpy.pack_images([[1, -1, 2]], BITS)[0] == 513 | 511 << 10 | 514 << 20
    assert _numpy.pack_images([[-512, 511, 0]], BITS)[0] == 0 | 1023 << 10 | 512 << 20


@pytest.mark.parametrize("bits", [BITS, BIGBITS], ids=["smallbig", "bigbig"])
def test_unpacking_undoes_packing_over_the_whole_range(bits):
    _, _, mask, offset = bits
    rng = np.random.default_rng(0)
    flags = rng.integers(-offset, mask - offset + 1, size=(500, 3))
    flags[:2] = [[-offset] * 3, [mask - offset] * 3]  # the two ends of the range
    packed = _numpy.pack_images(flags, bits)
    if bits == BITS:
        packed = packed.astype(np.int32)  # LAMMPS's imageint of this build
    unpacked = _numpy.unpack_images(packed, bits)
    assert unpacked.dtype == np.int64
    np.testing.assert_array_equal(unpacked, flags)


def cell():
    return np.array([[10.0, 0, 0], [2.0, 9.0, 0], [-1.0, 1.5, 11.0]])


def test_positions_are_written_in_each_atom_s_image_and_read_back():
    """Atoms within [-1/2, 3/2) of their image's box keep it: ``x`` is the position less the
    image's lattice vector, and ``x`` plus the image is the position again."""
    h = cell()
    frac = np.array([[0.1, 0.2, 0.3], [1.3, -0.4, 0.9], [-0.2, 1.1, 0.5]])
    flags = np.array([[0, 0, 0], [2, -1, 0], [-3, 4, 1]])
    positions = (frac + flags) @ h
    order = np.array([2, 0, 1])  # LAMMPS's atom i is ASE's atom order[i]
    image = _numpy.pack_images(flags[order], BITS).astype(np.int32)
    before = image.copy()
    x = np.empty((3, 3))
    assert not _numpy.write_positions(positions, order, image, BITS, h, x)
    np.testing.assert_array_equal(image, before)
    # Measured: 1.8e-15 Å from the exact x (roundoff of the inverse cell); bound 1e-13.
    np.testing.assert_allclose(x, frac[order] @ h, rtol=0, atol=1e-13)
    read_back = x + _numpy.unpack_images(image, BITS) @ h
    np.testing.assert_allclose(read_back, positions[order], rtol=0, atol=1e-13)


def test_an_atom_far_out_of_its_box_moves_to_another_image():
    """An atom 2.7 boxes out along a is put back in its box, its image shifted by 2; the
    others are left as they were, and ``x`` plus the images is still every position."""
    h = cell()
    flags = np.array([[0, 0, 0], [1, 0, -1]])
    frac = np.array([[0.5, 0.5, 0.5], [2.7, 0.25, 0.5]])
    positions = (frac + flags) @ h
    order = np.arange(2)
    image = _numpy.pack_images(flags, BITS).astype(np.int32)
    x = np.empty((2, 3))
    assert _numpy.write_positions(positions, order, image, BITS, h, x)
    np.testing.assert_array_equal(_numpy.unpack_images(image, BITS), [[0, 0, 0], [3, 0, -1]])
    # Measured: exact here (0 Å); the bound allows the inverse cell's roundoff, 1e-13.
    np.testing.assert_allclose(x, np.array([[0.5, 0.5, 0.5], [0.7, 0.25, 0.5]]) @ h,
                               rtol=0, atol=1e-13)
    read_back = x + _numpy.unpack_images(image, BITS) @ h
    np.testing.assert_allclose(read_back, positions, rtol=0, atol=1e-13)


def test_forces_are_put_back_in_the_ase_order():
    """LAMMPS's atom i has the id ``ids[i]`` (ASE's atom ``ids[i] - 1``); ``order`` becomes
    that map and ``out`` the forces in ASE's order."""
    ids = np.array([3, 1, 4, 2], dtype=np.int32)
    f = np.arange(12.0).reshape(4, 3)
    order = np.full(4, -7, dtype=np.int64)
    out = np.empty((4, 3))
    _numpy.read_forces(f, ids, order, out)
    np.testing.assert_array_equal(order, [2, 0, 3, 1])
    np.testing.assert_array_equal(out, f[[1, 3, 0, 2]])
