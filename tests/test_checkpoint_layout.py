"""Checkpoints written before the package layout (every module flat) load and continue exactly.

``tests/data/checkpoint_flat_*.npz`` were written by the code at commit 994d68e
(``tests/data/make_flat_layout_checkpoints.py`` says how); a checkpoint stores class
names and coupling kinds, never module paths, so moving the modules must not change
what it loads into.  The old code continued each one for ``AFTER`` steps: today's
code, from the same file, must reach the same bits.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from rigidmd import load_checkpoint
from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.couplings.barostats import CRescaleBarostat
from rigidmd.couplings.thermostats import BussiThermostat

DATA = Path(__file__).with_name("data")
sys.path.insert(0, str(DATA))
from make_flat_layout_checkpoints import AFTER, BEFORE, calculator  # noqa: E402


@pytest.mark.parametrize("kind, part", [("bussi", BussiThermostat),
                                        ("crescale", CRescaleBarostat)])
def test_a_checkpoint_of_the_flat_layout_continues_bit_for_bit(kind, part):
    path = DATA / f"checkpoint_flat_{kind}.npz"
    assert read_checkpoint(path).nsteps == BEFORE
    dyn = load_checkpoint(path, calculator(kind))
    assert dyn.nsteps == BEFORE
    assert any(isinstance(p, part) for p in dyn.couplings)
    dyn.run(AFTER)
    reference = np.load(DATA / "checkpoint_flat_reference.npz")
    np.testing.assert_array_equal(dyn.atoms.positions, reference[f"{kind}_positions"])
    np.testing.assert_array_equal(dyn.atoms.get_momenta(), reference[f"{kind}_momenta"])
    np.testing.assert_array_equal(dyn.atoms.cell.array, reference[f"{kind}_cell"])
    assert dyn.get_conserved_energy() == reference[f"{kind}_conserved"]
