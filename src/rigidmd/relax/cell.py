r"""The cell part of a rigid relaxation: molecular scaling, the cell gradient.

A relaxation of the cell deforms it by a deformation gradient :math:`D`
(cell vectors as rows, :math:`h = h_0 D^\mathsf{T}`) and moves the centres
of mass of the bodies and the point particles with it,
:math:`X = s D^\mathsf{T}` with :math:`s` fixed; orientations do not change,
so the molecules stay rigid (molecular scaling).  The optimizer sees
:math:`u = c\,(D - 1)` as three extra rows of coordinates (``c`` the cell
factor, as in ASE's :class:`~ase.filters.UnitCellFilter`), with

================  ==========================================================
mode              deformation
================  ==========================================================
``"iso"``         :math:`D = (1 + \mathrm{tr}\,u / 3c)\,\mathbb{1}`
``"aniso"``       :math:`D = \mathbb{1} + \mathrm{diag}(u) / c`
``"full"``        :math:`D = \mathbb{1} + \tfrac12 (u + u^\mathsf{T}) / c`
================  ==========================================================

(symmetric :math:`D`: the cell does not rotate).  The energy minimised is
the enthalpy :math:`E + pV` at the target pressure :math:`p` (eV/Å³, ASE's
``scalar_pressure``).  With the molecular virial
:math:`W = \sum_b X_b \otimes F_b + \sum_\mathrm{free} x \otimes f`,

.. math:: \frac{\partial (E + pV)}{\partial D}
          = \left(-W^\mathsf{T} + pV\,\mathbb{1}\right) D^{-\mathsf{T}},

projected onto the mode's coordinates.  :math:`W` is the calculator's atomic
virial :math:`-V\sigma` less the intramolecular part
:math:`\sum_b\sum_{i\in b} r_i \otimes f_i`, whose symmetric part is
:func:`rigidmd.core.operators.intramolecular_virial` and whose antisymmetric part
is half the bodies' total torque (:math:`R_{ij} - R_{ji} = \epsilon_{ijk}\tau_k`): the one
molecular virial of the package, :func:`rigidmd.core.observables.molecular_virial`
(the barostats' one) less :func:`rigidmd.core.observables.torque_virial`.
"""

import numpy as np

__all__ = ["CELL_MODES", "deformation", "cell_gradient", "cell_mode"]

#: The cell relaxations: isotropic, the three cell lengths, the full (symmetric) strain.
CELL_MODES = ("iso", "aniso", "full")


def cell_mode(cell):
    """The mode a ``cell`` argument names: None (fixed cell) or one of :data:`CELL_MODES`.

    ``False``/``None`` keep the cell, ``True`` is ``"full"``.

    Raises
    ------
    ValueError
        Any other value (one line naming it).
    """
    if cell is None or cell is False:
        return None
    if cell is True:
        return "full"
    if isinstance(cell, str) and cell in CELL_MODES:
        return cell
    raise ValueError(f"cell={cell!r}: expected False, True or one of {', '.join(CELL_MODES)}")


def deformation(u, mode, cell_factor):
    r"""Deformation gradient :math:`D` of the cell coordinates ``u``.

    Parameters
    ----------
    u : numpy.ndarray, shape (3, 3)
        The optimizer's cell rows, :math:`c\,(D - 1)` (dimensionless times ``c``).
    mode : str
        One of :data:`CELL_MODES`.
    cell_factor : float
        :math:`c`.

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        Symmetric.
    """
    if mode == "iso":
        return (1.0 + np.trace(u) / (3.0 * cell_factor)) * np.eye(3)
    if mode == "aniso":
        return np.eye(3) + np.diag(np.diag(u)) / cell_factor
    return np.eye(3) + 0.5 * (u + u.T) / cell_factor


def cell_gradient(virial, volume, D, scalar_pressure, mode, cell_factor):
    r"""Gradient of :math:`E + pV` with respect to the cell rows ``u`` (eV).

    Parameters
    ----------
    virial : numpy.ndarray, shape (3, 3)
        The full :math:`W` (eV): :func:`rigidmd.core.observables.molecular_virial` less
        :func:`rigidmd.core.observables.torque_virial`.
    volume : float
        Current volume (Å³).
    D : numpy.ndarray, shape (3, 3)
        Current deformation gradient.
    scalar_pressure : float
        :math:`p` (eV/Å³).
    mode : str
    cell_factor : float

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        :math:`\partial (E + pV)/\partial u`; zero in the components the mode
        does not use.
    """
    g = (-virial.T + scalar_pressure * volume * np.eye(3)) @ np.linalg.inv(D).T
    if mode == "iso":
        return np.eye(3) * np.trace(g) / (3.0 * cell_factor)
    if mode == "aniso":
        return np.diag(np.diag(g)) / cell_factor
    return 0.5 * (g + g.T) / cell_factor
