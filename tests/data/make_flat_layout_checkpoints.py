"""Make ``checkpoint_flat_*.npz``: checkpoints written by rigidmd before its package layout.

Written by the code at commit 994d68e (every module flat in ``src/rigidmd``),
before the modules moved into ``rigidmd.core``, ``rigidmd.couplings`` and
``rigidmd.run``; ``tests/core/test_checkpoint_layout.py`` loads them with today's code
and checks the continuation against the positions the old code reached
(``checkpoint_flat_reference.npz``).  Two dynamics: a Bussi thermostat on the
CO2/water/neon droplet (``mixture()``, a random-number generator in the file) and
C-rescale NPT on the dimer liquid (``dimer_fluid()``, a barostat and a cell).
Only the public API is used, so the script runs with the old code and the new.

Run (with the old code on the path):
    git archive 994d68e src tests | tar -x -C /tmp/old
    cp tests/data/make_flat_layout_checkpoints.py /tmp/old/tests/data/
    PYTHONPATH=/tmp/old/src python /tmp/old/tests/data/make_flat_layout_checkpoints.py OUTDIR
"""

import sys
from pathlib import Path

import numpy as np
from ase import units

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from helpers import CoulombLJ, PeriodicLJ, dimer_fluid, mixture  # noqa: E402

from rigidmd import RigidBussi, RigidCRescale, load_checkpoint  # noqa: E402

#: Steps before the checkpoint and after it.
BEFORE, AFTER = 20, 10


def build(kind):
    rng = np.random.default_rng(5)
    if kind == "crescale":
        return RigidCRescale(dimer_fluid(n_side=4, rc=7.0), 2 * units.fs, 80, units.bar,
                             50 * units.fs, 500 * units.fs, 1e-4 / units.bar, bodies="tags",
                             rng=rng)
    return RigidBussi(mixture(), 2 * units.fs, 300, 50 * units.fs, rng=rng, bodies="mol-id")


def calculator(kind):
    return PeriodicLJ(rc=7.0) if kind == "crescale" else CoulombLJ()


def main(outdir):
    outdir = Path(outdir)
    reference = {}
    for kind in ("bussi", "crescale"):
        dyn = build(kind)
        dyn.run(BEFORE)
        path = outdir / f"checkpoint_flat_{kind}.npz"
        dyn.save_checkpoint(path)
        resumed = load_checkpoint(path, calculator(kind))
        resumed.run(AFTER)
        reference[f"{kind}_positions"] = resumed.atoms.positions
        reference[f"{kind}_momenta"] = resumed.atoms.get_momenta()
        reference[f"{kind}_cell"] = resumed.atoms.cell.array
        reference[f"{kind}_conserved"] = np.array(resumed.get_conserved_energy())
    np.savez(outdir / "checkpoint_flat_reference.npz", **reference)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent)
