"""Each part of a rigid dynamics on its own: link, evaluator, record, stepper, coupling parts.

The parts are built by hand (no :class:`~rigidmd.RigidDynamics` unless the test is
about what a dynamics composes): a coupling part gets a :class:`CouplingView` of a
state, model and record made here, and its half step is checked against what it
promises (the energy it exchanges, the direction a pressure moves the cell).
"""

import numpy as np
import pytest
from ase import units
from helpers import CoulombLJ, PeriodicLJ, ZeroForce, dimer_fluid, mixture

from rigidmd import RigidBussi, RigidCRescale, RigidLangevinBAOAB, RigidNPT, RigidVerlet
from rigidmd.core import observables as obs
from rigidmd.core.bodies import RigidBodies
from rigidmd.core.forces import ForceEvaluator, NonFiniteForceError
from rigidmd.core.link import AtomsSync, BodyLink
from rigidmd.core.model import BodyModel
from rigidmd.core.record import StepRecord
from rigidmd.couplings.baoab import LangevinBAOABThermostat
from rigidmd.couplings.barostats import CRescaleBarostat, MTKBarostat
from rigidmd.couplings.base import CouplingView
from rigidmd.couplings.thermostats import (
    BussiThermostat,
    LangevinThermostat,
    NoseHooverThermostat,
)


def parts(atoms, bodies="mol-id", backend="numpy"):
    """Link, state and record of ``atoms`` made by hand, momenta read."""
    rigid = RigidBodies.resolve(atoms, bodies)
    geometry = rigid.geometry(atoms)
    link = BodyLink(atoms, geometry.model, backend)
    state = link.initial_state(geometry)
    link.read_momenta(state)
    return link, state, StepRecord(state, geometry.model)


def kinetic(view):
    """Kinetic energy of the view's state (eV), computed afresh."""
    return float(obs.translational_kinetic_energies(view.state, view.model).sum()
                 + obs.free_kinetic_energy(view.state, view.model)
                 + obs.rotational_kinetic_energy(view.state, view.model))


# ------------------------------------------------------------------ the body link
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_link_places_atoms_and_reads_them_back(backend):
    atoms = mixture()
    link, state, _ = parts(atoms, backend=backend)
    model = link.model
    r = link.place(state)
    # x_i = X_b + R(q_b) d_i for every body atom; free atoms where the state has them.
    np.testing.assert_allclose(atoms.positions[model.order],
                               state.X[model.atom_body] + r, atol=1e-12)
    np.testing.assert_array_equal(atoms.positions[model.free], state.x)
    link.write_momenta(state, r)
    again = link.initial_state(RigidBodies.resolve(atoms, "mol-id").geometry(atoms))
    link.read_momenta(again)
    np.testing.assert_allclose(again.V, state.V, atol=1e-12)
    np.testing.assert_allclose(obs.angular_velocities(again, model),
                               obs.angular_velocities(state, model), atol=1e-10)
    assert link.removed_kinetic_energy == pytest.approx(0.0, abs=1e-12)


def test_the_sync_notices_a_change_and_reads_it_once():
    atoms = mixture()
    link, state, record = parts(atoms)
    sync = AtomsSync(link, state, record, RigidBodies.resolve(atoms, "mol-id").body_ids,
                     fixcom=False, holds_momentum=False)
    sync.write_atoms()
    evaluations = []
    assert not sync.sync(sync.synced, lambda: evaluations.append(1), step=0)
    # An observer that shifts every atom: noted while it runs, read before the next step.
    shift = np.array([0.3, 0.0, 0.0])
    sync.call_observers([(lambda: atoms.set_positions(atoms.positions + shift), 1, (), {})],
                        step=1)
    assert sync.changed is not None
    X = state.X.copy()
    assert sync.before_step(lambda: evaluations.append(1), step=1)
    np.testing.assert_allclose(state.X, X + shift, atol=1e-12)
    assert evaluations == [1] and sync.changed is None
    assert not sync.before_step(lambda: evaluations.append(1), step=1)
    # An observer marked as only reading costs no snapshot (even if it did change the
    # Atoms, which it promised not to); one not due is not called.

    class Reader:
        modifies_atoms = False
        calls = 0

        def __call__(self):
            Reader.calls += 1
            atoms.positions[0] += 0.1

    sync.call_observers([(Reader(), 1, (), {}), (Reader(), 3, (), {})], step=4)
    assert Reader.calls == 1 and sync.changed is None


# ------------------------------------------------------------------ the force evaluator
class Counting(CoulombLJ):
    calls = 0

    def calculate(self, *args, **kwargs):
        Counting.calls += 1
        super().calculate(*args, **kwargs)


