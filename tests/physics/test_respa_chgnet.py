"""CHGNet on the slow level of r-RESPA (``validation/respa_chgnet.py``).

The fitted fast level, :class:`FourSite`, is checked here without CHGNet: its forces are the
energy's gradient, and with TIP4P's parameters its energy, net forces and torques are ASE's
``TIP4P`` calculator's.  The script's quick form runs where CHGNet is installed (its own
environment, not the test extra) and is skipped otherwise.
"""

import importlib.util

import numpy as np
import pytest
from ase.calculators import tip4p
from helpers import benchmark_module

from rigidmd.systems import water_cluster

respa_chgnet = benchmark_module("respa_chgnet")


@pytest.mark.parametrize("oh_terms", [(0.0, 0.0), (300.0, 4.0)])
def test_four_site_forces_are_the_gradient_of_its_energy(oh_terms):
    atoms = water_cluster(8, seed=3)
    calc = respa_chgnet.FourSite(0.5564, 3.1589, 0.008, 0.128, 0.0, *oh_terms)
    atoms.calc = calc
    forces = atoms.get_forces()
    h, worst = 1e-5, 0.0
    for i in range(0, len(atoms), 5):
        for k in range(3):
            moved = atoms.copy()
            moved.calc = calc
            moved.positions[i, k] += h
            up = moved.get_potential_energy()
            moved.positions[i, k] -= 2 * h
            down = moved.get_potential_energy()
            worst = max(worst, abs(-(up - down) / (2 * h) - forces[i, k]))
    # Central differences at h = 1e-5 Å: 3e-10 eV/Å measured (forces up to 0.8 eV/Å); a
    # wrong sign or a lost term of the M site's share is 1e-2 or more.
    assert worst < 1e-8


def test_four_site_with_tip4p_parameters_is_ase_s_tip4p():
    """ASE's ``TIP4P`` puts M 0.15 Å along the bisector and shares its force otherwise; a
    rigid water feels only the net force and torque, which must then agree, as must the
    energy (ASE's cut-off far beyond the cluster)."""
    atoms = water_cluster(8, seed=3)
    x = atoms.positions[:3]
    a = 0.15 / np.linalg.norm((x[1] - x[0]) + (x[2] - x[0]))
    ours = respa_chgnet.FourSite(tip4p.qH, tip4p.sigma0, tip4p.epsilon0, a)
    theirs = tip4p.TIP4P(rc=40.0)
    e = []
    for calc in (ours, theirs):
        atoms.calc = calc
        e.append(atoms.get_potential_energy())
    f_ours, t_ours = respa_chgnet.generalized(atoms, ours).reshape(2, -1)
    f_theirs, t_theirs = respa_chgnet.generalized(atoms, theirs).reshape(2, -1)
    # The same sums in another order: 1e-15 relative; a misplaced M site (a off by 1 %)
    # moves the energy by 8e-3 eV and the torques by 1e-3 eV (measured).
    assert e[0] == pytest.approx(e[1], rel=1e-10, abs=1e-10)
    np.testing.assert_allclose(f_ours, f_theirs, atol=1e-10)
    np.testing.assert_allclose(t_ours, t_theirs, atol=1e-10)


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("chgnet") is None,
                    reason='needs CHGNet and PyTorch (pip install "rigidmd[chgnet]")')
def test_the_quick_form_runs_and_reports(tmp_path):
    assert respa_chgnet.main(["--quick", "--out", str(tmp_path / "out")]) == 0
    text = (tmp_path / "out.txt").read_text()
    assert "| none (CHGNet alone) | 1 |" in text and "| fitted | 4 |" in text
    assert "CHGNet − fitted (slow level)" in text


def test_the_page_shows_what_the_committed_run_gives():
    """The report made again from the committed JSON is the committed text, and its tables
    and verdicts are on the page (a page or text kept by hand from another run fails)."""
    import json
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    rows = json.loads((root / "validation" / "respa_chgnet.json").read_text())
    text = respa_chgnet.report(rows)
    assert text == (root / "validation" / "respa_chgnet.txt").read_text()
    page = (root / "docs" / "validation" / "respa-chgnet.md").read_text()
    shown = [line for line in text.splitlines() if line.startswith(("| ", "- "))]
    assert len(shown) > 10
    missing = [line for line in shown if line not in page]
    assert not missing, f"lines the page lacks: {missing}"
