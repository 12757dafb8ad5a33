"""Checkpoints written before the package layout (every module flat) load and continue exactly.

``tests/data/checkpoint_flat_*.npz`` were written by the code at commit 994d68e
(``tests/data/make_flat_layout_checkpoints.py`` says how); a checkpoint stores class
names and coupling kinds, never module paths, so moving the modules must not change
what it loads into.  The old code continued each one for ``AFTER`` steps: today's
code, from the same file, must reach the same bits: the positions, momenta and cell,
which the step computes in an order of its own.  The conserved energy adds the kinetic
energy of the atoms through a BLAS dot product, whose order of summation is the BLAS
build's and the CPU's (another NumPy wheel gave one ulp less); it is checked at the
bound that holds for any order.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from rigidmd import RigidBussi, RigidCRescale, load_checkpoint
from rigidmd.core.checkpoint import read_checkpoint
from rigidmd.core.dof import kinetic_energy
from rigidmd.couplings.barostats import CRescaleBarostat
from rigidmd.couplings.thermostats import BussiThermostat

DATA = Path(__file__).resolve().parents[1] / "data"
sys.path.insert(0, str(DATA))
from make_flat_layout_checkpoints import AFTER, BEFORE, calculator  # noqa: E402


@pytest.mark.parametrize("kind, part, cls", [("bussi", BussiThermostat, RigidBussi),
                                             ("crescale", CRescaleBarostat, RigidCRescale)])
def test_a_checkpoint_of_the_flat_layout_continues_bit_for_bit(kind, part, cls):
    """It continues bit for bit, as the class it names (these files store no bases)."""
    path = DATA / f"checkpoint_flat_{kind}.npz"
    assert read_checkpoint(path).nsteps == BEFORE
    assert "classes" not in read_checkpoint(path).meta
    dyn = load_checkpoint(path, calculator(kind))
    assert dyn.nsteps == BEFORE and type(dyn) is cls
    assert any(isinstance(p, part) for p in dyn.couplings)
    dyn.run(AFTER)
    reference = np.load(DATA / "checkpoint_flat_reference.npz")
    np.testing.assert_array_equal(dyn.atoms.positions, reference[f"{kind}_positions"])
    np.testing.assert_array_equal(dyn.atoms.get_momenta(), reference[f"{kind}_momenta"])
    np.testing.assert_array_equal(dyn.atoms.cell.array, reference[f"{kind}_cell"])
    # Summing 3N non-negative terms in any order errs by at most 3N u times their sum
    # (u the unit roundoff), and the final additions by an ulp each; measured: 0 and 1 ulp.
    kinetic = kinetic_energy(dyn.atoms)
    bound = 3 * len(dyn.atoms) * 0.5 * np.spacing(1.0) * kinetic
    bound += 4 * np.spacing(abs(float(reference[f"{kind}_conserved"])))
    assert dyn.get_conserved_energy() == pytest.approx(float(reference[f"{kind}_conserved"]),
                                                       rel=0, abs=bound)
