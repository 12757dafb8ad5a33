"""RigidCRescale (:mod:`rigidmd.md.crescale`): stochastic cell rescaling and velocity
rescaling.

The parts (:class:`~rigidmd.couplings.thermostats.BussiThermostat`,
:class:`~rigidmd.couplings.barostats.CRescaleBarostat`) and their ensembles are tested
in ``tests/couplings/test_barostats.py``; here, the class: the parts it composes from
its arguments (one random generator for both), a short run's effective energy, its
checkpoint.
"""

import numpy as np
import pytest
from ase import units
from helpers import PeriodicLJ, checkpoint_continues, dimer_fluid

from rigidmd import RigidCRescale
from rigidmd.couplings.barostats import CRescaleBarostat
from rigidmd.couplings.thermostats import BussiThermostat

T = 80.0


def build(**kwargs):
    """27 rigid LJ dimers (tagged bodies), 2 fs steps, taut 50 fs, taup 500 fs."""
    kwargs.setdefault("rng", np.random.default_rng(5))
    return RigidCRescale(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, T, units.bar,
                         50 * units.fs, 500 * units.fs, 1e-4 / units.bar, bodies="tags",
                         **kwargs)


def test_builds_a_bussi_thermostat_and_a_crescale_barostat_on_one_generator():
    rng = np.random.default_rng(1)
    dyn = build(couple="tri", every=3, rng=rng)
    thermostat, barostat = dyn.thermostat, dyn.barostat
    assert type(thermostat) is BussiThermostat and type(barostat) is CRescaleBarostat
    assert dyn.couplings == (thermostat, barostat)
    assert thermostat.rng is barostat.rng is rng
    assert (thermostat.temperature_K, thermostat.taut) == (T, 50 * units.fs)
    assert (barostat.pressure_au, barostat.taup, barostat.couple, barostat.every) == (
        units.bar, 500 * units.fs, "tri", 3)
    assert barostat.compressibility_au == pytest.approx(1e-4 / units.bar, rel=1e-15)
    assert (dyn.temperature_K, dyn.pressure_au) == (T, units.bar)
    assert dyn.todict()["thermostat"] == thermostat.todict()
    assert dyn.todict()["barostat"] == barostat.todict()
    # Without a generator given, the two parts still share one.
    default = build(rng=None)
    assert default.thermostat.rng is default.barostat.rng


def test_a_bad_argument_names_itself():
    with pytest.raises(ValueError, match="every must be a positive integer"):
        build(every=0)
    with pytest.raises(ValueError, match="temperature_K = 0: stochastic cell rescaling"):
        RigidCRescale(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, 0, units.bar,
                      50 * units.fs, 500 * units.fs, 1e-4 / units.bar, bodies="tags")


def test_a_short_run_keeps_its_effective_energy_while_the_cell_moves():
    """50 steps of 2 fs: the volume moves, and the effective energy (less the work of the
    thermostat and the barostat) holds to the integration error."""
    dyn = build()
    atoms = dyn.atoms
    E0, V0 = dyn.get_conserved_energy(), atoms.get_volume()
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()))
    dyn.run(50)
    # Measured: the volume changed by 1.6 %; the effective energy by 4.0e-5 eV at most
    # (kinetic energy 0.43 eV); bound 4e-4 eV.
    assert abs(atoms.get_volume() / V0 - 1) > 1e-3
    np.testing.assert_allclose(energies, E0, rtol=0, atol=4e-4)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(build, PeriodicLJ(rc=5.0), tmp_path / "state.npz")
