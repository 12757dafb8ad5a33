"""``benchmarks/lammps_engine.py`` compares like with like: rigidmd's timed steps are steps 1
to N from the start, as native LAMMPS's loop, and native's step leaves out its output.

At 1728 waters one neighbour-list build costs two to three steps, and from the benchmark's
thermal start LAMMPS re-neighbours at steps 22 and 39: a rigidmd window of steps 4 to 23
(three set-up steps, then 20 timed) held one build more than native's steps 1 to 20, and
read 1.12-1.13x native where the aligned windows read 0.98-1.03x.
"""

import numpy as np
import pytest
from helpers import PPPM_27, benchmark_module, water_box_27

from rigidmd.lammps import LAMMPSCalculator

pytestmark = pytest.mark.lammps


class CountingCalculator(LAMMPSCalculator):
    """The in-process calculator, keeping the positions of every call."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls = []

    def calculate(self, atoms=None, properties=("energy",), system_changes=()):
        self.calls.append(atoms.positions.copy())
        super().calculate(atoms, properties, system_changes)


@pytest.mark.parametrize("kind", ["nve", "mtk"])
def test_the_timed_steps_are_steps_one_to_n_from_the_start(kind, monkeypatch):
    bench = benchmark_module("lammps_engine")
    calcs = []

    def counting(commands, **options):  # the benchmark's commands, cut off for 27 waters
        calcs.append(CountingCalculator(PPPM_27, **options))
        return calcs[-1]

    monkeypatch.setattr(bench, "LAMMPSCalculator", counting)
    start = water_box_27(temperature_K=298)
    steps = 4
    bench.calc_run(start, kind, steps)
    calls = calcs[0].calls
    # the last call is at the positions of `steps` steps from the start
    reference = start.copy()
    reference.calc = LAMMPSCalculator(PPPM_27)
    bench.dynamics(reference, kind).run(steps)
    np.testing.assert_allclose(calls[-1], reference.positions, rtol=0, atol=1e-12)
    # one calculator call per timed step after the start's (computed before the timing;
    # the start as the dynamics places it: to roundoff; a step moves atoms by ~1e-3 A)
    at_start = [k for k, x in enumerate(calls)
                if np.allclose(x, start.positions, rtol=0, atol=1e-9)]
    assert len(calls) - 1 - at_start[-1] == steps


LOG = """\
Loop time of 0.8 on 1 procs for 40 steps with 5184 atoms

Performance: 4.320 ns/day, 5.556 hours/ns, 50.000 timesteps/s, 0.259 Matom-step/s
99.5% CPU use with 1 MPI tasks x 1 OpenMP threads

MPI task timing breakdown:
Section |  min time  |  avg time  |  max time  |%varavg| %total
---------------------------------------------------------------
Pair    | 0.4        | 0.4        | 0.4        |   0.0 | 50.00
Bond    | 0          | 0          | 0          |   0.0 |  0.00
Kspace  | 0.16       | 0.16       | 0.16       |   0.0 | 20.00
Neigh   | 0.08       | 0.08       | 0.08       |   0.0 | 10.00
Comm    | 0.004      | 0.004      | 0.004      |   0.0 |  0.50
Output  | 0.04       | 0.04       | 0.04       |   0.0 |  5.00
Modify  | 0.02       | 0.02       | 0.02       |   0.0 |  2.50
Other   |            | 0.096      |            |       | 12.00
"""


def test_the_native_step_leaves_out_its_output():
    bench = benchmark_module("lammps_engine")
    wall, cpu, floor = bench.log_timing(LOG, 40)
    assert wall == pytest.approx((0.8 - 0.04) / 40, rel=1e-12)
    assert cpu == pytest.approx(0.995 * (0.8 - 0.04) / 40, rel=1e-12)
    assert floor == pytest.approx((0.4 + 0.16 + 0.08) / 40, rel=1e-12)
