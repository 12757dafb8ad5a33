"""The per-step record's sums follow every change of the state, on every path (property test).

The record (:class:`rigidmd.core.record.StepRecord`) keeps the volume, the kinetic
tensor and the rotational energy with the versions of the state they describe
(:attr:`rigidmd.core.state.RigidState.versions`); nobody invalidates them by hand.
Here random sequences of changes go through every path that changes the state (the
Atoms changed between steps, an observer that changes them, ``set_state``, a failed
step's rollback, the coupling parts' half steps and middle action, a barostat's cell
move, the scheme's operators and kernels) and, before and after each part's action and
each step, every cached sum is compared with a fresh one
(:mod:`rigidmd.core.observables`).  A path that changed the state without moving its
version leaves a sum of the old state, which differs by far more than the bound.
"""

import numpy as np
import pytest
from ase import units
from helpers import PeriodicLJ, dimer_fluid
from hypothesis_or_skip import HealthCheck, given, settings, st

import rigidmd
from rigidmd.core import observables as obs
from rigidmd.couplings.baoab import LangevinBAOABThermostat
from rigidmd.couplings.barostats import CRescaleBarostat, MTKBarostat
from rigidmd.couplings.montecarlo import MonteCarloBarostat
from rigidmd.couplings.thermostats import LangevinThermostat, NoseHooverThermostat

DT = 5 * units.fs
T, P = 80.0, 50 * units.bar

# Measured: a sum carried through a known scaling (StepRecord.scaled) and the fresh sum
# of the scaled arrays differ by at most 8e-16 relative (every case, both backends, 40
# steps and each change; roundoff of the two orders of arithmetic); a stale sum, after a
# change these tests make, by 2e-3 or more (the smallest: a volume after a strain; kicks
# and scalings change the kinetic sums by 2e-2 to 0.5).  The bound sits between.
RTOL = 1e-10


class FailingLJ(PeriodicLJ):
    """PeriodicLJ whose next call raises when ``armed`` (a failed step, then a rollback)."""

    armed = False

    def calculate(self, *args, **kwargs):
        if self.armed:
            self.armed = False
            raise RuntimeError("the calculator failed (on purpose)")
        super().calculate(*args, **kwargs)


def make(case, backend, scheme="no_squish"):
    """A dynamics of 25 rigid dimers and 4 free atoms in a periodic box, for ``case``, with
    the integrator ``scheme`` where the case takes one (not BAOAB's or r-RESPA's)."""
    atoms = dimer_fluid(n_side=3, spacing=4.6, seed=5, temperature_K=80, rc=5.5)
    tags = atoms.get_tags()
    tags[:4] = 0  # two dimers become four free atoms: the point particles' paths too
    atoms.set_tags(tags)
    rigidmd.rigid_maxwell_boltzmann(atoms, 80, bodies="tags", rng=np.random.default_rng(5))
    atoms.calc = FailingLJ(rc=5.5)
    rng = np.random.default_rng(11)
    common = dict(bodies="tags", backend=backend)
    if "baoab" not in case and not case.startswith("respa"):
        common["integrator"] = scheme
    if case.startswith("respa"):  # two levels, each with its record (SplitRecord)
        atoms.calc = rigidmd.MultipleTimeStep(FailingLJ(rc=5.5, epsilon=0.005),
                                              PeriodicLJ(rc=5.5, epsilon=0.001), substeps=3)
        case = case.removeprefix("respa_")
    if case == "bussi":
        return rigidmd.RigidBussi(atoms, DT, T, 100 * units.fs, rng=rng, **common)
    if case == "langevin":
        return rigidmd.RigidLangevin(atoms, DT, T, 0.01, rng=rng, **common)
    if case == "baoab":
        return rigidmd.RigidLangevinBAOAB(atoms, DT, T, 0.01, rng=rng, **common)
    if case == "baoab_fixcm_false":  # no shift of the centre after the O step
        return rigidmd.RigidDynamics(atoms, DT, couplings=[
            LangevinBAOABThermostat(T, 0.01, rng=rng, fixcm=False)], **common)
    if case == "nose_hoover_mtk":
        return rigidmd.RigidDynamics(atoms, DT, couplings=[
            NoseHooverThermostat(T, 100 * units.fs),
            MTKBarostat(T, P, 1000 * units.fs, couple="aniso")], **common)
    if case == "langevin_crescale":
        return rigidmd.RigidDynamics(atoms, DT, couplings=[
            LangevinThermostat(T, 0.01, rng=rng, fixcm=False),
            CRescaleBarostat(T, P, 500 * units.fs, 1e-4 / units.bar, rng=rng)], **common)
    if case == "monte_carlo":
        return rigidmd.RigidDynamics(atoms, DT, couplings=[
            LangevinThermostat(T, 0.01, rng=rng, fixcm=False),
            MonteCarloBarostat(T, P, every=2, rng=rng, step=0.02)], **common)
    raise ValueError(case)


