"""RigidNPT (:mod:`rigidmd.md.npt`): Nosé–Hoover chains and the MTK barostat.

The parts (:class:`~rigidmd.couplings.thermostats.NoseHooverThermostat`,
:class:`~rigidmd.couplings.barostats.MTKBarostat`) and their ensembles are tested in
``tests/couplings/test_barostats.py``; here, the class: the parts it composes from its
arguments, a short run's conserved energy, its checkpoint.
"""

import numpy as np
import pytest
from ase import units
from helpers import PeriodicLJ, checkpoint_continues, dimer_fluid

from rigidmd import RigidNPT
from rigidmd.couplings.barostats import MTKBarostat
from rigidmd.couplings.thermostats import NoseHooverThermostat

T = 80.0


def build(**kwargs):
    """27 rigid LJ dimers (tagged bodies), 2 fs steps, tdamp 50 fs, pdamp 500 fs."""
    return RigidNPT(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, T, units.bar, 50 * units.fs,
                    500 * units.fs, bodies="tags", **kwargs)


def test_builds_a_chain_thermostat_and_an_mtk_barostat():
    dyn = build(couple="aniso", tchain=4, pchain=2, tloop=3, ploop=2)
    thermostat, barostat = dyn.thermostat, dyn.barostat
    assert type(thermostat) is NoseHooverThermostat and type(barostat) is MTKBarostat
    assert dyn.couplings == (thermostat, barostat)
    assert (thermostat.temperature_K, thermostat.tdamp) == (T, 50 * units.fs)
    assert (thermostat.tchain, thermostat.tloop) == (4, 3)
    assert (barostat.temperature_K, barostat.pressure_au, barostat.pdamp) == (
        T, units.bar, 500 * units.fs)
    assert (barostat.couple, barostat.pchain, barostat.ploop) == ("aniso", 2, 2)
    assert (dyn.temperature_K, dyn.pressure_au) == (T, units.bar)
    assert dyn.todict()["md-type"] == "RigidNPT"
    assert dyn.todict()["thermostat"] == thermostat.todict()
    assert dyn.todict()["barostat"] == barostat.todict()


def test_a_bad_argument_names_itself():
    with pytest.raises(ValueError, match="couple must be one of iso, aniso, tri"):
        build(couple="xy")
    with pytest.raises(ValueError, match="pchain must be a positive integer"):
        build(pchain=0)


def test_a_short_run_conserves_its_energy_while_the_cell_moves():
    """50 steps of 2 fs: the volume moves, and the conserved energy (particles, chains,
    the barostat's kinetic energy and P0 V) holds to the integration error."""
    dyn = build()
    atoms = dyn.atoms
    E0, V0 = dyn.get_conserved_energy(), atoms.get_volume()
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()))
    dyn.run(50)
    # Measured: the volume changed by 17 %; the conserved energy by 2.6e-5 eV at most
    # (kinetic energy 0.45 eV); bound 2e-4 eV.
    assert abs(atoms.get_volume() / V0 - 1) > 1e-3
    np.testing.assert_allclose(energies, E0, rtol=0, atol=2e-4)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(build, PeriodicLJ(rc=5.0), tmp_path / "state.npz")