@pytest.mark.parametrize("energy", [False, True])
def test_the_evaluator_reduces_forces_and_computes_what_the_step_asks(energy):
    atoms = mixture()
    atoms.calc = Counting()
    link, state, record = parts(atoms)
    evaluator = ForceEvaluator(link, record)
    Counting.calls = 0
    evaluator.begin_step(7, energy=energy)
    evaluator.evaluate(state)
    assert Counting.calls == 1  # forces (and the energy) in one call
    forces = atoms.get_forces()
    model = link.model
    F = np.zeros((model.n_bodies, 3))
    np.add.at(F, model.atom_body, forces[model.order])
    np.testing.assert_allclose(record.F, F, atol=1e-12)
    tau = np.zeros((model.n_bodies, 3))
    np.add.at(tau, model.atom_body, np.cross(record.r, forces[model.order]))
    np.testing.assert_allclose(record.tau, tau, atol=1e-12)
    np.testing.assert_array_equal(record.f, forces[model.free])
    assert evaluator.energy_known is energy
    assert (record.energy is not None) is energy
    if energy:
        assert record.energy == pytest.approx(atoms.get_potential_energy(), abs=0)
    assert Counting.calls == 1


def test_the_evaluator_names_the_atom_of_a_non_finite_force():
    atoms = mixture()
    atoms.calc = ZeroForce()
    link, state, record = parts(atoms)
    evaluator = ForceEvaluator(link, record)
    forces = np.zeros((len(atoms), 3))
    forces[4, 1] = np.nan
    evaluator.begin_step(12)
    with pytest.raises(NonFiniteForceError, match=r"atom\(s\) \[4\] after step 12"):
        evaluator.check_forces(forces)


# ------------------------------------------------------------------ the per-step record
def fresh_and_cached(record, state, model):
    return [(record.volume, obs.volume(state.cell) if np.linalg.det(state.cell) else None),
            (record.kinetic_tensor, obs.kinetic_tensor(state, model)),
            (record.translational_energy,
             float(obs.translational_kinetic_energies(state, model).sum()
                   + obs.free_kinetic_energy(state, model))),
            (record.rotational_energy, obs.rotational_kinetic_energy(state, model))]


@pytest.mark.parametrize("kind", ["langevin", "bussi", "nose_hoover", "mtk", "crescale",
                                  "langevin_baoab"])
def test_the_record_equals_a_fresh_computation_after_every_half_step(kind):
    """What the record caches (volume, kinetic tensor and energies) is what the state gives,
    after each part's first and second half and after the scheme, at every step."""
    rng = np.random.default_rng(2)
    if kind in ("mtk", "crescale"):
        atoms = dimer_fluid(n_side=3, rc=5.0)
        part = (MTKBarostat(80, units.bar, 500 * units.fs) if kind == "mtk" else
                CRescaleBarostat(80, units.bar, 500 * units.fs, 1e-4 / units.bar, rng=rng))
        thermostat = NoseHooverThermostat(80, 50 * units.fs)
        couplings, bodies = [thermostat, part], "tags"
    else:
        atoms = mixture()
        part = {"langevin": LangevinThermostat(300, 0.01 / units.fs, rng=rng),
                "bussi": BussiThermostat(300, 20 * units.fs, rng=rng),
                "nose_hoover": NoseHooverThermostat(300, 20 * units.fs),
                "langevin_baoab": LangevinBAOABThermostat(300, 0.01 / units.fs, rng=rng)}[kind]
        couplings, bodies = [part], "mol-id"
    from rigidmd import RigidDynamics

    dyn = RigidDynamics(atoms, 2 * units.fs, bodies=bodies, couplings=couplings)
    checked = []

    def checking(method, where):
        def run(view, h):
            method(view, h)
            for cached, fresh in fresh_and_cached(view.record, view.state, view.model):
                if fresh is not None:
                    np.testing.assert_allclose(cached, fresh, rtol=1e-12, atol=1e-14,
                                               err_msg=where)
            checked.append(where)
        return run

    for p in couplings:
        p.first_half = checking(p.first_half, f"{p.kind} first half")
        p.second_half = checking(p.second_half, f"{p.kind} second half")
        if p.acts_in_middle:
            p.middle = checking(p.middle, f"{p.kind} middle half")
    for _ in range(6):
        dyn.run(1)
        for cached, fresh in fresh_and_cached(dyn.record, dyn.state, dyn.model):
            if fresh is not None:
                np.testing.assert_allclose(cached, fresh, rtol=1e-12, atol=1e-14)
    # (A part whose second half is its first half checks twice there.)
    assert set(checked) == {f"{p.kind} {half} half" for p in couplings
                            for half in ("first", "second")
                            + (("middle",) if p.acts_in_middle else ())}
    assert len(checked) >= 6 * 2 * len(couplings)


