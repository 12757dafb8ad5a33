"""How a relaxation stops: failed steps, Ctrl-C, the last whole step (rigidmd.relax.stops)."""

import os
import signal

import numpy as np
import pytest
from ase.calculators.tip3p import TIP3P
from ase.optimize import BFGS

from rigidmd.core.forces import NonFiniteForceError
from rigidmd.relax.stops import (
    FailedValue,
    Interrupt,
    Interrupted,
    RelaxationFailed,
    WholeStep,
    failed,
)
from rigidmd.systems import water_cluster


def test_a_failed_step_becomes_one_line_of_its_kind():
    err = failed(RuntimeError("line search\n  found no descent"), "BFGS", 7)
    assert type(err) is RelaxationFailed
    assert str(err) == ("relax: BFGS failed after step 7 (RuntimeError: line search found no "
                        "descent); the atoms are back at the structure of step 7")
    value = failed(ValueError("cell too small"), "FIRE", 2)
    assert isinstance(value, FailedValue) and isinstance(value, ValueError)
    nan = failed(NonFiniteForceError("atom 3 has a non-finite force after step 12"), "FIRE", 2)
    assert type(nan) is NonFiniteForceError
    assert "(atom 3 has a non-finite force)" in str(nan)


def test_ctrl_c_is_held_until_the_step_is_whole():
    with Interrupt() as interrupt:
        interrupt()  # nothing pending
        os.kill(os.getpid(), signal.SIGINT)
        assert interrupt.pending
        with pytest.raises(Interrupted):
            interrupt()
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)  # a second Ctrl-C: at once
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_last_whole_step_is_restored():
    atoms = water_cluster(2, seed=1)
    atoms.calc = TIP3P()
    opt = BFGS(atoms, logfile=None)
    whole = WholeStep(atoms, opt)
    assert whole.step == 0
    opt.attach(whole)
    opt.run(steps=2)
    kept = atoms.positions.copy()
    atoms.positions += 1.0
    atoms.set_cell(np.eye(3) * 30.0)
    whole.restore()
    assert np.array_equal(atoms.positions, kept) and whole.step == opt.nsteps
    assert not atoms.cell.any()
