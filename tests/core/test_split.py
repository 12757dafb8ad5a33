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
    for bad in (0, 1.5, True, 1001, 10**20):
        with pytest.raises((TypeError, ValueError), match="substeps"):
            calc.substeps = bad
    calc.substeps = 1000  # the largest allowed (MAX_SUBSTEPS)
    with pytest.raises(ValueError, match="substeps must be at most 1000"):
        MultipleTimeStep(TIP3P(), EMT(), substeps=10**20)
    assert "stress" not in calc.implemented_properties  # TIP3P has no stress
    with pytest.raises(ValueError, match="MultipleTimeStep: the fast calculator TIP3P provides "
                                         "no stress .* which the barostat needs"):
        calc.check_level_properties("stress", "the barostat")
    atoms = water_cluster(1)
    atoms.calc = MultipleTimeStep(TIP3P(), TIP3P())
    with pytest.raises(PropertyNotImplementedError):
        atoms.get_stress()


def test_what_the_parts_read_is_asked_of_the_calculator_or_each_level():
    """A barostat's stress and a Monte Carlo barostat's energy: each level of a split is
    asked for both; a plain calculator for the energy it declares it lacks (its stress
    is looked for at the first call)."""
    from types import SimpleNamespace

    from ase.calculators.calculator import Calculator

    from rigidmd.core.split import check_calculator_properties, missing_property

    def part(stress=False, energy=False):
        return SimpleNamespace(needs_stress=stress, needs_energy=energy, kind="barostat",
                               section="monte_carlo")

    class ForcesOnly(Calculator):
        implemented_properties = ("forces",)

    check_calculator_properties(TIP3P(), [part(stress=True, energy=True)])  # stress: later
    barostat = part(stress=True)
    assert missing_property(TIP3P(), [barostat]) is None
    assert missing_property(TIP3P(), [barostat], declared=True) == ("stress", barostat)
    assert missing_property(EMT(), [barostat], declared=True) is None  # EMT declares stress
    check_calculator_properties(ForcesOnly(), [part(stress=True)])
    with pytest.raises(ValueError, match=r"^the calculator ForcesOnly provides no energy "
                                         r"\(it implements forces\), which the barostat "
                                         r"monte_carlo needs$"):
        check_calculator_properties(ForcesOnly(), [part(), part(energy=True)])
    check_calculator_properties(MultipleTimeStep(EMT(), EMT()), [part(True, True)])
    with pytest.raises(ValueError, match=r"^MultipleTimeStep: the slow calculator ForcesOnly "
                                         r"provides no energy"):
        check_calculator_properties(MultipleTimeStep(EMT(), ForcesOnly()), [part(energy=True)])
    with pytest.raises(ValueError, match=r"^MultipleTimeStep: the fast calculator TIP3P "
                                         r"provides no stress .* the barostat monte_carlo"):
        check_calculator_properties(MultipleTimeStep(TIP3P(), EMT()), [part(stress=True)])


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


def test_full_makes_the_slow_level_full_less_fast_with_one_call_of_each():
    """``full=``: the slow level is :class:`FullLessFast`; a dynamics under it follows the
    same trajectory, bit for bit, as under ASE's ``LinearCombinationCalculator`` of the same
    models (full - fast rounds alike), and the full model is asked for forces and energy in
    one call where that one asked twice."""
    from ase import units
    from ase.calculators.mixing import LinearCombinationCalculator

    from rigidmd import RigidVerlet
    from rigidmd.core.split import FullLessFast

    calls = {}

    class Counted(TIP3P):
        """Keeps only what it was asked for, as LAMMPSCalculator tallies only that."""

        def calculate(self, atoms=None, properties=("energy",), system_changes=()):
            calls[self.kind] = calls.get(self.kind, 0) + 1
            super().calculate(atoms, properties, system_changes)
            self.results = {name: self.results[name] for name in properties}

    def split(kind):
        fast, full = TIP3P(rc=7.0, width=3.0), Counted(rc=40.0)
        full.kind = kind
        if kind == "full":
            return MultipleTimeStep(fast, full=full, substeps=3)
        return MultipleTimeStep(fast, LinearCombinationCalculator([full, fast], [1.0, -1.0]),
                                substeps=3)

    runs = {}
    for kind in ("full", "mixing"):
        atoms = water_cluster(4, seed=1)
        atoms.calc = split(kind)
        dyn = RigidVerlet(atoms, 2 * units.fs)
        energies = []
        dyn.attach(lambda a=atoms, e=energies: e.append(a.get_potential_energy()), interval=1)
        calls[kind] = 0
        dyn.run(5)
        runs[kind] = (atoms.positions.copy(), energies)
    assert isinstance(split("full").slow, FullLessFast)
    np.testing.assert_array_equal(runs["full"][0], runs["mixing"][0])
    assert runs["full"][1] == runs["mixing"][1]
    assert calls == {"full": 6, "mixing": 12}  # a run's start and 5 steps; twice with mixing
    assert split("full").todict() == {"fast": "TIP3P", "slow": "FullLessFast",
                                      "substeps": 3, "full": "Counted"}


def test_slow_and_full_are_one_or_the_other():
    for kwargs, words in (({}, "the slow calculator is missing"),
                          ({"slow": TIP3P(), "full": TIP3P()}, "not both")):
        with pytest.raises(TypeError, match=words) as err:
            MultipleTimeStep(TIP3P(), **kwargs)
        assert "\n" not in str(err.value)
    with pytest.raises(TypeError, match="the full calculator must be an ASE calculator"):
        MultipleTimeStep(TIP3P(), full=object())


def test_full_less_fast_closes_and_checkpoints_the_full_model():
    closed = []

    class Engine(TIP3P):
        saved = None

        def close(self):
            closed.append(self)

        def get_checkpoint_state(self):
            return {"gewald": 0.3}

        def set_checkpoint_state(self, saved):
            self.saved = saved

    fast, full = Engine(), Engine()
    calc = MultipleTimeStep(fast, full=full)
    assert calc.get_checkpoint_state() == {"fast": {"gewald": 0.3}, "slow": {"gewald": 0.3}}
    calc.set_checkpoint_state({"fast": None, "slow": {"gewald": 0.4}})
    assert full.saved == {"gewald": 0.4} and fast.saved is None
    calc.close()
    assert closed == [fast, full]

