"""MultipleTimeStep with two LAMMPS levels in one process (rigidmd.core.split's ``full=``).

64 equilibrated TIP4P/2005 waters (explicit M; ``validation/timestep_table``'s start of that
size).  The full model is ``lj/cut/coul/long`` at 6 Å (the box is 12.4 Å) with PPPM 1e-5 and
the Lennard-Jones energy shifted to zero at the cut-off (``pair_modify shift yes``, in place
of the tail correction: the unshifted energy jumps at each pair crossing 6 Å, a floor of
2.9e-3 eV under the conserved energy's fluctuation here, at every step size, which would hide
its Δt² law).  The fast level is ``WaterModel.lammps_short_range_commands(4.0)``
(``lj/smooth/linear`` and ``coul/dsf``), each in its own :class:`LAMMPSCalculator`; the slow
level is full less fast.  The measurements on 216 waters are in
``tests/physics/test_respa_lammps.py``.
"""

from pathlib import Path

import numpy as np
import pytest
from ase import Atoms, units
from helpers import count_calls

from rigidmd import MultipleTimeStep, RigidVerlet
from rigidmd.water import water_model

pytestmark = pytest.mark.lammps

ROOT = Path(__file__).resolve().parents[2]
START = ROOT / "validation" / "timestep_table.start_tip4p2005_64.npz"
TYPES = {"O": 1, "H": 2, "X": 3}
MODEL = water_model("tip4p2005")


def start():
    with np.load(START) as d:
        atoms = Atoms(numbers=d["numbers"], positions=d["positions"], cell=d["cell"],
                      pbc=True)
        atoms.set_masses(np.tile(MODEL.masses(), 64))
        atoms.set_momenta(d["momenta"])
    atoms.set_initial_charges(MODEL.charges(64))
    atoms.set_tags(np.repeat(np.arange(1, 65), 4))
    return atoms


def full_model():
    from rigidmd.lammps import LAMMPSCalculator

    return LAMMPSCalculator(MODEL.lammps_commands(6.0, "pppm", 1e-5, tail=False)
                            + ["pair_modify shift yes"], atom_types=TYPES)


def lammps_split(k):
    """(split, full, fast): two LAMMPS instances, the slow level full less fast."""
    from rigidmd.lammps import LAMMPSCalculator

    full = full_model()
    fast = LAMMPSCalculator(MODEL.lammps_short_range_commands(4.0), atom_types=TYPES)
    return MultipleTimeStep(fast, full=full, substeps=k), full, fast


