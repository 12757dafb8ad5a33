"""What the analyses share: time spacing, autocorrelation, unwrapping (rigidmd.mdanalysis._base)."""

import numpy as np
import pytest

pytest.importorskip("MDAnalysis", reason='needs MDAnalysis (pip install "rigidmd[analysis]")')

from rigidmd.mdanalysis._base import (  # noqa: E402
    PS,
    autocorrelation,
    frame_spacing,
    unwrap_series,
)


def test_frames_evenly_spaced_in_time():
    assert PS == pytest.approx(98.2269, rel=1e-5)  # one ps in ASE time
    assert frame_spacing([0.0, 0.5, 1.0, 1.5]) == 0.5
    assert frame_spacing([3.0]) == 1.0
    times = np.float32(np.arange(5) * 0.1 + 1000.0).astype(float)  # float32 roundoff
    assert frame_spacing(times) == pytest.approx(0.1, rel=1e-4)
    with pytest.raises(ValueError, match="frames must be evenly spaced in time"):
        frame_spacing([0.0, 1.0, 3.0])


def test_autocorrelation_averages_every_origin(rng):
    x = rng.normal(size=(50, 2))
    c = autocorrelation(x, 5)
    assert c.shape == (6, 2)
    for m in range(6):
        assert np.allclose(c[m], np.mean(x[:50 - m] * x[m:], axis=0), rtol=1e-12)


def test_unwrapping_removes_the_jumps():
    box = 10.0
    true = np.cumsum(np.full((6, 1, 3), 3.0), axis=0)  # 3 Å a frame along each axis
    wrapped = true % box
    boxes = np.tile([box, box, box, 90.0, 90.0, 90.0], (6, 1))
    assert np.allclose(unwrap_series(wrapped, boxes), wrapped[:1] + (true - true[:1]))
    triclinic = np.tile([box, box, box, 90.0, 90.0, 80.0], (6, 1))
    assert unwrap_series(wrapped, triclinic).shape == wrapped.shape
    assert unwrap_series(wrapped, None) is wrapped
