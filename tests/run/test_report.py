"""What a run says about itself: progress, description, summary (rigidmd.run.report)."""

import io

import numpy as np
from ase import units
from ase.calculators.tip3p import TIP3P

from rigidmd import RigidBussi, RigidVerlet
from rigidmd.run.report import Progress, describe, observables, summary, time_left
from rigidmd.systems import water_cluster


def test_time_left():
    assert time_left(0, 10.0) == "" and time_left(10, 0.0) == ""
    assert time_left(725, 1.0) == "  12m05s left"
    assert time_left(7200 + 60, 1.0) == "  2h01m left"


def dynamics(thermostat=False):
    atoms = water_cluster(3, seed=1)
    atoms.calc = TIP3P()
    if thermostat:
        return RigidBussi(atoms, 1 * units.fs, temperature_K=300, taut=100 * units.fs,
                          rng=np.random.default_rng(0))
    return RigidVerlet(atoms, 1 * units.fs)


def test_describe_and_observables():
    assert describe(dynamics()) == "NVE"
    dyn = dynamics(thermostat=True)
    assert describe(dyn) == "bussi thermostat at 300 K"
    assert observables(dyn) == (dyn.get_time(), dyn.get_conserved_energy())


def test_progress_off_a_terminal_writes_the_last_step():
    dyn = dynamics()
    out = io.StringIO()
    progress = Progress(dyn, 4, stream=out, width=8)
    dyn.attach(progress, interval=1)
    dyn.run(4)
    lines = out.getvalue().splitlines()
    assert lines[-1].startswith("[########] 4/4 steps       -- steps/s  T ")
    assert len(lines) == 1  # a short run: one line (at most one a minute off a terminal)


def test_the_summary_names_what_it_covers():
    dyn = dynamics()
    rows = []
    for _ in range(3):
        dyn.run(1)
        rows.append(observables(dyn))
    out = io.StringIO()
    summary(dyn, rows, 1.5, out, steps=[1, 2, 3])
    text = out.getvalue()
    assert text.startswith("3 steps (1.5 s for this run); T = ")
    assert f"({dyn.degrees_of_freedom} degrees of freedom)" in text
    out = io.StringIO()
    summary(dyn, rows, 1.5, out, steps=[1, 2, 3], resumed_at=1)
    assert out.getvalue().startswith("3 steps (2 since --resume at step 1, 1.5 s)")
