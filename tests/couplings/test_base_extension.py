"""The extension API as the how-to uses it: a thermostat written outside rigidmd.

The part is the ``berendsen.py`` the page ``docs/howto/write-a-thermostat.md`` writes
(read from the page, so the tested code is the documented code).  Its import registers
the kind ``berendsen``; the fixture removes it again, so that other tests see rigidmd's
registry only.
"""

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest
from ase import units
from ase.calculators.tip3p import TIP3P
from codeblocks import blocks

from rigidmd import RigidDynamics, load_checkpoint, rigid_maxwell_boltzmann
from rigidmd.config import ConfigError, check_config, load_config
from rigidmd.couplings import COUPLINGS, Coupling, Thermostat, register
from rigidmd.run.cli import main
from rigidmd.systems import water_cluster

PAGE = Path(__file__).resolve().parents[2] / "docs" / "howto" / "write-a-thermostat.md"


def page_file(name):
    """The text of the page's block that starts with ``# file: NAME``."""
    found = [body for _, body in blocks(PAGE.read_text()) if body.startswith(f"# file: {name}")]
    assert len(found) == 1, name
    return found[0]


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A folder with the page's ``berendsen.py`` and ``berendsen.yaml``; unregistered after."""
    for name in ("berendsen.py", "berendsen.yaml"):
        (tmp_path / name).write_text(page_file(name))
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    COUPLINGS.pop("berendsen", None)
    sys.modules.pop("berendsen", None)


@pytest.fixture
def berendsen(folder, monkeypatch):
    """The page's ``BerendsenThermostat`` class, imported (and so registered)."""
    monkeypatch.syspath_prepend(str(folder))
    return importlib.import_module("berendsen").BerendsenThermostat


def cluster(n=8, seed=0):
    atoms = water_cluster(n)
    atoms.calc = TIP3P(rc=40.0)
    rigid_maxwell_boltzmann(atoms, 200, rng=np.random.default_rng(seed))
    return atoms


def test_the_page_part_is_registered_with_its_fields(berendsen):
    assert COUPLINGS["berendsen"] is berendsen
    assert issubclass(berendsen, Thermostat)
    assert [p.field for p in berendsen.parameters] == ["temperature", "taut", "fixcm"]


def test_the_part_checks_the_system_and_the_timestep(berendsen):
    still = water_cluster(4)
    still.calc = TIP3P(rc=40.0)
    with pytest.raises(ValueError, match="zero stays zero"):
        RigidDynamics(still, units.fs, couplings=[berendsen(300, 50 * units.fs)])
    with pytest.raises(ValueError, match="shorter than the time step"):
        RigidDynamics(cluster(4), 100 * units.fs, couplings=[berendsen(300, 50 * units.fs)])


def test_the_work_it_books_keeps_the_conserved_energy(berendsen):
    """Econs = total + energy() stays put while the thermostat takes energy out."""
    atoms = cluster()
    rigid_maxwell_boltzmann(atoms, 600, rng=np.random.default_rng(0))  # hot: it cools
    thermostat = berendsen(300, 20 * units.fs)
    dyn = RigidDynamics(atoms, units.fs, couplings=[thermostat])
    start = dyn.get_conserved_energy()
    dyn.run(300)
    # Measured (8 waters from 600 K, three starts): the thermostat takes out 0.41-0.82 eV in
    # 300 steps and Econs changes by 3-6e-4 eV (the integrator's own error at 1 fs); a
    # thermostat that booked no work, or the wrong sign, would be off by the whole amount.
    assert thermostat.work < -0.3
    assert abs(dyn.get_conserved_energy() - start) < 0.01 * abs(thermostat.work)


def test_it_continues_from_a_checkpoint_bit_for_bit(berendsen, folder):
    """On the NumPy backend, as the page says: 60 steps, or 25, a checkpoint and 35 more."""
    reference = RigidDynamics(cluster(), units.fs, couplings=[berendsen(300, 50 * units.fs)],
                              backend="numpy")
    reference.run(60)
    first = RigidDynamics(cluster(), units.fs, couplings=[berendsen(300, 50 * units.fs)],
                          backend="numpy")
    first.run(25)
    first.save_checkpoint(folder / "state.npz")
    resumed = load_checkpoint(folder / "state.npz", TIP3P(rc=40.0))
    assert type(resumed.thermostat).__name__ == "BerendsenThermostat"
    assert resumed.thermostat.work == first.couplings[0].work
    resumed.run(35)
    np.testing.assert_array_equal(resumed.atoms.positions, reference.atoms.positions)
    np.testing.assert_array_equal(resumed.atoms.get_momenta(), reference.atoms.get_momenta())
    assert resumed.get_conserved_energy() == reference.get_conserved_energy()


def test_a_configuration_names_it_only_with_trust(folder):
    raw = load_config(folder / "berendsen.yaml")  # the page's
    with pytest.raises(ConfigError, match=r"^thermostat\.kind: 'berendsen\.BerendsenThermostat'"
                       r" is a coupling part of your own; .* --trust"):
        check_config(raw)
    assert "berendsen" not in sys.modules  # refused before the import
    config = check_config(raw, trust=True)  # found in the configuration's folder
    assert config.coupling.thermostat.kind == "berendsen"
    part = config.coupling.thermostat.part()
    assert type(part).__name__ == "BerendsenThermostat" and part.taut == 50 * units.fs
    missing = dict(raw, thermostat={"kind": "berendsen.BerendsenThermostat",
                                    "temperature": "300 K"})
    with pytest.raises(ConfigError, match=r"thermostat\.taut: missing for berendsen"):
        check_config(missing, trust=True)


@pytest.mark.parametrize(("section", "kind", "message"), [
    ("barostat", "berendsen.BerendsenThermostat", "is a thermostat, not a barostat"),
    ("thermostat", "collections.OrderedDict", "is not a coupling part"),
    ("thermostat", "berendsen.NoSuchClass", "cannot import"),
    ("thermostat", "no_such_module_here.Part", "cannot import"),
    ("thermostat", "berendsen.Unregistered", "is not registered"),
])
def test_a_dotted_kind_that_is_not_a_registered_part_is_refused(folder, section, kind, message):
    with (folder / "berendsen.py").open("a") as fh:
        fh.write("\n\nclass Unregistered(Thermostat):\n    kind = 'unregistered'\n")
    raw = load_config(folder / "berendsen.yaml")
    del raw["thermostat"]
    raw[section] = {"kind": kind, "temperature": "300 K", "taut": "50 fs"}
    with pytest.raises(ConfigError, match=f"^{section}\\.kind: .*{message}"):
        check_config(raw, trust=True)


def test_a_kind_that_is_a_number_is_not_taken_for_a_dotted_path(folder):
    raw = load_config(folder / "berendsen.yaml")
    raw["thermostat"] = dict(raw["thermostat"], kind=3.5)
    with pytest.raises(ConfigError, match=r"^thermostat\.kind: use langevin, .*got 3\.5$"):
        check_config(raw, trust=True)


def test_export_lammps_refuses_it_with_the_reason(folder, capsys):
    assert main(["export-lammps", "--trust", "berendsen.yaml", "deck"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("rigidmd: error: thermostat.kind: LAMMPS has no Berendsen "
                            "thermostat for rigid bodies"), error
    assert not (folder / "deck").exists()


def test_a_registered_kind_cannot_be_registered_twice():
    class Twice(Coupling):
        kind = "langevin"

    with pytest.raises(ValueError, match="registered twice"):
        register(Twice)
