"""Issue 37: the LAMMPS calculator's compiled loops give what their NumPy references give.

``rigidmd.lammps._numba.write_positions`` (positions into LAMMPS's images, atoms more
than half a box out shifted by whole cell vectors) and ``read_forces`` (forces back in
the ASE order) against their NumPy references in ``rigidmd.lammps._numpy``, over random
lower-triangular cells, image flags and permutations (hypothesis).
"""

import numpy as np
from helpers import LAMMPS_IMAGE_BITS as BITS
from helpers import lammps_image_case as _case
from hypothesis_or_skip import given, settings, st

from rigidmd.lammps import _numba, _numpy


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), tilt=st.sampled_from([0.0, 1.0]),
       outside=st.booleans())
def test_positions_go_into_lammps_images_as_the_numpy_reference_puts_them(seed, n, tilt,
                                                                           outside):
    positions, order, image, cell = _case(seed, n, tilt, outside)
    image_ref = image.copy()
    x, x_ref = np.empty((n, 3)), np.empty((n, 3))
    shifted = _numba.write_positions(positions, order, image, BITS, cell, x)
    shifted_ref = _numpy.write_positions(positions, order, image_ref, BITS, cell, x_ref)
    assert shifted == shifted_ref == outside
    np.testing.assert_array_equal(image, image_ref)
    # The same sums in another order (image @ cell as NumPy's matmul sums it): roundoff.
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-12 * np.abs(cell).max())
    frac = x @ np.linalg.inv(cell)
    assert frac.min() >= -0.5 and frac.max() < 1.5
    if outside:  # every atom into the box, and the images say where it was
        assert frac.min() >= -1e-12 and frac.max() < 1 + 1e-12
    unwrapped = x + _numpy.unpack_images(image, BITS) @ cell
    np.testing.assert_allclose(unwrapped, positions[order], rtol=0,
                               atol=1e-11 * np.abs(cell).max())


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60))
def test_forces_come_back_in_the_ase_order(seed, n):
    rng = np.random.default_rng(seed)
    ids = (rng.permutation(n) + 1).astype(np.int32)  # LAMMPS's atom IDs, 1-based
    f = rng.normal(size=(n, 3))
    out, out_ref = np.empty((n, 3)), np.empty((n, 3))
    order, order_ref = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    _numba.read_forces(f, ids, order, out)
    _numpy.read_forces(f, ids, order_ref, out_ref)
    np.testing.assert_array_equal(out, out_ref)
    np.testing.assert_array_equal(order, order_ref)
    np.testing.assert_array_equal(out[ids - 1], f)


def test_image_flags_pack_and_unpack():
    flags = np.array([[-512, 0, 511], [3, -7, 1], [0, 0, 0]])
    np.testing.assert_array_equal(
        _numpy.unpack_images(_numpy.pack_images(flags, BITS).astype(np.int32), BITS), flags)