def test_the_split_is_the_full_model_to_roundoff():
    """Measured: energy equal to the last bit, forces 2e-16 eV/Å, stress 1e-19 eV/Å³ apart
    (the sum (full - fast) + fast rounds once per term; the fast energy is -397 eV, its
    largest force 3 eV/Å: 1e-12 eV, 1e-14 eV/Å and 1e-16 eV/Å³ allow for that)."""
    atoms = start()
    atoms.calc, _, fast = lammps_split(4)
    reference = start()
    reference.calc = full_model()
    assert atoms.get_potential_energy() == pytest.approx(reference.get_potential_energy(),
                                                         rel=0, abs=1e-12)
    np.testing.assert_allclose(atoms.get_forces(), reference.get_forces(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(atoms.get_stress(), reference.get_stress(), rtol=0, atol=1e-16)
    # the fast level is a real part of the forces, not zero (cut-off 4 Å, no k-space)
    assert abs(fast.get_potential_energy(atoms)) > 100
    assert np.abs(fast.get_forces(atoms)).max() > 1


def test_each_level_is_one_lammps_instance_set_up_once():
    """A dynamics under the split calls the fast instance k times and the full one once per
    outer step, also on steps an observer asks for the energy (ASE's
    ``LinearCombinationCalculator`` as the slow level called LAMMPS a second time there:
    it asks one property at a time), and neither sets LAMMPS up again."""
    atoms = start()
    atoms.calc, full, fast = lammps_split(3)
    calls = count_calls("calculate", full=full, fast=fast)
    dyn = RigidVerlet(atoms, 3 * units.fs)
    dyn.run(1)
    instances = full._instance, fast._instance
    assert None not in instances
    before = dict(calls)
    dyn.run(5)
    assert (calls["fast"] - before["fast"], calls["full"] - before["full"]) == (15, 5)
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=1)
    dyn.run(4)  # the observer at its start asks the energy of the present positions
    before = dict(calls)
    dyn.run(5)
    assert (calls["fast"] - before["fast"], calls["full"] - before["full"]) == (15, 5)
    assert len(energies) == 9 and np.ptp(energies) < 0.1  # one a step; 27 fs of NVE
    assert (full._instance, fast._instance) == instances


def test_nve_energy_fluctuation_falls_as_the_outer_step_squared():
    """NVE, k = 4, outer steps of 1, 2 and 4 fs, 100 fs each from the equilibrated start.

    Measured: std of the conserved energy 3.99e-4, 1.44e-3, 4.93e-3 eV, exponents 1.85 and
    1.78 (with k = 1: 1.00e-3, 3.78e-3, 1.53e-2 eV, exponents 1.92 and 2.02): r-RESPA's
    error is second order, and the higher orders lower the exponent a little at 4 fs.  The
    fitted exponent is bound to 1.6-2.3 (a first-order error gives 1, a resonance far more
    than 2).  At 2 fs, k = 4 is 2.6 times below k = 1 (bound: 1.5): the fast level carries
    the fast forces.
    """
    split, _, _ = lammps_split(4)
    spread = {}
    for k, dts in ((4, (1.0, 2.0, 4.0)), (1, (2.0,))):
        split.substeps = k
        for dt in dts:
            atoms = start()
            atoms.calc = split
            dyn = RigidVerlet(atoms, dt * units.fs)
            energies = [dyn.get_conserved_energy() for _ in dyn.irun(int(round(100 / dt)))]
            spread[k, dt] = np.std(energies)
    dts = np.array([1.0, 2.0, 4.0])
    exponent = np.polyfit(np.log(dts), np.log([spread[4, dt] for dt in dts]), 1)[0]
    assert 1.6 < exponent < 2.3, (exponent, spread)
    assert spread[1, 2.0] / spread[4, 2.0] > 1.5, spread


def test_two_engines_are_the_in_process_split_to_roundoff():
    """Each level a LAMMPSEngine (its own processes, set up once): 20 steps at k = 4 follow
    the split of two in-process instances (measured 7e-15 Å, the same energy; bound 1e-12 Å,
    the roundoff growth the engine tests allow), and each engine's processes end with it."""
    from helpers import processes_named

    from rigidmd.ipi.processes import descendants
    from rigidmd.lammps import LAMMPSCalculator
    from rigidmd.lammps.engine import LAMMPSEngine

    full_commands = MODEL.lammps_commands(6.0, "pppm", 1e-5, tail=False) + [
        "pair_modify shift yes"]
    fast_commands = MODEL.lammps_short_range_commands(4.0)
    runs = []
    for kind in (LAMMPSCalculator, LAMMPSEngine):
        atoms = start()
        fast, full = (kind(commands, atom_types=TYPES)
                      for commands in (fast_commands, full_commands))
        atoms.calc = MultipleTimeStep(fast, full=full, substeps=4)
        RigidVerlet(atoms, 4 * units.fs, bodies="tags").run(20)
        runs.append((atoms.positions.copy(), atoms.get_potential_energy()))
        if kind is LAMMPSEngine:  # one LAMMPS rank of each engine
            ranks = [p for engine in (fast, full) for p in descendants(engine.pid)
                     if p in processes_named("lmp")]
            assert len(ranks) == 2
        atoms.calc.close()
    assert np.abs(runs[0][0] - runs[1][0]).max() < 1e-12
    assert runs[0][1] == pytest.approx(runs[1][1], abs=1e-9)
    assert not [p for p in ranks if p in processes_named("lmp")]
