"""RigidMCBarostat (:mod:`rigidmd.md.mcbarostat`): a thermostat part and the Monte Carlo
barostat.

The barostat part (:class:`~rigidmd.couplings.montecarlo.MonteCarloBarostat`), its moves
and its ensemble are tested in ``tests/couplings/test_montecarlo.py``; here, the class:
``taut`` or a thermostat part, the parts it composes (one random generator), its
checkpoint.  Systems: the rigid LJ dimer liquid with a calculator without stress.
"""

import numpy as np
import pytest
from ase import units
from helpers import NoStressLJ, checkpoint_continues, dimer_fluid

from rigidmd import RigidMCBarostat, load_checkpoint
from rigidmd.couplings.barostats import CRescaleBarostat
from rigidmd.couplings.montecarlo import MonteCarloBarostat
from rigidmd.couplings.thermostats import (
    BussiThermostat,
    LangevinThermostat,
    NoseHooverThermostat,
)

T = 80.0


def mc(atoms, couple="iso", every=5, rng=1, **kwargs):
    """RigidMCBarostat on tagged bodies with a Bussi thermostat (taut 100 fs), 5 fs steps."""
    kwargs.setdefault("bodies", "tags")
    return RigidMCBarostat(atoms, kwargs.pop("dt", 5 * units.fs), T,
                           kwargs.pop("pressure", 100 * units.bar), 100 * units.fs,
                           couple=couple, every=every, rng=np.random.default_rng(rng), **kwargs)


def liquid():
    """64 rigid LJ dimers with :class:`helpers.NoStressLJ` (no stress)."""
    atoms = dimer_fluid(n_side=4, rc=7.0)
    atoms.calc = NoStressLJ(rc=7.0)
    return atoms


def test_builds_a_bussi_thermostat_and_the_barostat_on_one_generator():
    rng = np.random.default_rng(2)
    dyn = RigidMCBarostat(liquid(), 5 * units.fs, T, 100 * units.bar, 100 * units.fs,
                          couple="aniso", every=7, rng=rng, adapt_moves=40, step=0.03,
                          bodies="tags")
    thermostat, barostat = dyn.thermostat, dyn.barostat
    assert type(thermostat) is BussiThermostat and type(barostat) is MonteCarloBarostat
    assert dyn.couplings == (thermostat, barostat)
    assert thermostat.rng is barostat.rng is rng
    assert (thermostat.temperature_K, thermostat.taut) == (T, 100 * units.fs)
    assert dyn.todict()["barostat"] == {
        "kind": "monte_carlo", "temperature_K": T, "pressure_au": 100 * units.bar,
        "couple": "aniso", "every": 7, "adapt_moves": 40, "step": 0.03}
    assert dyn.todict()["thermostat"] == thermostat.todict()
    assert (dyn.temperature_K, dyn.pressure_au) == (T, 100 * units.bar)


def test_taut_or_a_thermostat_part():
    """Moved here from tests/couplings/test_montecarlo.py's refusals: the part given must
    be a thermostat part at the barostat's temperature, and in place of ``taut``."""
    atoms = liquid()
    before = atoms.positions.copy()
    with pytest.raises(TypeError, match="give taut .* or a thermostat part, not both"):
        RigidMCBarostat(atoms, units.fs, T, units.bar, 100 * units.fs,
                        thermostat=NoseHooverThermostat(T, 100 * units.fs), bodies="tags")
    with pytest.raises(TypeError, match="not both or neither"):
        RigidMCBarostat(atoms, units.fs, T, units.bar, bodies="tags")
    with pytest.raises(ValueError, match="thermostat's temperature .300 K. differs"):
        RigidMCBarostat(atoms, units.fs, T, units.bar,
                        thermostat=NoseHooverThermostat(300, 100 * units.fs), bodies="tags")
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


@pytest.mark.parametrize("part", [
    CRescaleBarostat(T, units.bar, 500 * units.fs, 1e-4 / units.bar),
    "bussi",
], ids=["a barostat part", "a name"])
def test_a_thermostat_of_another_kind_is_refused_in_one_line(part):
    with pytest.raises(TypeError) as err:
        RigidMCBarostat(liquid(), units.fs, T, units.bar, thermostat=part, bodies="tags")
    assert str(err.value) == ("thermostat must be a thermostat part "
                              f"(rigidmd.couplings.thermostats), got {type(part).__name__}")


def test_composes_with_other_thermostats():
    for thermostat in (LangevinThermostat(T, 0.01 / units.fs, np.random.default_rng(2),
                                          fixcm=False), NoseHooverThermostat(T, 100 * units.fs)):
        atoms = liquid()
        dyn = RigidMCBarostat(atoms, 5 * units.fs, T, 100 * units.bar, thermostat=thermostat,
                              every=5, rng=np.random.default_rng(1), bodies="tags")
        dyn.run(50)
        assert dyn.barostat.attempted.sum() == 10


def test_continuation_from_a_checkpoint_is_bit_identical(tmp_path):
    """Random state, move sizes and counters live in the checkpoint (sizes still adapting)."""
    def build():
        return mc(liquid(), "tri", every=3, adapt_moves=30)

    reference = build()
    reference.run(60)
    first = build()
    first.run(25)
    first.save_checkpoint(tmp_path / "state.npz")
    resumed = load_checkpoint(tmp_path / "state.npz", NoStressLJ(rc=7.0))
    barostat = next(p for p in resumed.couplings if isinstance(p, MonteCarloBarostat))
    np.testing.assert_array_equal(barostat.steps, first.barostat.steps)
    resumed.run(35)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(resumed.atoms.get_momenta(), reference.atoms.get_momenta())
    np.testing.assert_array_equal(resumed.atoms.cell.array, reference.atoms.cell.array)
    np.testing.assert_array_equal(barostat.steps, reference.barostat.steps)
    np.testing.assert_array_equal(barostat.accepted, reference.barostat.accepted)
    assert resumed.get_conserved_energy() == reference.get_conserved_energy()


def test_a_given_thermostat_part_continues_from_a_checkpoint(tmp_path):
    """A Langevin part given in place of ``taut``, sharing the generator: 4 steps, a
    checkpoint, 4 more are the 8 straight."""
    def build():
        rng = np.random.default_rng(4)
        return RigidMCBarostat(liquid(), 5 * units.fs, T, 100 * units.bar, every=2, rng=rng,
                               thermostat=LangevinThermostat(T, 0.01 / units.fs, rng,
                                                             fixcm=False), bodies="tags")

    checkpoint_continues(build, NoStressLJ(rc=7.0), tmp_path / "state.npz")
