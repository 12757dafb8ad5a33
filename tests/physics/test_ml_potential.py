"""Rigid water under a machine-learned potential (MACE), when mace-torch is installed.

mace-torch and PyTorch are the ``ml`` extra, not the ``test`` extra (PyTorch's
wheels are gigabytes and CI has no GPU): without them this module is skipped
with the reason.  The example builds its model in code (nothing downloaded).
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mace", reason='needs mace-torch (pip install "rigidmd[ml]")')

ROOT = Path(__file__).resolve().parents[2]


def test_mace_example_runs_rigid_water(tmp_path):
    """8 rigid waters, 50 NO_SQUISH steps of 2 fs with a small random-weight MACE.

    Measured on the CPU: the conserved energy spans 5.0e-4 eV (drift +3.4e-4 eV/ps),
    37 ms per step on one thread.  Bound 5e-3 eV.
    """
    out = tmp_path / "mace.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "mace_water.py"), "--quick", "--json",
         str(out)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    res = json.loads(out.read_text())
    assert res["molecules"] == 8 and res["steps"] == 50
    assert res["degrees_of_freedom"] == 48
    assert res["energy_spread_eV"] < 5e-3, res
