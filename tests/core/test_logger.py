"""The rigid dynamics' log (rigidmd.core.logger)."""

import io

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from helpers import PeriodicLJ, dimer_fluid

from rigidmd import RigidBussi, RigidVerlet
from rigidmd.core.logger import LOG_COLUMNS, RigidLogger
from rigidmd.systems import water_cluster


def test_a_cluster_logs_the_energies_and_temperatures():
    atoms = water_cluster(4, seed=1)
    atoms.calc = TIP3P()
    dyn = RigidVerlet(atoms, 1 * units.fs)
    out = io.StringIO()
    dyn.attach(RigidLogger(dyn, out), interval=2)
    dyn.run(4)
    header, *rows = out.getvalue().splitlines()
    assert header.split() == list(LOG_COLUMNS[:8])
    assert len(rows) == 3
    values = [float(v) for v in rows[-1].split()]
    assert values[0] == pytest.approx(4 * units.fs / (1000 * units.fs), abs=1e-4)
    assert values[2] == pytest.approx(atoms.get_potential_energy(), abs=1e-6)
    assert values[1] == pytest.approx(values[2] + values[3], abs=2e-6)


def test_a_periodic_box_adds_pressure_volume_density_and_the_parts_columns():
    atoms = dimer_fluid(8)
    assert isinstance(atoms.calc, PeriodicLJ)
    dyn = RigidBussi(atoms, 2 * units.fs, temperature_K=100, taut=50 * units.fs,
                     rng=np.random.default_rng(0))
    out = io.StringIO()
    logger = RigidLogger(dyn, out, pressure=True)
    logger()
    header, row = out.getvalue().splitlines()
    names = header.split()
    assert names[8:11] == ["P[bar]", "V[A^3]", "rho[g/cm3]"]
    assert names[11:] == [name for part in dyn.couplings for name in part.log_columns]
    values = [float(v) for v in row.split()]
    assert len(values) == len(names)
    assert values[9] == pytest.approx(atoms.get_volume(), abs=1e-3)
    assert values[8] == pytest.approx(dyn.get_pressure() / units.bar, abs=1e-3)
    quiet = io.StringIO()
    RigidLogger(dyn, quiet, header=False)()
    assert len(quiet.getvalue().splitlines()) == 1
