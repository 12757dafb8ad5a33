"""The cell's part of a relaxation (rigidmd.relax.cell)."""

import numpy as np
import pytest

from rigidmd.relax.cell import CELL_MODES, cell_gradient, cell_mode, deformation


def test_cell_modes():
    assert CELL_MODES == ("iso", "aniso", "full")
    assert cell_mode(False) is None and cell_mode(None) is None
    assert cell_mode(True) == "full" and cell_mode("aniso") == "aniso"
    with pytest.raises(ValueError, match="cell='xy': expected False, True or one of iso, "
                                         "aniso, full"):
        cell_mode("xy")


def test_deformations_of_each_mode():
    u = np.array([[0.3, 0.1, 0.0], [0.3, -0.6, 0.0], [0.0, 0.0, 0.9]])
    c = 2.0
    assert np.allclose(deformation(u, "iso", c), (1 + 0.6 / 6) * np.eye(3))
    assert np.allclose(deformation(u, "aniso", c), np.diag([1.15, 0.7, 1.45]))
    full = deformation(u, "full", c)
    assert np.allclose(full, full.T) and full[0, 1] == pytest.approx(0.1)


@pytest.mark.parametrize("mode", CELL_MODES)
def test_the_gradient_of_e_plus_pv_by_finite_differences(mode, rng):
    """E(u) = -tr(W ln D)-like quadratic stand-in: for a homogeneous strain energy
    E = V0/2 (D-1):C:(D-1) the analytic gradient matches central differences."""
    volume0, p, c = 100.0, 0.01, 3.0
    stiffness = 0.5

    def energy(u):
        D = deformation(u, mode, c)
        strain = D - np.eye(3)
        return volume0 * stiffness * np.sum(strain * strain) + p * volume0 * np.linalg.det(D)

    u = 0.05 * rng.normal(size=(3, 3))
    D = deformation(u, mode, c)
    strain = D - np.eye(3)
    # Virial of the strain energy: W = -dE_el/dD D^T.
    virial = -(2 * volume0 * stiffness * strain) @ D.T
    gradient = cell_gradient(virial, volume0 * np.linalg.det(D), D, p, mode, c)
    numeric = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[i, j] = 1e-6
            numeric[i, j] = (energy(u + e) - energy(u - e)) / 2e-6
    if mode == "iso":
        numeric = np.eye(3) * np.trace(numeric) / 3.0
    elif mode == "full":
        numeric = 0.5 * (numeric + numeric.T)
    assert np.allclose(gradient, numeric, atol=1e-6), (gradient, numeric)
