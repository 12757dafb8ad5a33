"""The rigid dynamics' log (rigidmd.core.logger)."""

import io

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from helpers import PeriodicLJ, dimer_fluid

from rigidmd import RigidBussi, RigidVerlet
from rigidmd.core.logger import LOG_COLUMNS, RigidLogger
from rigidmd.systems import water_box, water_cluster


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


@pytest.mark.parametrize("atoms, calc, message", [
    (water_cluster(4), TIP3P(rc=20.0),
     r"log_pressure=True: the pressure needs a cell periodic in x, y and z \(pbc is "
     r"\[False, False, False\]\)"),
    (water_box(2), TIP3P(rc=2.9), r"log_pressure=True: the calculator TIP3P provides no "
                                  r"stress \(it implements energy, forces\)"),
    (water_box(2), TIP3P(rc=2.9), None),
])
def test_a_pressure_the_log_cannot_have_is_refused_before_the_log_is_written(
        tmp_path, atoms, calc, message):
    """``log_pressure=True`` on a cluster, or with a calculator without stress, wrote the
    log's header and failed at the first step, leaving a log of one line; "yes" was taken
    for True."""
    atoms.calc = calc
    log = tmp_path / "md.log"
    if message is None:
        with pytest.raises(TypeError, match="log_pressure must be True, False or None, got "
                                            "'yes'"):
            RigidVerlet(atoms, 1 * units.fs, logfile=str(log), log_pressure="yes")
    else:
        with pytest.raises(ValueError, match=message):
            RigidVerlet(atoms, 1 * units.fs, logfile=str(log), log_pressure=True)
    assert not log.exists() and atoms.constraints == []
