"""Rebuilding a dynamics from a checkpoint (rigidmd.run.restart)."""

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidBussi, RigidDynamics, RigidVerlet
from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.run.restart import load_checkpoint
from rigidmd.systems import water_cluster


def test_a_thermostatted_run_continues_exactly(tmp_path):
    atoms = water_cluster(4, seed=2)
    atoms.calc = TIP3P(rc=8.0)
    dyn = RigidBussi(atoms, 1 * units.fs, temperature_K=300, taut=50 * units.fs,
                     rng=np.random.default_rng(3))
    dyn.run(3)
    dyn.save_checkpoint(tmp_path / "c.npz")
    dyn.run(4)
    again = load_checkpoint(tmp_path / "c.npz", TIP3P(rc=8.0))
    assert type(again) is RigidDynamics and again.nsteps == 3
    assert again.thermostat.kind == "bussi" and not hasattr(again, "barostat")
    again.run(4)
    assert np.array_equal(again.atoms.positions, dyn.atoms.positions)
    assert again.get_time() == pytest.approx(dyn.get_time())


def test_a_read_checkpoint_and_a_calculator_state(tmp_path):
    class Stateful(TIP3P):
        def get_checkpoint_state(self):
            return {"calls": 7}

        def set_checkpoint_state(self, saved):
            self.saved = saved

    atoms = water_cluster(2, seed=1)
    atoms.calc = Stateful()
    dyn = RigidVerlet(atoms, 1 * units.fs)
    dyn.run(2)
    dyn.save_checkpoint(tmp_path / "c.npz")
    calc = Stateful()
    again = load_checkpoint(read_checkpoint(tmp_path / "c.npz"), calc)
    assert again.atoms.calc is calc and again.atoms is not atoms
    assert calc.saved == {"calls": 7}
    assert again.couplings == () or list(again.couplings) == []
