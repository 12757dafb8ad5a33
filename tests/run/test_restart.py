"""Rebuilding a dynamics from a checkpoint (rigidmd.run.restart)."""

import warnings

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from helpers import PeriodicLJ, dimer_fluid, npt, waters

from rigidmd import (
    RigidBussi,
    RigidDynamics,
    RigidLangevin,
    RigidLangevinBAOAB,
    RigidNoseHoover,
    RigidVerlet,
)
from rigidmd.core.checkpoint import CheckpointError, read_checkpoint
from rigidmd.couplings.thermostats import BussiThermostat
from rigidmd.run.restart import load_checkpoint
from rigidmd.systems import water_cluster


def test_a_thermostatted_run_continues_exactly(tmp_path):
    atoms = water_cluster(4, seed=2)
    atoms.calc = TIP3P(rc=8.0)
    dyn = RigidBussi(atoms, 1 * units.fs, temperature_K=300, taut=50 * units.fs,
                     rng=np.random.default_rng(3))
    dyn.run(3)
    dyn.save_checkpoint(tmp_path / "c.npz")
    dyn.run(4)
    again = load_checkpoint(tmp_path / "c.npz", TIP3P(rc=8.0))
    assert type(again) is RigidBussi and again.nsteps == 3
    assert again.thermostat.kind == "bussi" and not hasattr(again, "barostat")
    assert again.taut == dyn.taut
    again.run(4)
    assert np.array_equal(again.atoms.positions, dyn.atoms.positions)
    assert again.thermostat_work == dyn.thermostat_work
    assert again.get_time() == pytest.approx(dyn.get_time())


def test_a_read_checkpoint_and_a_calculator_state(tmp_path):
    class Stateful(TIP3P):
        def get_checkpoint_state(self):
            return {"calls": 7}

        def set_checkpoint_state(self, saved):
            self.saved = saved

    atoms = water_cluster(2, seed=1)
    atoms.calc = Stateful()
    dyn = RigidVerlet(atoms, 1 * units.fs)
    dyn.run(2)
    dyn.save_checkpoint(tmp_path / "c.npz")
    calc = Stateful()
    again = load_checkpoint(read_checkpoint(tmp_path / "c.npz"), calc)
    assert again.atoms.calc is calc and again.atoms is not atoms
    assert calc.saved == {"calls": 7}
    assert again.couplings == () or list(again.couplings) == []


# ---------------------------------------------------------------- the class that comes back
def _classes():
    """A small dynamics of every class of rigidmd.md, by name (builders of fresh ones)."""
    rng = np.random.default_rng
    return {
        "RigidVerlet": lambda: RigidVerlet(waters(2), units.fs),
        "RigidBussi": lambda: RigidBussi(waters(2), units.fs, 300, 50 * units.fs, rng(1)),
        "RigidLangevin": lambda: RigidLangevin(waters(2), units.fs, 300, 0.01 / units.fs,
                                               rng=rng(1)),
        "RigidLangevinBAOAB": lambda: RigidLangevinBAOAB(waters(2), units.fs, 300,
                                                         0.01 / units.fs, rng=rng(1)),
        "RigidNoseHoover": lambda: RigidNoseHoover(waters(2), units.fs, 300, 50 * units.fs),
        "RigidNPT": lambda: npt(_fluid(), "mtk"),
        "RigidCRescale": lambda: npt(_fluid(), "crescale"),
        "RigidMCBarostat": lambda: npt(_fluid(), "mc"),
    }


def _fluid():
    return dimer_fluid(n_side=3, rc=5.0)


def _calculator(dyn):
    return PeriodicLJ(rc=5.0) if dyn.atoms.pbc.all() else TIP3P(rc=40)


#: What each class adds to RigidDynamics, called on the loaded dynamics.
METHODS = {
    "RigidVerlet": lambda d: d.get_conserved_energy(),
    "RigidBussi": lambda d: (d.taut, d.thermostat_work, d.temperature_K),
    "RigidLangevin": lambda d: (d.friction, d.thermostat_work, d.set_friction(d.friction)),
    "RigidLangevinBAOAB": lambda d: (d.friction, d.set_friction(d.friction)),
    "RigidNoseHoover": lambda d: (d.tdamp, d.chain_energy(), d.thermostat_work),
    "RigidNPT": lambda d: (d.pressure_au, d.temperature_K),
    "RigidCRescale": lambda d: (d.pressure_au, d.temperature_K),
    "RigidMCBarostat": lambda d: (d.pressure_au, d.temperature_K),
}


