"""Issue 37: the LAMMPS calculator's compiled loops give what their NumPy references give.

``rigidmd.lammps._numba.write_positions`` (positions into LAMMPS's images, atoms more
than half a box out shifted by whole cell vectors) and ``read_forces`` (forces back in
the ASE order) against their NumPy references in ``rigidmd.lammps._numpy``, over random
lower-triangular cells, image flags and permutations (hypothesis).
"""

import numpy as np
from hypothesis_or_skip import given, settings, st

from rigidmd.lammps import _numba, _numpy

#: LAMMPS's default image packing (``-DLAMMPS_SMALLBIG``): IMGBITS, IMG2BITS, IMGMASK, IMGMAX.
BITS = (10, 20, 1023, 512)


def _case(seed, n, tilt, outside):
    """A lower-triangular cell, positions given in random images, LAMMPS's packed images.

    Fractional coordinates stay 0.02 away from the integers and from -1/2 and 3/2, where
    the two formulas (an inverse matrix; back substitution) may round to either side.
    ``outside``: one atom is put 1.6-3 boxes out in its image (so every atom is shifted).
    """
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(5.0, 30.0, 3)
    cell = np.diag(lengths)
    cell[1, 0], cell[2, 0], cell[2, 1] = tilt * rng.uniform(-0.5, 0.5, 3) * lengths[[0, 0, 1]]
    frac = rng.integers(0, 2, (n, 3)) - 0.5 + rng.uniform(0.02, 0.48, (n, 3))  # [-.48, .98]
    if outside:
        frac[rng.integers(n), rng.integers(3)] = rng.choice([-1, 1]) * rng.uniform(1.62, 2.98)
    frac += np.where(np.abs(frac - np.round(frac)) < 0.02, 0.05, 0.0)
    flags = rng.integers(-3, 4, (n, 3))
    order = rng.permutation(n)
    positions = np.empty((n, 3))
    positions[order] = (frac + flags) @ cell  # LAMMPS atom i is ASE atom order[i]
    image = _numpy.pack_images(flags, BITS).astype(np.int32)
    return positions, order.astype(np.int64), image, cell


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
