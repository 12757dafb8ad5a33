"""RigidNoseHoover (:mod:`rigidmd.md.nosehoover`): ASE's ``NoseHooverChainNVT`` for rigid
bodies.

The part it builds (:class:`~rigidmd.couplings.thermostats.NoseHooverThermostat`) samples
the canonical ensemble and is compared with LAMMPS in
``tests/couplings/test_thermostats.py``; here, the class: its arguments and refusals,
the part it composes, a short run's conserved energy, its checkpoint.
"""

import inspect

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

from rigidmd import RigidNoseHoover
from rigidmd.couplings.thermostats import NoseHooverThermostat
from rigidmd.systems import water_cluster


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        ({"temperature_K": 300, "tdamp": 0.0}, ValueError, "tdamp must be"),
        ({"temperature_K": 300, "tdamp": 0.5 * units.fs}, ValueError,
         "shorter than the time step"),
        ({"temperature_K": 300, "tdamp": 100, "tchain": 0}, ValueError,
         "tchain must be a positive integer"),
    ],
)
def test_bad_parameters(kwargs, error, match):
    atoms = water_cluster(2)
    before = atoms.positions.copy()
    with pytest.raises(error, match=match):
        RigidNoseHoover(atoms, 1 * units.fs, **kwargs)
    np.testing.assert_array_equal(atoms.positions, before)
    assert atoms.constraints == []


def test_a_missing_argument_is_named_with_its_unit():
    with pytest.raises(TypeError) as err:
        RigidNoseHoover(waters(2), units.fs, tdamp=100 * units.fs)
    assert str(err.value) == ("RigidNoseHoover needs temperature_K (K) and tdamp (ASE time "
                              "units); missing: temperature_K")


def test_builds_one_chain_part_from_ase_s_arguments():
    """ASE's order (atoms, timestep, temperature_K, tdamp, tchain, tloop)."""
    dyn = RigidNoseHoover(waters(2), units.fs, 300, 100 * units.fs, 4, 2, fixcm=False)
    part = dyn.thermostat
    assert type(part) is NoseHooverThermostat
    assert dyn.couplings == (part,)
    assert (part.tchain, part.tloop, part.fixcm_option) == (4, 2, False)
    assert (dyn.temperature_K, dyn.tdamp) == (300.0, 100 * units.fs)
    assert dyn.chain_energy() == part.energy() == 0.0  # the chains start at rest
    assert dyn.todict()["kind"] == "nose_hoover"
    assert (dyn.todict()["tchain"], dyn.todict()["tloop"]) == (4, 2)
    assert dyn.todict()["couplings"] == [part.todict()]


def test_the_chains_hold_what_the_particles_lose():
    """Free tops: the kinetic energy plus the chains' energy is conserved, to the
    integration error, while the chains move 0.045 eV."""
    atoms = free_waters(8)
    dyn = RigidNoseHoover(atoms, units.fs, 300, 20 * units.fs)
    E0 = dyn.get_conserved_energy()
    dyn.run(100)
    # Measured: the chains hold -0.045 eV and the conserved energy moved 4.1e-5 eV.
    assert abs(dyn.chain_energy()) > 0.02
    assert dyn.get_conserved_energy() == pytest.approx(E0, abs=2e-4)
    assert dyn.get_conserved_energy() == pytest.approx(
        atoms.get_kinetic_energy() + dyn.chain_energy(), abs=1e-12)


def test_free_tops_come_to_the_target_temperature():
    """64 free waters from 250 K (tdamp 20 fs): the mean temperature of steps 100-400 is
    300 K within 12 K (as tests/md/test_langevin.py's; the chain's oscillation makes
    the samples more correlated).  Measured with seeds 0-4: 293.8-304.5 K (seed 1:
    293.8 K)."""
    atoms = free_waters(64)
    dyn = RigidNoseHoover(atoms, units.fs, 300, 20 * units.fs)
    temperatures = []
    dyn.attach(lambda: temperatures.append(rigid_temperature(atoms, 64)))
    dyn.run(400)
    assert np.mean(temperatures[100:]) == pytest.approx(300, abs=12)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    checkpoint_continues(
        lambda: RigidNoseHoover(mixture(), 2 * units.fs, 300, 50 * units.fs, bodies="mol-id"),
        CoulombLJ(), tmp_path / "state.npz")


def test_the_positional_arguments_are_ase_s():
    """``RigidNoseHoover(atoms, dt, T, tdamp, tchain, tloop)`` reads as ASE's
    ``NoseHooverChainNVT(atoms, dt, T, tdamp, tchain, tloop)``, with its defaults for
    tchain and tloop (T and tdamp default to None here, for the one-line message)."""
    from ase.md.nose_hoover_chain import NoseHooverChainNVT

    ours, ase = positional(RigidNoseHoover), positional(NoseHooverChainNVT)
    assert list(ours) == list(ase)
    assert (ours["tchain"], ours["tloop"]) == (ase["tchain"], ase["tloop"]) == (3, 1)


def positional(cls):
    """The positional parameters of ``cls`` and their defaults."""
    parameters = inspect.signature(cls.__init__).parameters.values()
    return {p.name: p.default for p in parameters if p.kind is p.POSITIONAL_OR_KEYWORD}
