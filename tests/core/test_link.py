"""Atoms ↔ rigid state, on the backend chosen once (rigidmd.core.link).

The atoms' sync between steps, as a dynamics uses it, is checked in ``test_stepper.py``
and ``test_dynamics.py``; here the link's own conversions."""

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from helpers import ZeroForce, count_calls, mixture, tip3p_calls, waters

from rigidmd import RigidBussi, RigidVerlet, load_checkpoint
from rigidmd.core.link import BodyLink


@pytest.fixture(params=["numpy", "numba"])
def dyn(request):
    return RigidVerlet(mixture(), 1 * units.fs, backend=request.param)


def test_place_and_momenta_reproduce_the_atoms(dyn):
    link, state, atoms = dyn.link, dyn.state, dyn.atoms
    assert link.backend.name == dyn.backend
    positions, momenta = atoms.positions.copy(), atoms.get_momenta().copy()
    atoms.arrays["positions"][:] = 0.0
    atoms.arrays["momenta"][:] = 0.0
    r = link.place(state)
    link.write_momenta(state, r)
    assert np.allclose(atoms.positions, positions, atol=1e-12)
    assert np.allclose(atoms.get_momenta(), momenta, atol=1e-12)
    body, speed = link.largest_angular_speed(state)
    assert 0 <= body < dyn.model.n_bodies and speed > 0


def test_reading_back_projects_onto_rigid_motion(dyn):
    link, state, atoms = dyn.link, dyn.state, dyn.atoms
    copy = state.copy()
    assert link.read_momenta(state) == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(state.data, copy.data, atol=1e-12)
    momenta = atoms.get_momenta()
    momenta[0] += [0.5, 0.0, 0.0]  # not a rigid motion of body 0
    atoms.set_momenta(momenta, apply_constraint=False)
    with pytest.warns(UserWarning, match="Owner: projecting the atoms' velocities onto "
                                         "rigid-body motion removed"):
        removed = link.read_momenta(state, owner="Owner")
    assert removed > 0 and link.removed_kinetic_energy == removed
    atoms.positions[:] += [0.1, 0.2, 0.3]
    link.read_positions(state)
    assert np.allclose(state.X, copy.X + [0.1, 0.2, 0.3], atol=1e-10)
    assert np.allclose(state.x, copy.x + [0.1, 0.2, 0.3], atol=1e-12)


def test_changes_between_steps_are_noticed(dyn):
    link, atoms = dyn.link, dyn.atoms
    written = link.snapshot()
    assert not link.differs(written)
    assert link.changes_since(written, "before step 1") == (False, False)
    atoms.positions[3, 0] += 0.01
    assert link.differs(written)
    assert link.changes_since(written, "before step 1") == (True, False)
    momenta = atoms.get_momenta()
    momenta[2, 1] = np.nan
    atoms.set_momenta(momenta, apply_constraint=False)
    with pytest.raises(ValueError, match="atom 2 has a non-finite momentum .* before step 1"):
        link.changes_since(written, "before step 1")
    link.check_unchanged_system()
    atoms.set_masses(np.r_[atoms.get_masses()[:-1], 30.0])
    with pytest.raises(ValueError, match="the atoms' masses changed; create a new dynamics"):
        link.check_unchanged_system()
    atoms.constraints = []
    del atoms[-1]
    with pytest.raises(ValueError, match="the atoms changed from 26 to 25"):
        link.check_unchanged_system()


def test_an_unknown_backend_is_refused():
    dyn = RigidVerlet(mixture(), 1 * units.fs)
    with pytest.raises(ValueError, match="backend must be 'numba' or 'numpy', got 'cuda'"):
        BodyLink(dyn.atoms, dyn.model, "cuda")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_run_in_pieces_or_through_a_checkpoint_is_the_run_in_one(backend, tmp_path):
    """A run's start asks the calculator again only if its forces are not the record's: a
    new call would reduce the forces to the bodies with NumPy, where the compiled step had
    used its kernel, and the pieces would differ from the whole in the last bit (they did:
    8.9e-16 Å after 20 steps of 32 waters, on the compiled backend only)."""
    def bussi(atoms):
        return RigidBussi(atoms, 1 * units.fs, 300, 50 * units.fs,
                          rng=np.random.default_rng(1), backend=backend)

    whole = waters(32, temperature_K=200)
    bussi(whole).run(20)
    pieces = waters(32, temperature_K=200)
    dyn = bussi(pieces)
    dyn.run(7)
    dyn.run(0)
    dyn.run(13)
    assert np.array_equal(pieces.positions, whole.positions)
    assert np.array_equal(pieces.get_momenta(), whole.get_momenta())
    restored = waters(32, temperature_K=200)
    dyn = bussi(restored)
    dyn.run(9)
    dyn.save_checkpoint(tmp_path / "c.npz")
    again = load_checkpoint(tmp_path / "c.npz", TIP3P(rc=40))
    again.run(11)
    assert np.array_equal(again.atoms.positions, whole.positions)