@pytest.mark.parametrize("name", METHODS)
def test_a_checkpoint_comes_back_as_the_class_saved(name, tmp_path):
    """Every class of rigidmd.md returns as itself: its methods and properties on the
    loaded one give what they give on the saved one, ``todict()`` (``md-type`` and the
    class's own fields) is the same, and the class is in the file."""
    dyn = _classes()[name]()
    dyn.run(2)
    dyn.save_checkpoint(tmp_path / "c.npz")
    assert read_checkpoint(tmp_path / "c.npz").meta["class"] == name
    again = load_checkpoint(tmp_path / "c.npz", _calculator(dyn))
    assert type(again) is type(dyn) and again.nsteps == 2
    assert again.todict() == dyn.todict() and again.todict()["md-type"] == name
    assert METHODS[name](again) == METHODS[name](dyn)
    assert [type(p) for p in again.couplings] == [type(p) for p in dyn.couplings]
    again.run(2)
    dyn.run(2)
    np.testing.assert_array_equal(again.atoms.positions, dyn.atoms.positions)


def test_a_class_of_the_users_own_comes_back_as_its_nearest_base_with_a_warning(tmp_path):
    """rigidmd imports no class a file names: a subclass of RigidBussi returns as a
    RigidBussi, one of RigidDynamics as a RigidDynamics, each with a warning naming it;
    ``dynamics_class=`` gives it back as the user's class, without a warning."""

    class MyBussi(RigidBussi):
        pass

    class MyDynamics(RigidDynamics):
        pass

    mine = MyBussi(waters(2), units.fs, 300, 50 * units.fs, np.random.default_rng(2))
    mine.save_checkpoint(tmp_path / "bussi.npz")
    with pytest.warns(UserWarning, match="the dynamics was a MyBussi, a class rigidmd does "
                                         "not rebuild; loaded as RigidBussi"):
        again = load_checkpoint(tmp_path / "bussi.npz", TIP3P(rc=40))
    assert type(again) is RigidBussi and again.taut == 50 * units.fs
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = load_checkpoint(tmp_path / "bussi.npz", TIP3P(rc=40), dynamics_class=MyBussi)
    assert type(again) is MyBussi and again.taut == 50 * units.fs
    with pytest.raises(TypeError, match="dynamics_class must be a subclass of RigidDynamics"):
        load_checkpoint(tmp_path / "bussi.npz", TIP3P(rc=40), dynamics_class=BussiThermostat)

    MyDynamics(waters(2), units.fs, couplings=[BussiThermostat(300, 50 * units.fs)]
               ).save_checkpoint(tmp_path / "plain.npz")
    with pytest.warns(UserWarning, match="was a MyDynamics.*loaded as RigidDynamics"):
        again = load_checkpoint(tmp_path / "plain.npz", TIP3P(rc=40))
    assert type(again) is RigidDynamics and again.thermostat.kind == "bussi"


def _rewrite_meta(path, change):
    """Rewrite the checkpoint at ``path`` with ``change(meta)`` applied to its metadata."""
    import json

    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    meta = json.loads(str(arrays["meta"]))
    change(meta)
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)


def test_a_checkpoint_that_names_no_class_comes_back_as_rigid_dynamics(tmp_path):
    """As a file written before the class was stored: a RigidDynamics with the parts."""
    dyn = _classes()["RigidBussi"]()
    dyn.run(2)
    dyn.save_checkpoint(tmp_path / "c.npz")
    _rewrite_meta(tmp_path / "c.npz", lambda meta: (meta.pop("class"), meta.pop("classes")))
    again = load_checkpoint(tmp_path / "c.npz", TIP3P(rc=40))
    assert type(again) is RigidDynamics and again.thermostat.kind == "bussi"
    again.run(2)
    dyn.run(2)
    np.testing.assert_array_equal(again.atoms.positions, dyn.atoms.positions)


def test_a_class_whose_parts_the_file_does_not_hold_is_refused_in_one_line(tmp_path):
    dyn = _classes()["RigidBussi"]()
    dyn.save_checkpoint(tmp_path / "c.npz")
    _rewrite_meta(tmp_path / "c.npz", lambda meta: meta.update(classes=["RigidNoseHoover"]))
    calc = TIP3P(rc=40)
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(tmp_path / "c.npz", calc)
    assert str(err.value) == ("checkpoint: RigidNoseHoover is built around the parts "
                              "NoseHooverThermostat; got BussiThermostat")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("kind", ["mtk", "crescale"])
def test_a_checkpoint_written_before_the_first_force_call_continues_exactly(kind, backend,
                                                                            tmp_path):
    """Saved before any step (no forces yet: the file says so), loaded, run: the
    uninterrupted run's bits, the barostat's first step with its virial."""
    reference = npt(_fluid(), kind, backend=backend)
    reference.run(3)
    npt(_fluid(), kind, backend=backend).save_checkpoint(tmp_path / "c.npz")
    assert read_checkpoint(tmp_path / "c.npz").meta["record"]["forces_known"] is False
    again = load_checkpoint(tmp_path / "c.npz", _calculator(reference))
    again.run(3)
    np.testing.assert_array_equal(again.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(again.atoms.cell.array, reference.atoms.cell.array)
    assert again.get_conserved_energy() == reference.get_conserved_energy()