# ------------------------------------------------------------------ the stepper
class FailOn(CoulombLJ):
    """CoulombLJ that raises at its ``fail``-th calculation."""

    def __init__(self, fail):
        super().__init__()
        self.fail, self.count = fail, 0

    def calculate(self, *args, **kwargs):
        self.count += 1
        if self.count == self.fail:
            raise RuntimeError("calculator failed")
        super().calculate(*args, **kwargs)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_stepper_undoes_a_failed_step(backend):
    atoms = mixture()
    atoms.calc = FailOn(fail=4)
    dyn = RigidBussi(atoms, 2 * units.fs, 300, 20 * units.fs, bodies="mol-id",
                     rng=np.random.default_rng(0), backend=backend)
    dyn.run(2)  # calls 1-3
    stepper = dyn.stepper
    before = (dyn.state.copy(), dyn.record.F.copy(), dyn.record.tau.copy(),
              dyn.couplings[0].get_state(), atoms.positions.copy(), atoms.get_momenta(),
              stepper.time)
    with pytest.raises(RuntimeError, match="calculator failed"):
        stepper.step(dyn.dt, dyn.nsteps)
    state, F, tau, coupling, positions, momenta, time = before
    for name in ("X", "V", "q", "p", "x", "v", "cell"):
        np.testing.assert_array_equal(getattr(dyn.state, name), getattr(state, name))
    np.testing.assert_array_equal(dyn.record.F, F)
    np.testing.assert_array_equal(dyn.record.tau, tau)
    assert dyn.couplings[0].get_state()["work"] == coupling["work"]
    np.testing.assert_array_equal(atoms.positions, positions)
    np.testing.assert_array_equal(atoms.get_momenta(), momenta)
    assert stepper.time == time
    stepper.step(dyn.dt, dyn.nsteps)  # the next try goes through
    assert stepper.time == time + dyn.dt


# ------------------------------------------------------------------ coupling parts alone
def fake_view(atoms=None, bodies="mol-id"):
    """A CouplingView of a state, model and record made by hand (no dynamics, no evaluator)."""
    atoms = mixture() if atoms is None else atoms
    link, state, record = parts(atoms, bodies)
    return CouplingView(state, link.model, record, evaluator=None), atoms


@pytest.mark.parametrize("make", [
    lambda: BussiThermostat(300, 20 * units.fs, rng=np.random.default_rng(3)),
    lambda: LangevinThermostat(300, 0.02 / units.fs, rng=np.random.default_rng(3)),
])
def test_a_stochastic_thermostat_books_the_energy_it_exchanges(make):
    """Kinetic energy plus the part's term does not change in its half steps."""
    view, atoms = fake_view()
    part = make()
    part.check(atoms, view.model, units.fs)
    part.bind(view)
    start = kinetic(view) + part.energy(view)
    K = kinetic(view)
    for _ in range(5):
        part.first_half(view, units.fs)
        part.second_half(view, units.fs)
    assert kinetic(view) != pytest.approx(K, rel=1e-6)  # it did act
    assert kinetic(view) + part.energy(view) == pytest.approx(start, rel=1e-12)


def test_baoab_books_the_energy_its_O_step_exchanges():
    """Kinetic energy plus the part's term does not change in its middle (O) step."""
    view, atoms = fake_view()
    part = LangevinBAOABThermostat(300, 0.02 / units.fs, rng=np.random.default_rng(3))
    part.check(atoms, view.model, units.fs)
    part.bind(view)
    start = kinetic(view) + part.energy(view)
    K = kinetic(view)
    for _ in range(5):
        part.first_half(view, units.fs)  # nothing
        part.middle(view, units.fs)
        part.second_half(view, units.fs)  # nothing
    assert kinetic(view) != pytest.approx(K, rel=1e-6)  # it did act
    assert kinetic(view) + part.energy(view) == pytest.approx(start, rel=1e-12)
    assert part.reported == pytest.approx(part.kinetic_energies(view), rel=1e-12)


