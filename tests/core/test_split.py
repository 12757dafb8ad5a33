"""MultipleTimeStep as an ASE calculator: the sum of two levels (rigidmd.core.split).

r-RESPA in the dynamics is tested in ``test_respa.py``."""

import numpy as np
import pytest
from ase.calculators.calculator import PropertyNotImplementedError
from ase.calculators.emt import EMT
from ase.calculators.lj import LennardJones
from ase.calculators.tip3p import TIP3P

from rigidmd import MultipleTimeStep
from rigidmd.systems import water_cluster


def test_the_sum_of_the_levels():
    atoms = water_cluster(3, seed=2)
    fast, slow = TIP3P(rc=4.0), LennardJones(sigma=3.0, epsilon=0.01, rc=6.0)
    calc = MultipleTimeStep(fast, slow, substeps=4)
    atoms.calc = calc
    energy, forces = atoms.get_potential_energy(), atoms.get_forces()
    parts = []
    for level in (fast, slow):
        copy = atoms.copy()
        copy.calc = level
        parts.append((copy.get_potential_energy(), copy.get_forces()))
    assert energy == pytest.approx(parts[0][0] + parts[1][0], abs=1e-12)
    assert np.allclose(forces, parts[0][1] + parts[1][1], atol=1e-12)
    assert calc.results["free_energy"] == calc.results["energy"]
    assert calc.levels == (("fast", fast), ("slow", slow))
    assert calc.todict() == {"fast": "TIP3P", "slow": "LennardJones", "substeps": 4}


def test_substeps_and_missing_properties():
    calc = MultipleTimeStep(TIP3P(), EMT())
    assert calc.substeps == 1
    calc.substeps = 3
    assert calc.substeps == 3
    for bad in (0, 1.5, True):
        with pytest.raises((TypeError, ValueError), match="substeps"):
            calc.substeps = bad
    assert "stress" not in calc.implemented_properties  # TIP3P has no stress
    with pytest.raises(ValueError, match="MultipleTimeStep: the fast calculator TIP3P provides "
                                         "no stress .* which the barostat needs"):
        calc.check_level_properties("stress", "the barostat")
    atoms = water_cluster(1)
    atoms.calc = MultipleTimeStep(TIP3P(), TIP3P())
    with pytest.raises(PropertyNotImplementedError):
        atoms.get_stress()


def test_close_and_checkpoint_state_reach_both_levels():
    calls = []

    class Engine(TIP3P):
        def __init__(self, name, fail=False):
            super().__init__()
            self.label, self.fail, self.saved = name, fail, None

        def close(self):
            calls.append(self.label)
            if self.fail:
                raise OSError("engine gone")

        def get_checkpoint_state(self):
            return {"who": self.label}

        def set_checkpoint_state(self, saved):
            self.saved = saved

    calc = MultipleTimeStep(Engine("fast", fail=True), Engine("slow"))
    with pytest.raises(OSError, match="engine gone"):
        calc.close()
    assert calls == ["fast", "slow"]  # the slow level is closed although the fast one failed
    state = calc.get_checkpoint_state()
    assert state == {"fast": {"who": "fast"}, "slow": {"who": "slow"}}
    calc.set_checkpoint_state({"fast": None, "slow": {"who": "x"}})
    assert calc.fast.saved is None and calc.slow.saved == {"who": "x"}
    assert MultipleTimeStep(TIP3P(), TIP3P()).get_checkpoint_state() == {"fast": None,
                                                                          "slow": None}
