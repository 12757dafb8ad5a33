"""The default optimizer, preconditioned L-BFGS of rigid bodies (rigidmd.relax.lbfgs).

Exact continuation from its state is in ``test_state.py``; its preconditioner in
``test_precon.py``."""

import numpy as np
import pytest
from ase.calculators.tip3p import TIP3P
from ase.optimize import BFGS

from rigidmd.relax import RigidFilter, RigidLBFGS, RigidPrecon
from rigidmd.systems import water_cluster


def cluster():
    atoms = water_cluster(4, seed=3)
    atoms.calc = TIP3P(rc=20.0)
    return atoms


def test_it_reaches_the_minimum_bfgs_reaches():
    atoms, reference = cluster(), cluster()
    opt = RigidLBFGS(RigidFilter(atoms), logfile=None)
    assert isinstance(opt.precon, RigidPrecon) and opt.memory == 20 and opt.maxstep == 0.2
    assert opt.run(fmax=1e-4, steps=300)
    BFGS(RigidFilter(reference), logfile=None).run(fmax=1e-4, steps=1000)
    assert atoms.get_potential_energy() == pytest.approx(reference.get_potential_energy(),
                                                         abs=1e-6)
    assert opt.todict()["memory"] == 20


def test_without_a_preconditioner_and_with_a_short_memory():
    atoms = cluster()
    opt = RigidLBFGS(RigidFilter(atoms), logfile=None, precon=None, memory=3, maxstep=0.1)
    start = atoms.get_potential_energy()
    opt.run(fmax=1e-3, steps=200)
    assert atoms.get_potential_energy() < start
    assert len(opt.s) <= 3


def test_bad_arguments_and_states_are_refused():
    view = RigidFilter(cluster())
    with pytest.raises(ValueError, match="RigidLBFGS: maxstep=0 Å must be positive"):
        RigidLBFGS(view, maxstep=0, logfile=None)
    with pytest.raises(ValueError, match="RigidLBFGS: memory=0 must be a whole number >= 1"):
        RigidLBFGS(view, memory=0, logfile=None)
    opt = RigidLBFGS(view, logfile=None)
    opt.run(fmax=1e-3, steps=3)
    state = opt.get_state()
    assert state["s"].shape == (len(opt.s), 3 * len(view)) and len(opt.s) >= 1
    assert any(key.startswith("precon.") for key in state)
    other = RigidLBFGS(RigidFilter(cluster()), logfile=None, memory=5)
    with pytest.raises(ValueError, match="RigidLBFGS: the state was taken with memory=20, "
                                         "this optimizer has 5"):
        other.set_state(state)
    two = water_cluster(2, seed=1)
    two.calc = TIP3P()
    small = RigidLBFGS(RigidFilter(two), logfile=None)
    with pytest.raises(ValueError, match="RigidLBFGS: the state holds vectors of "):
        small.set_state(state)
    np.testing.assert_array_equal(state["memory"], 20)