def check(dyn, where):
    """Every sum the record keeps equals a fresh one of the state as it is now."""
    record, state, model = dyn.record, dyn.state, dyn.model
    np.testing.assert_allclose(record.volume, obs.volume(state.cell), rtol=RTOL,
                               err_msg=f"volume, {where}")
    np.testing.assert_allclose(record.kinetic_tensor, obs.kinetic_tensor(state, model),
                               rtol=RTOL, atol=1e-14, err_msg=f"kinetic tensor, {where}")
    np.testing.assert_allclose(record.rotational_energy,
                               obs.rotational_kinetic_energy(state, model), rtol=RTOL,
                               err_msg=f"rotational energy, {where}")
    for level in (getattr(record, "fast", None), getattr(record, "slow", None)):
        if level is not None:  # a split's levels: the same state, the same versions
            np.testing.assert_allclose(level.volume, obs.volume(state.cell), rtol=RTOL,
                                       err_msg=f"a level's volume, {where}")


def checked(dyn, action, where):
    """``action(view, h)`` with the record checked before and after it."""
    def run(view, h):
        check(dyn, f"before {where}")
        action(view, h)
        check(dyn, f"after {where}")

    return run


def watch(dyn):
    """Check the record before and after every part's half step and middle action, and
    at the start of every step (after the Atoms' changes were read)."""
    for part in dyn.couplings:
        names = ("first_half", "second_half") + (("middle",) if part.acts_in_middle else ())
        for name in names:
            setattr(part, name, checked(dyn, getattr(part, name), f"{part.kind}.{name}"))
    step = dyn.stepper.step

    def checked_step(*args, **kwargs):
        check(dyn, "at the start of the step")
        step(*args, **kwargs)

    dyn.stepper.step = checked_step


def change_atoms(atoms, rng, what):
    """Change the Atoms as a user or an observer may: kick, move, or strain the cell."""
    if what == "kick":
        atoms.set_momenta(atoms.get_momenta() * rng.uniform(0.5, 1.5, (len(atoms), 1)))
    elif what == "scale":  # one factor for all: the record may not keep the old sums
        atoms.set_momenta(atoms.get_momenta() * rng.uniform(0.5, 1.5))
    elif what == "move":
        atoms.positions = atoms.positions + rng.normal(0, 0.05, 3)  # a rigid shift
    else:  # "strain": the cell and the positions with it
        atoms.set_cell(atoms.cell.array * rng.uniform(0.99, 1.01), scale_atoms=True)


ACTIONS = ("step", "between_steps", "observer", "set_state", "rollback", "irun")
CHANGES = ("kick", "scale", "move", "strain")
#: The integrators whose operators write the state (the fused kernel: no_squish on numba).
SCHEMES = ("no_squish", "richardson", "rozmanov_kusalik", "pcdm", "exadem")
CASES = ("bussi", "langevin", "baoab", "baoab_fixcm_false", "nose_hoover_mtk",
         "langevin_crescale", "monte_carlo", "respa_bussi", "respa_nose_hoover_mtk")


@pytest.mark.filterwarnings("ignore:.*rigid image of the body")
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=st.sampled_from(CASES), backend=st.sampled_from(("numpy", "numba")),
       scheme=st.sampled_from(SCHEMES),
       actions=st.lists(st.tuples(st.sampled_from(ACTIONS), st.sampled_from(CHANGES)),
                        min_size=1, max_size=6),
       seed=st.integers(0, 2**16))
def test_the_record_follows_every_change_of_the_state(case, backend, scheme, actions, seed):
    rng = np.random.default_rng(seed)
    dyn = make(case, backend, scheme)
    watch(dyn)
    atoms = dyn.atoms
    check(dyn, "after construction")
    saved = dyn.get_state()  # before the first force call: restored, the start calls it
    for action, change in actions:
        where = f"after {action} ({change})"
        if action == "step":
            dyn.run(1)
        elif action == "between_steps":  # read at the next run's start
            change_atoms(atoms, rng, change)
            dyn.run(1)
        elif action == "observer":  # changes the Atoms after the step; read before the next
            def observer(_change=change):
                change_atoms(atoms, rng, _change)

            dyn.attach(observer, interval=1)
            dyn.run(2)
            dyn.observers.remove(dyn.observers[-1])
        elif action == "irun":  # the caller changes the Atoms between the generator's items
            for i, _ in enumerate(dyn.irun(2)):
                if i == 1:
                    change_atoms(atoms, rng, change)
        elif action == "set_state":
            dyn.set_state(saved)
        else:  # "rollback": the step fails at its force call and is undone
            check(dyn, "before the failing step")  # the sums kept, then restored
            steps = dyn.irun(1)
            next(steps)  # the run's start (which may find the forces current: no call)
            calc = getattr(atoms.calc, "fast", atoms.calc)
            # The step's own call fails: armed, and no cached result (after set_state the
            # step may return to positions the calculator holds results for).
            calc.armed, calc.results = True, {}
            with pytest.raises(RuntimeError, match="on purpose"):
                next(steps)
        check(dyn, where)
        if rng.random() < 0.3:
            saved = dyn.get_state()
