"""RigidVerlet (:mod:`rigidmd.md.verlet`): ASE's ``VelocityVerlet`` for rigid bodies.

The integrator itself (energy conservation, order, reversibility, every scheme) is
tested in ``tests/core/test_dynamics.py`` and ``tests/core/test_schemes.py``; here, what
the class adds: no coupling parts, its arguments, its checkpoint.
"""

import numpy as np
import pytest
from ase import units
from helpers import CoulombLJ, checkpoint_continues, free_waters, mixture, waters

from rigidmd import RigidDynamics, RigidVerlet


def test_is_nve_and_refuses_couplings_in_one_line():
    with pytest.raises(TypeError) as err:
        RigidVerlet(waters(2), units.fs, couplings=[])
    assert str(err.value) == ("RigidVerlet is NVE and takes no couplings; use RigidDynamics "
                              "or a thermostat class")
    dyn = RigidVerlet(waters(2), units.fs)
    assert isinstance(dyn, RigidDynamics)
    assert dyn.couplings == ()
    assert dyn.todict()["couplings"] == []
    assert dyn.todict()["md-type"] == "RigidVerlet"


def test_arguments_reach_the_dynamics(tmp_path):
    """Positional ``bodies`` after the time step, ASE's ``trajectory``, ``logfile`` and
    ``loginterval``, the integrator and the backend."""
    atoms = waters(3)
    dyn = RigidVerlet(atoms, 2 * units.fs, "mol-id", str(tmp_path / "md.traj"),
                      str(tmp_path / "md.log"), 2, integrator="pcdm", backend="numpy")
    assert dyn.dt == 2 * units.fs
    assert dyn.todict()["bodies_rule"] == "mol-id"
    assert dyn.todict()["integrator"] == dyn.scheme.name == "pcdm"
    assert dyn.todict()["timestep"] == 2 * units.fs
    dyn.run(4)
    # The log: a header and steps 0, 2 and 4.
    assert len((tmp_path / "md.log").read_text().splitlines()) == 4
    assert dyn.todict()["n_bodies"] == 3


def test_free_bodies_move_in_straight_lines():
    """Without forces the centres of mass move at their velocities, exactly (to roundoff),
    the total momentum stays, and the kinetic energy holds to the rotation's splitting
    error."""
    atoms = free_waters(8)
    dyn = RigidVerlet(atoms, units.fs)
    X0, V0 = dyn.state.X.copy(), dyn.state.V.copy()
    P0, K0 = atoms.get_momenta().sum(axis=0), atoms.get_kinetic_energy()
    dyn.run(50)
    # Measured: 1.0e-14 Å from X0 + 50 dt V0.
    np.testing.assert_allclose(dyn.state.X, X0 + 50 * units.fs * V0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(dyn.state.V, V0)
    np.testing.assert_allclose(atoms.get_momenta().sum(axis=0), P0, rtol=0, atol=1e-12)
    # Measured: 4.5e-5 relative (NO_SQUISH's free rotation is a splitting of the
    # asymmetric top: symplectic, not exact); bound 2e-4.
    assert atoms.get_kinetic_energy() == pytest.approx(K0, rel=2e-4)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(
        lambda: RigidVerlet(mixture(), 2 * units.fs, bodies="mol-id"), CoulombLJ(),
        tmp_path / "state.npz")
