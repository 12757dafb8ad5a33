"""The ``relax:`` section of a run configuration (rigidmd.config.relaxsection)."""

import pytest
from ase import units

from rigidmd.config import RelaxSection
from rigidmd.config.quantities import ConfigError


def test_absent_means_no_relaxation_and_empty_means_the_defaults():
    assert RelaxSection.from_config({}) is None
    assert RelaxSection.from_config({"relax": None}) is None
    section = RelaxSection.from_config({"relax": {}})
    assert (section.fmax, section.steps, section.optimizer, section.cell, section.pressure,
            section.trajectory, section.log) == (0.05, 1000, "RigidLBFGS", False, 0.0,
                                                 "relax.traj", "relax.log")


def test_every_field():
    section = RelaxSection.from_config({"relax": {
        "fmax": "0.01 eV/A", "steps": 50, "optimizer": "FIRE", "cell": True,
        "pressure": "1 GPa", "trajectory": "r.traj", "log": "r.log"}})
    assert section.fmax == 0.01 and section.steps == 50 and section.optimizer == "FIRE"
    assert section.cell == "full"  # true is the full cell
    assert section.pressure == pytest.approx(units.GPa)
    assert (section.trajectory, section.log) == ("r.traj", "r.log")
    assert RelaxSection.from_config({"relax": {"fmax": 0.2}}).fmax == 0.2  # eV/Å by default


@pytest.mark.parametrize("raw, match", [
    ({"fmax": 0}, "relax.fmax: must be positive, got 0"),
    ({"steps": -1}, "relax.steps: expected a whole number >= 1"),
    ({"optimizer": "SD"}, "relax.optimizer: 'SD' is not one of RigidLBFGS, "),
    ({"cell": "xy"}, "relax.cell: expected false, true or one of iso, aniso, full, got 'xy'"),
    ({"pressure": "1 bar"}, "relax.pressure: a target pressure needs relax.cell"),
    ({"log": ""}, "relax.log: expected a file name, got ''"),
    ({"trajectory": 3}, "relax.trajectory: expected a file name, got 3"),
    ({"tol": 1}, "relax.tol: unknown key"),
])
def test_mistakes_name_the_field(raw, match):
    with pytest.raises(ConfigError, match=match):
        RelaxSection.from_config({"relax": raw})


@pytest.mark.parametrize("pressure", ["200 GPa", "-2e6 bar", "1.5 eV/A^3"])
def test_a_pressure_beyond_a_barostats_is_refused_in_the_files_units(pressure):
    """``relax.pressure: 2e6 bar`` (meant 2 bar, or 2e6 Pa) ran a relaxation at 200 GPa;
    the barostats refuse such a target, and so does the relaxation now."""
    with pytest.raises(ConfigError) as err:
        RelaxSection.from_config({"relax": {"cell": "iso", "pressure": pressure}})
    assert str(err.value) == (f"relax.pressure: {pressure} is beyond ±160.2 GPa (±1.602e+06 "
                              "bar), where molecules no longer stay whole; is the unit right?")
    assert RelaxSection.from_config({"relax": {"cell": "iso", "pressure": "100 GPa"}}) \
        .pressure == pytest.approx(100 * units.GPa)


def test_a_restart_is_not_relaxed():
    with pytest.raises(ConfigError, match="relax: a restart continues a run's dynamics"):
        RelaxSection.from_config({"relax": {}, "restart": "md.traj"})
