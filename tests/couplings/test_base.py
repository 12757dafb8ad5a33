"""What the thermostats and barostats share (rigidmd.couplings.base): the parameter
checks.  The interface (registry, generators, composition, export) is tested in
``tests/core/test_coupling.py``; each part on a fake view in ``tests/core/test_stepper.py``;
the kinds themselves in ``test_thermostats.py``, ``test_barostats.py``, ``test_baoab.py`` and
``test_montecarlo.py``."""

import numpy as np
import pytest

from rigidmd.couplings import base


def test_argument_checks_name_the_argument():
    assert base.check_temperature(300) == 300.0
    assert base.check_time("taut", 2) == 2.0
    assert base.check_flag("fixcm", np.bool_(True)) is True
    assert base.check_positive_integer("tchain", 3) == 3
    with pytest.raises(ValueError, match="temperature_K must be >= 0 K, got -1"):
        base.check_temperature(-1)
    with pytest.raises(TypeError, match="temperature_K must be a number"):
        base.check_temperature("hot")
    with pytest.raises(ValueError, match="taut must be a positive time"):
        base.check_time("taut", 0.0)
    with pytest.raises(TypeError, match="fixcm must be True or False, got 1"):
        base.check_flag("fixcm", 1)
    with pytest.raises(ValueError, match="tchain must be a positive integer, got True"):
        base.check_positive_integer("tchain", True)
