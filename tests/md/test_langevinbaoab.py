"""RigidLangevinBAOAB (:mod:`rigidmd.md.langevinbaoab`): ASE's ``LangevinBAOAB`` (NVT) for
rigid bodies.

The part it builds (:class:`~rigidmd.couplings.baoab.LangevinBAOABThermostat`), its
kernels and its exact sampling are tested in ``tests/couplings/test_baoab.py``; here,
the class: ``friction`` or ASE's ``T_tau``, the refusals, the part and the integrator
it sets, a short run, its checkpoint.
"""

import numpy as np
import pytest
from ase import units
from helpers import (
    CoulombLJ,
    checkpoint_continues,
    free_waters,
    mixture,
    rigid_temperature,
    waters,
)

from rigidmd import RigidLangevinBAOAB
from rigidmd.couplings.baoab import LangevinBAOABThermostat


def test_friction_or_T_tau():
    atoms = mixture()
    dyn = RigidLangevinBAOAB(atoms, 2 * units.fs, 300, T_tau=100 * units.fs, bodies="mol-id")
    assert dyn.friction == pytest.approx(0.01 / units.fs, rel=1e-15)
    with pytest.raises(TypeError, match="friction .* or T_tau .*not both"):
        RigidLangevinBAOAB(mixture(), units.fs, 300, 0.01, T_tau=100.0, bodies="mol-id")
    with pytest.raises(TypeError, match="missing: friction or T_tau"):
        RigidLangevinBAOAB(mixture(), units.fs, 300, bodies="mol-id")
    with pytest.raises(ValueError, match="T_tau must be a positive time"):
        RigidLangevinBAOAB(mixture(), units.fs, 300, T_tau=-1.0, bodies="mol-id")
    # No limit on friction * dt: the O step is exact (RigidLangevin refuses > 0.5).
    RigidLangevinBAOAB(mixture(), 2 * units.fs, 300, 50.0, bodies="mol-id").run(2)



@pytest.mark.parametrize("T_tau, error, message", [
    ("long", TypeError, "T_tau must be a time in ASE units, got 'long'"),
    (0.0, ValueError, "T_tau must be a positive time (ASE units), got 0.0"),
    (float("inf"), ValueError, "T_tau must be a positive time (ASE units), got inf"),
])
def test_a_bad_T_tau_is_one_line(T_tau, error, message):
    with pytest.raises(error) as err:
        RigidLangevinBAOAB(waters(2), units.fs, 300, T_tau=T_tau)
    assert str(err.value) == message


def test_a_missing_argument_is_named_with_its_unit():
    with pytest.raises(TypeError) as err:
        RigidLangevinBAOAB(waters(2), units.fs, friction=0.01)
    assert str(err.value) == ("RigidLangevinBAOAB needs temperature_K (K) and friction (per "
                              "ASE time unit) or T_tau (ASE time units); missing: "
                              "temperature_K")
    with pytest.raises(TypeError, match="missing: temperature_K, friction or T_tau$"):
        RigidLangevinBAOAB(waters(2), units.fs)


def test_builds_one_baoab_part_and_the_baoab_integrator():
    """ASE's ``temperature_K`` and ``T_tau`` by keyword; ``rng`` and ``fixcm`` to the part;
    the integrator becomes ``baoab`` unless one with a middle operator is given."""
    rng = np.random.default_rng(3)
    dyn = RigidLangevinBAOAB(waters(2), units.fs, temperature_K=300, T_tau=50 * units.fs,
                             rng=rng, fixcm=False)
    assert type(dyn.thermostat) is LangevinBAOABThermostat
    assert dyn.couplings == (dyn.thermostat,)
    assert dyn.thermostat.rng is rng
    assert dyn.thermostat.fixcm_option is False
    assert dyn.scheme.name == dyn.todict()["integrator"] == "baoab"
    assert dyn.temperature_K == 300.0
    assert dyn.friction == pytest.approx(1 / (50 * units.fs), rel=1e-15)
    dyn.set_friction(0.5)  # no limit on friction * dt
    assert dyn.friction == dyn.thermostat.friction == 0.5
    assert dyn.todict()["kind"] == "langevin_baoab"
    assert dyn.todict()["couplings"] == [dyn.thermostat.todict()]


def test_the_work_is_the_kinetic_energy_it_put_in():
    """Free tops: the thermostat's work is the change of the kinetic energy (the log's
    kinetic energies are those after O; the Atoms' those of the end of the step)."""
    atoms = free_waters(8)
    dyn = RigidLangevinBAOAB(atoms, units.fs, 300, 0.05 / units.fs,
                             rng=np.random.default_rng(1))
    K0, E0 = atoms.get_kinetic_energy(), dyn.get_conserved_energy()
    dyn.run(100)
    # Measured: 0.26 eV of work; the kinetic energy 6.7e-6 eV from it.
    assert dyn.thermostat_work > 0.1
    assert atoms.get_kinetic_energy() - K0 == pytest.approx(dyn.thermostat_work, abs=5e-5)
    assert dyn.get_conserved_energy() == pytest.approx(E0, abs=5e-5)


def test_free_tops_come_to_the_target_temperature():
    """64 free waters from 250 K (friction 0.1/fs): the mean temperature of steps 100-400
    is 300 K within 12 K (as tests/md/test_langevin.py's).  Measured with seeds 0-4:
    301.2-304.7 K (seed 1: 304.7 K)."""
    atoms = free_waters(64)
    dyn = RigidLangevinBAOAB(atoms, units.fs, 300, 0.1 / units.fs,
                             rng=np.random.default_rng(1))
    temperatures = []
    dyn.attach(lambda: temperatures.append(rigid_temperature(atoms, 64)))
    dyn.run(400)
    assert np.mean(temperatures[100:]) == pytest.approx(300, abs=12)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    reference, resumed = checkpoint_continues(
        lambda: RigidLangevinBAOAB(mixture(), 2 * units.fs, 300, 0.01 / units.fs,
                                   bodies="mol-id", rng=np.random.default_rng(5)),
        CoulombLJ(), tmp_path / "state.npz")
    assert resumed.scheme.name == "baoab"
    assert resumed.thermostat.reported == reference.thermostat.reported
