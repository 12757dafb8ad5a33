"""Every ensemble and barostat combination, on both backends, repeats its stored trajectory.

The reference (``tests/data/trajectory_identity.npz``) was written by
``tests/data/make_trajectory_identity.py`` before the package's layout changed
(issue 46): a refactoring may move code, never a bit of the dynamics.  In the
environment that wrote the file (the same Python, NumPy, numba and ASE
versions, pinned in ``.ci/pinned.txt``) the comparison is exact.  Under other
releases the summation order of a library call may differ in its last bit, so
there the bound is ``ROUNDOFF_BOUND``.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "data"))

import make_trajectory_identity as reference  # noqa: E402

STORED = np.load(reference.OUT)

# Measured (tests/data/make_trajectory_identity.py's cases, both backends): moving one
# coordinate of the start by one ulp changes the final state by at most 6.2e-10 (Å, amu
# Å/ASE time, eV) after 30 steps (the free-atom case; every other case <= 4.5e-14).  A new
# release may change many roundings in every step, so the bound has a margin of about 100
# over that growth.
ROUNDOFF_BOUND = 1e-7


def pinned() -> bool:
    """Whether this environment is the one that wrote the reference."""
    return all(str(STORED[f"version/{key}"]) == value
               for key, value in reference.versions().items())


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("name", list(reference.cases()))
def test_the_trajectory_is_the_stored_one(name, backend):
    got = reference.run_case(name, backend)
    for key, value in got.items():
        stored = STORED[f"{name}/{backend}/{key}"]
        assert value.shape == stored.shape, key
        if pinned():
            assert np.array_equal(value, stored), (
                f"{name} ({backend}): {key} differs from the stored trajectory by "
                f"{np.max(np.abs(value - stored)):.3g} in the environment that wrote it")
        else:
            np.testing.assert_allclose(value, stored, rtol=0, atol=ROUNDOFF_BOUND,
                                       err_msg=f"{name} ({backend}): {key}")


def test_the_reference_covers_every_public_dynamics():
    import rigidmd

    dynamics = {name for name in rigidmd.__all__
                if name.startswith("Rigid") and name not in ("RigidBodies", "RigidBodyDOF",
                                                              "RigidDynamics")}
    covered = {"RigidVerlet", "RigidLangevin", "RigidLangevinBAOAB", "RigidBussi",
               "RigidNoseHoover", "RigidNPT", "RigidCRescale", "RigidMCBarostat"}
    assert dynamics == covered, "add the new dynamics to make_trajectory_identity.py"
