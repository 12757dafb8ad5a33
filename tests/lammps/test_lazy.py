"""The lazy name table of :mod:`rigidmd.lammps` (:mod:`rigidmd.lammps.lazy`, PEP 562)."""

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

import rigidmd.lammps
from rigidmd.lammps import lazy

SOURCE = Path(__file__).resolve().parents[2] / "src"


def test_importing_lammps_imports_neither_the_engine_nor_the_reference_runs():
    """``rigidmd.lammps``'s names are imported on first access (PEP 562): importing the
    package (the configuration does, to check a section) starts none of the engine's,
    i-PI's, the reference runs' or the calculator's modules; every name still resolves and
    ``dir()`` lists each."""
    script = (
        "import sys, rigidmd.lammps as lammps\n"
        "print(sorted(m for m in sys.modules if m.startswith('rigidmd.lammps.')"
        " or m.startswith('rigidmd.ipi')))\n"
        "print(sorted(set(lammps.__all__) - set(dir(lammps))))\n"
        "print(lammps.LAMMPSEngine.__module__, 'rigidmd.lammps.engine' in sys.modules)\n"
        "print(all(getattr(lammps, name) is not None for name in lammps.__all__))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": str(SOURCE)}
                         ).stdout.splitlines()
    assert out == ["['rigidmd.lammps.lazy']", "[]", "rigidmd.lammps.engine True", "True"], out


def test_the_table_names_each_public_name_once():
    """``__all__`` is the table's names, each defined by exactly one module."""
    defined = [name for names in lazy.MODULES.values() for name in names]
    assert len(defined) == len(set(defined))
    assert sorted(defined) == sorted(rigidmd.lammps.__all__)


@pytest.mark.parametrize("name", rigidmd.lammps.__all__)
def test_every_name_is_the_object_of_its_defining_module(name):
    module = next(module for module, names in lazy.MODULES.items() if name in names)
    expected = getattr(importlib.import_module(module), name)
    assert getattr(rigidmd.lammps, name) is expected
    assert lazy.attribute(name) is expected
    # Once read, the name is kept on the package: the next access is a plain lookup.
    assert vars(rigidmd.lammps)[name] is expected


def test_dir_lists_every_public_name_and_the_package_s_attributes():
    listed = dir(rigidmd.lammps)
    assert listed == lazy.names() == sorted(listed)
    assert set(rigidmd.lammps.__all__) <= set(listed)
    assert {"__all__", "__getattr__", "__dir__", "lazy"} <= set(listed)


def test_an_unknown_name_is_the_standard_attribute_error():
    with pytest.raises(AttributeError) as err:
        rigidmd.lammps.LAMMPSCalculatr  # noqa: B018 - the access is the test
    assert str(err.value) == "module 'rigidmd.lammps' has no attribute 'LAMMPSCalculatr'"
    with pytest.raises(AttributeError, match="^module 'rigidmd.lammps' has no attribute 'x'$"):
        lazy.attribute("x")
    assert not hasattr(rigidmd.lammps, "MODULES")  # the table's own names are not the package's
    # ``from rigidmd.lammps import ...`` of an unknown name: Python's ImportError from it.
    with pytest.raises(ImportError, match="cannot import name 'nothing'"):
        exec("from rigidmd.lammps import nothing", {})