def test_nose_hoover_keeps_its_extended_energy_to_second_order_on_a_fake_view():
    """Without forces, K + the chain's energy is a constant of the chain's flow; its
    half steps (a Trotter splitting) keep it to O(h^2).  Measured over 10 fs from a start
    far hotter than 100 K: drift -3.5e-5, -9.0e-6, -2.3e-6, -5.7e-7 eV at h = 1, 0.5,
    0.25, 0.125 fs (ratio 3.9-4.0 per halving)."""
    drifts = []
    for h, n in [(1.0, 10), (0.5, 20)]:
        view, atoms = fake_view()
        part = NoseHooverThermostat(100, 20 * units.fs, fixcm=False)  # (as measured)
        part.check(atoms, view.model, units.fs)
        part.bind(view)
        start, K = kinetic(view) + part.energy(view), kinetic(view)
        for _ in range(n):
            part.first_half(view, h * units.fs)
            part.second_half(view, h * units.fs)
        assert kinetic(view) < 0.6 * K  # cooling towards 100 K
        drifts.append(abs(kinetic(view) + part.energy(view) - start))
    assert drifts[0] < 1e-4
    assert 3.5 < drifts[0] / drifts[1] < 4.5


@pytest.mark.parametrize("pressure_sign", [1.0, -1.0])
@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_a_barostat_moves_the_cell_towards_its_target_on_a_fake_view(kind, pressure_sign):
    """An internal pressure far above the target expands the cell, far below shrinks it."""
    atoms = dimer_fluid(n_side=3, rc=5.0)
    atoms.calc = PeriodicLJ(rc=5.0)
    view, _ = fake_view(atoms, bodies="tags")
    # The virial of a pressure of +-10 kbar (the kinetic part is small beside it).
    view.record.virial = pressure_sign * 1e4 * units.bar * view.record.volume * np.eye(3)
    part = (MTKBarostat(80, units.bar, 200 * units.fs) if kind == "mtk" else
            CRescaleBarostat(80, units.bar, 200 * units.fs, 1e-4 / units.bar,
                             rng=np.random.default_rng(0)))
    part.check(atoms, view.model, units.fs)
    part.bind(view)
    part.first_half(view, units.fs)
    A = part.drift_matrices(view, units.fs)[0]
    assert np.sign(np.linalg.det(A) - 1.0) == pressure_sign


# ------------------------------------------------------------------ one model for every part
def model_holders(dyn):
    """Every BodyModel reachable from the dynamics' attributes, with where it was found."""
    found, seen = [], set()

    def walk(obj, where, depth):
        if isinstance(obj, BodyModel):  # every holder counts, the same object or not
            found.append((where, obj))
            return
        if id(obj) in seen or depth > 4:
            return
        seen.add(id(obj))
        if isinstance(obj, (list, tuple)):
            for i, item in enumerate(obj):
                walk(item, f"{where}[{i}]", depth + 1)
            return
        if type(obj).__module__.startswith("rigidmd") and hasattr(obj, "__dict__"):
            for name, value in vars(obj).items():
                walk(value, f"{where}.{name}", depth + 1)

    walk(dyn, "dyn", 0)
    return found


@pytest.mark.parametrize("build", [
    lambda: RigidBussi(mixture(), 2 * units.fs, 300, 20 * units.fs, bodies="mol-id",
                       rng=np.random.default_rng(1)),
    lambda: RigidNPT(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, 80, units.bar,
                     50 * units.fs, 500 * units.fs, bodies="tags"),
    lambda: RigidCRescale(dimer_fluid(n_side=3, rc=5.0), 2 * units.fs, 80, units.bar,
                          50 * units.fs, 500 * units.fs, 1e-4 / units.bar, bodies="tags",
                          rng=np.random.default_rng(1)),
    lambda: RigidVerlet(mixture(), 2 * units.fs, bodies="mol-id", backend="numba"),
    lambda: RigidLangevinBAOAB(mixture(), 2 * units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                               rng=np.random.default_rng(1)),
])
def test_a_restore_leaves_no_part_with_the_old_model(build):
    dyn = build()
    dyn.run(3)
    saved = dyn.get_state()
    # A model that differs from the measured one (as a checkpoint's may, by roundoff).
    saved["model"]["body_coordinates"] = saved["model"]["body_coordinates"] * (1 + 1e-9)
    other = build()
    holders = model_holders(other)
    assert len(holders) >= 5  # dyn, link, record, evaluator, the step's one view, ...
    other.set_state(saved)
    for where, model in model_holders(other):
        assert model is other.model, where
        np.testing.assert_array_equal(model.body_coordinates,
                                      saved["model"]["body_coordinates"], err_msg=where)
    np.testing.assert_array_equal(other.stepper.context.model.packed[1][:, :3],
                                  saved["model"]["body_coordinates"])
    other.run(2)  # and the step runs with it
