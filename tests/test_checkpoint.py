"""Checkpoints: exact continuation of every kind of dynamics, and what a file holds."""

import numpy as np
import pytest
from ase import units
from helpers import CoulombLJ, PeriodicLJ, dimer_fluid, mixture

from rigidmd import (
    RigidBussi,
    RigidCRescale,
    RigidLangevin,
    RigidNoseHoover,
    RigidNPT,
    RigidVerlet,
    load_checkpoint,
)
from rigidmd.checkpoint import CheckpointError, read_checkpoint

KINDS = ["nve", "langevin", "bussi", "nose_hoover", "mtk", "crescale"]


def build(kind, integrator="no_squish"):
    """A dynamics of each kind: the CO2/water/neon droplet, or the dimer liquid for NPT."""
    rng = np.random.default_rng(5)
    if kind in ("mtk", "crescale"):
        atoms = dimer_fluid(n_side=4, rc=7.0)
        if kind == "mtk":
            return RigidNPT(atoms, 2 * units.fs, 80, units.bar, 50 * units.fs, 500 * units.fs,
                            bodies="tags", integrator=integrator)
        return RigidCRescale(atoms, 2 * units.fs, 80, units.bar, 50 * units.fs, 500 * units.fs,
                             1e-4 / units.bar, bodies="tags", rng=rng, integrator=integrator)
    atoms = mixture()
    kwargs = {"bodies": "mol-id", "integrator": integrator}
    if kind == "nve":
        return RigidVerlet(atoms, 2 * units.fs, **kwargs)
    if kind == "langevin":
        return RigidLangevin(atoms, 2 * units.fs, 300, 0.01 / units.fs, rng=rng, **kwargs)
    if kind == "bussi":
        return RigidBussi(atoms, 2 * units.fs, 300, 50 * units.fs, rng=rng, **kwargs)
    return RigidNoseHoover(atoms, 2 * units.fs, 300, 50 * units.fs, **kwargs)


def calculator(kind):
    return PeriodicLJ(rc=7.0) if kind in ("mtk", "crescale") else CoulombLJ()


@pytest.mark.parametrize("kind", KINDS)
def test_continuation_is_bit_identical(tmp_path, kind):
    """Run 60 steps; or 25, checkpoint, load into new objects, 35 more: the same bits."""
    reference = build(kind)
    reference.run(60)
    first = build(kind)
    first.run(25)
    first.save_checkpoint(tmp_path / "state.npz")
    resumed = load_checkpoint(tmp_path / "state.npz", calculator(kind))
    assert resumed.nsteps == 25 and resumed.get_time() == first.get_time()
    resumed.run(35)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(resumed.atoms.get_momenta(), reference.atoms.get_momenta())
    np.testing.assert_array_equal(resumed.atoms.cell.array, reference.atoms.cell.array)
    assert resumed.get_conserved_energy() == reference.get_conserved_energy()


@pytest.mark.parametrize("integrator", ["richardson", "rozmanov_kusalik", "pcdm", "exadem"])
def test_continuation_of_every_integrator(tmp_path, integrator):
    reference = build("langevin", integrator)
    reference.run(30)
    first = build("langevin", integrator)
    first.run(10)
    first.save_checkpoint(tmp_path / "state.npz")
    resumed = load_checkpoint(tmp_path / "state.npz", calculator("langevin"))
    resumed.run(20)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)


def test_checkpoint_holds_what_continuation_needs(tmp_path):
    dyn = build("crescale")
    dyn.run(5)
    dyn.save_checkpoint(tmp_path / "state.npz", extra={"note": "hello"})
    checkpoint = read_checkpoint(tmp_path / "state.npz")
    assert checkpoint.nsteps == 5 and checkpoint.extra == {"note": "hello"}
    parts = checkpoint.meta["couplings"]
    assert [p["parameters"]["kind"] for p in parts] == ["bussi", "crescale"]
    # The thermostat and the barostat of RigidCRescale draw from one generator.
    assert parts[1]["rng_owner"] == 0
    np.testing.assert_array_equal(checkpoint.arrays["model_body_coordinates"],
                                  dyn.model.body_coordinates)
    atoms = checkpoint.atoms()
    np.testing.assert_array_equal(atoms.get_tags(), dyn.atoms.get_tags())
    # No stray temporary file is left behind.
    assert [p.name for p in tmp_path.iterdir()] == ["state.npz"]


def test_unreadable_checkpoints_are_clear_errors(tmp_path):
    with pytest.raises(CheckpointError, match="no such file"):
        read_checkpoint(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        read_checkpoint(tmp_path / "junk.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(CheckpointError, match="holds no rigidmd metadata"):
        read_checkpoint(tmp_path / "other.npz")


def test_a_failed_write_keeps_the_previous_checkpoint(tmp_path, monkeypatch):
    dyn = build("nve")
    dyn.run(3)
    dyn.save_checkpoint(tmp_path / "state.npz")
    before = (tmp_path / "state.npz").read_bytes()

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    dyn.run(3)
    with pytest.raises(OSError, match="No space left"):
        dyn.save_checkpoint(tmp_path / "state.npz")
    assert (tmp_path / "state.npz").read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["state.npz"]


def test_legacy_random_state_is_checkpointed(tmp_path):
    """ASE's default rng, numpy.random's RandomState, continues exactly too."""
    runs = []
    for split in (None, 10):
        atoms = mixture()
        dyn = RigidLangevin(atoms, 2 * units.fs, 300, 0.01 / units.fs, bodies="mol-id",
                            rng=np.random.RandomState(3))
        if split is None:
            dyn.run(20)
        else:
            dyn.run(split)
            dyn.save_checkpoint(tmp_path / "state.npz")
            dyn = load_checkpoint(tmp_path / "state.npz", CoulombLJ())
            dyn.run(20 - split)
        runs.append(dyn.atoms.positions.copy())
    np.testing.assert_array_equal(runs[0], runs[1])