def test_a_run_start_calls_the_calculator_only_when_its_forces_are_not_current(monkeypatch):
    calls = tip3p_calls(monkeypatch)
    atoms = waters(8)
    dyn = RigidVerlet(atoms, 1 * units.fs)
    dyn.run(3)
    assert len(calls) == 4  # the first start, then one per step
    dyn.run(3)
    assert len(calls) == 7  # the cache answered the second start
    atoms.calc.reset()  # what ASE's calc.set(...) does: the results are gone
    dyn.run(0)
    assert len(calls) == 8
    atoms.positions[0, 0] += 0.01  # moved: refitted and asked
    dyn.run(0)
    assert len(calls) == 9
    atoms.calc = TIP3P(rc=40)  # another calculator, even one of the same kind, is asked
    dyn.run(0)
    assert len(calls) == 10
    atoms.calc = ZeroForce()
    dyn.run(0)
    assert not dyn.record.F.any() and not dyn.record.tau.any()


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_split_run_in_pieces_is_the_run_in_one_without_asking_its_levels_again(backend):
    """Under MultipleTimeStep a run's start asked both levels again (the split calculator
    holds no results of its own), which a level without a cache that answers (LAMMPS asked
    for more than it holds) computed again; its levels hold the results, so a start now asks
    neither while both still hold forces for these atoms: ``run(4); run(6)`` is ``run(10)``
    bit for bit, and the second run asks each level only for its steps.  A level reset is
    asked again."""
    from ase.calculators.lj import LennardJones

    from rigidmd import MultipleTimeStep

    def build():
        atoms = waters(4, seed=3)
        fast, slow = TIP3P(rc=4.0), LennardJones(sigma=3.0, epsilon=0.005, rc=6.0)
        asks = count_calls("get_forces", fast=fast, slow=slow)
        atoms.calc = MultipleTimeStep(fast, slow, substeps=3)
        return RigidVerlet(atoms, 2 * units.fs, backend=backend), asks, slow

    whole, _, _ = build()
    whole.run(10)
    pieces, asks, slow = build()
    pieces.run(4)
    before = dict(asks)
    pieces.run(6)
    assert (asks["fast"] - before["fast"], asks["slow"] - before["slow"]) == (18, 6)
    np.testing.assert_array_equal(pieces.atoms.positions, whole.atoms.positions)
    np.testing.assert_array_equal(pieces.atoms.get_momenta(), whole.atoms.get_momenta())
    slow.reset()
    before = dict(asks)
    pieces.run(1)  # the start asks both levels, then one step
    assert (asks["fast"] - before["fast"], asks["slow"] - before["slow"]) == (4, 2)


def test_each_dynamics_puts_its_own_degrees_of_freedom_on_the_atoms_when_it_runs():
    """Two dynamics on one Atoms: a thermostat's (fixcm, 21 for 4 waters) then an NVE one
    (24).  The NVE run kept the thermostat's marker, so ``atoms.get_temperature()`` (and
    ASE's MDLogger) read 216.37 K where 2K/(24 k_B) is 189.32 K (measured)."""
    from rigidmd import RigidLangevin

    atoms = waters(4)
    atoms.calc = TIP3P(rc=20.0)
    nve = RigidVerlet(atoms, 1 * units.fs)
    eq = RigidLangevin(atoms, 1 * units.fs, temperature_K=300, friction=0.01,
                       rng=np.random.default_rng(0))
    for dyn, dof in ((eq, 21), (nve, 24), (eq, 21)):
        dyn.run(2)
        assert dyn.degrees_of_freedom == dof
        assert atoms.get_number_of_degrees_of_freedom() == dof
        kinetic = atoms.get_kinetic_energy()
        assert atoms.get_temperature() == pytest.approx(2 * kinetic / (dof * units.kB),
                                                        rel=1e-12)
