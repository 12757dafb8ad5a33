"""A force split in the ``calculator:`` section (rigidmd.config.splitsection)."""

import pytest
from ase.calculators.tip3p import TIP3P

from rigidmd import MultipleTimeStep
from rigidmd.config.quantities import ConfigError
from rigidmd.config.sections import CalculatorSection
from rigidmd.config.splitsection import SplitCalculatorSection, calculator_section
from rigidmd.core.split import FullLessFast
from rigidmd.systems import water_cluster


def test_one_calculator_or_a_split(tmp_path):
    one = calculator_section({"calculator": {"name": "tip3p"}}, tmp_path)
    assert type(one) is CalculatorSection
    assert type(calculator_section({}, tmp_path)) is CalculatorSection  # tip3p by default
    split = calculator_section({"calculator": {"fast": {"name": "tip3p"},
                                               "slow": {"name": "tip4p"}, "substeps": 3}},
                               tmp_path)
    assert type(split) is SplitCalculatorSection
    assert (split.name, split.substeps, split.difference) == ("multiple_time_step", 3, False)
    assert [level for level, _ in split.levels] == ["fast", "slow"]
    assert split.processes is None and split.address is None
    fields = split.fingerprint_fields(lambda section: {"name": section.name})
    assert fields == {"substeps": 3, "difference": False, "fast": {"name": "tip3p"},
                      "slow": {"name": "tip4p"}}


def test_a_split_builds_a_multiple_time_step(tmp_path):
    atoms = water_cluster(2, seed=1)
    split = calculator_section({"calculator": {"fast": {"name": "tip3p"},
                                               "full": {"name": "tip3p"}, "substeps": 2}},
                               tmp_path)
    assert split.difference and [level for level, _ in split.levels] == ["fast", "full"]
    calc = split.build(atoms, tmp_path / "engine")
    assert isinstance(calc, MultipleTimeStep) and calc.substeps == 2
    assert isinstance(calc.fast, TIP3P)
    assert isinstance(calc.slow, FullLessFast) and calc.full is calc.slow.full
    assert isinstance(calc.full, TIP3P) and calc.slow.fast is calc.fast


@pytest.mark.parametrize("calc, match", [
    ({"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}, "full": {"name": "tip3p"},
      "substeps": 2}, "calculator.full: the slow level is full less fast; give slow or full"),
    ({"fast": {"name": "tip3p"}, "substeps": 2}, r"calculator.slow: missing \(a calculator"),
    ({"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}},
     r"calculator.substeps: missing \(inner steps"),
    ({"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}, "substeps": 0},
     "calculator.substeps: expected a whole number from 1 to 1000"),
    ({"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}, "substeps": 10**20},
     "calculator.substeps: expected a whole number from 1 to 1000"),
    ({"fast": {"fast": {"name": "tip3p"}}, "slow": {"name": "tip3p"}, "substeps": 2},
     "calculator.fast: a level is one calculator, not another split"),
    ({"fast": {"options": {}}, "slow": {"name": "tip3p"}, "substeps": 2},
     r"calculator.fast.name: missing"),
    ({"fast": {"name": "tip3p"}, "slow": {"name": "tip3p"}, "substeps": 2, "x": 1},
     "calculator.x: unknown key"),
])
def test_mistakes_name_the_level(tmp_path, calc, match):
    with pytest.raises(ConfigError, match=match):
        calculator_section({"calculator": calc}, tmp_path)


def test_a_dotted_level_is_checked_for_trust_under_its_level(tmp_path):
    split = calculator_section({"calculator": {"fast": {"name": "tip3p"},
                                               "slow": {"name": "os.system"}, "substeps": 2}},
                               tmp_path)
    with pytest.raises(ConfigError, match=r"^calculator.slow"):
        split.check_trust(trust=False)
