"""The ``diagnostics:`` section (rigidmd.config.diagnostics)."""

import pytest
from ase import units
from helpers import CoulombLJ, water_parameters

from rigidmd import RigidVerlet
from rigidmd.config.diagnostics import DiagnosticsSection
from rigidmd.config.quantities import ConfigError
from rigidmd.systems import water_cluster
from rigidmd.water import water_model


def test_absent_or_empty_means_nothing_is_measured():
    assert DiagnosticsSection.from_config({}).configurational_temperature is None
    assert DiagnosticsSection.from_config({"diagnostics": None}).configurational_temperature \
        is None
    assert DiagnosticsSection.from_config({"diagnostics": {}}).attach(None) == []


def test_defaults_of_the_configurational_temperature():
    section = DiagnosticsSection.from_config(
        {"diagnostics": {"configurational_temperature": {"interval": 10}}})
    assert section.configurational_temperature == {"interval": 10, "probes": 4, "seed": 0}


@pytest.mark.parametrize("spec, match", [
    ({}, "diagnostics.configurational_temperature.interval: missing"),
    ({"interval": 0}, "diagnostics.configurational_temperature.interval: expected a whole "
                      "number >= 1"),
    ({"interval": 5, "probes": 0}, "configurational_temperature.probes: expected a whole"),
    ({"interval": 5, "seed": -1}, "configurational_temperature.seed: expected a whole"),
    ({"interval": 5, "every": 1}, "configurational_temperature.every: unknown key"),
])
def test_mistakes_name_the_field(spec, match):
    with pytest.raises(ConfigError, match=match):
        DiagnosticsSection.from_config({"diagnostics": {"configurational_temperature": spec}})
    with pytest.raises(ConfigError, match="diagnostics.rdf: unknown key"):
        DiagnosticsSection.from_config({"diagnostics": {"rdf": 1}})


def test_attach_samples_at_the_interval():
    model = water_model("tip3p")
    atoms = water_cluster(4, seed=1)
    atoms.set_initial_charges(model.charges(4))
    atoms.calc = CoulombLJ(parameters=water_parameters(model))
    dyn = RigidVerlet(atoms, 1 * units.fs)
    section = DiagnosticsSection.from_config(
        {"diagnostics": {"configurational_temperature": {"interval": 2, "probes": 1}}})
    (tconf,) = section.attach(dyn)
    assert (tconf.probes, tconf.dyn) == (1, dyn)
    dyn.run(4)
    assert [s[-1] for s in tconf.sums] == [0, 2, 4]
    assert tconf.results["samples"] == 3
    assert tconf.force_calls == 3 * 2  # two force calls per probe, the step's own forces
