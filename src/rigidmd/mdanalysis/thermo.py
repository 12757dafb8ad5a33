r"""Heat of vaporisation of rigid water, block averages, and what a LAMMPS energy holds.

Rigid molecules have no intramolecular energy, so the liquid's potential
energy is all intermolecular, and with an ideal gas of the same rigid
molecules (whose kinetic energy is the liquid's at the same temperature)

.. math::
    \Delta H_\mathrm{vap} = -\frac{\langle U \rangle}{N} + RT .

Models fitted with a polarisation correction (SPC/E [1]_, TIP4P/2005 [2]_)
compare :math:`\Delta H_\mathrm{vap} - E_\mathrm{pol}` with experiment, where
:math:`E_\mathrm{pol} = (\mu - \mu_\mathrm{gas})^2 / (2\alpha)` is the cost of
polarising a gas-phase molecule (:math:`\mu_\mathrm{gas}` = 1.85 D,
:math:`\alpha` = 1.44 Å³ [1]_) to the model's dipole :math:`\mu`.
:class:`HeatOfVaporization` gives both numbers.

With ``neigh_modify exclude molecule/intra`` (how
:class:`~rigidmd.lammps.LAMMPSCalculator` keeps a molecule's sites from
interacting) LAMMPS's k-space energy still holds the reciprocal-space part of
every excluded pair, :math:`\sum_{i<j} q_i q_j \operatorname{erf}(g r_{ij}) /
(4\pi\varepsilon_0 r_{ij})` per molecule: a constant of rigid molecules (no
force on a body) but of order −2 eV per water, which
:func:`excluded_kspace_energy` gives so that it can be taken off.

References
----------
.. [1] H. J. C. Berendsen, J. R. Grigera and T. P. Straatsma, J. Phys. Chem.
   91, 6269 (1987).
.. [2] J. L. F. Abascal and C. Vega, J. Chem. Phys. 123, 234505 (2005).
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
from ase import units
from scipy.special import erf

__all__ = ["block_average", "HeatOfVaporization", "excluded_kspace_energy",
           "ewald_parameter", "dipole_moment_debye", "polarization_energy",
           "POLARIZATION_CORRECTED", "KJ_PER_MOL", "COULOMB"]

#: One kJ/mol per molecule in eV.
KJ_PER_MOL = units.kJ / units.mol
#: Coulomb's constant 1/(4π ε0) in eV Å / e².
COULOMB = units.Hartree * units.Bohr
#: One debye in e Å.
DEBYE = units.Debye
#: Gas-phase dipole of water (D) and its polarisability (Å³) used by Berendsen et al. (1987).
GAS_DIPOLE_DEBYE = 1.85
POLARIZABILITY_A3 = 1.44
#: Models whose paper compares ΔH_vap - E_pol with experiment (key: water-model name).
POLARIZATION_CORRECTED = {
    "spce": "Berendsen, Grigera & Straatsma, J. Phys. Chem. 91, 6269 (1987)",
    "tip4p2005": "Abascal & Vega, J. Chem. Phys. 123, 234505 (2005)",
    # Horn et al. and Izadi et al. also add a term C (vibrations, non-ideal gas; -0.070
    # kcal/mol at 298 K in Horn's table) that is not applied here, and take the gas dipole
    # and polarisability from experiment (1.855 D, 1.495 Å³, which reproduce the 1.04
    # kcal/mol Wang et al. 2009 quote for TIP4P-Ew) rather than Berendsen's 1.85 D and
    # 1.44 Å³: together -0.03 kJ/mol for TIP4P-Ew, +0.14 for OPC (docs/validation/water.md).
    "tip4pew": "Horn et al., J. Chem. Phys. 120, 9665 (2004)",
    "opc": "Izadi, Anandakrishnan & Onufriev, J. Phys. Chem. Lett. 5, 3863 (2014), SI eq. 15",
}


class Results(SimpleNamespace):
    """Results of a series analysis (attributes, like MDAnalysis's ``Results``)."""


def block_average(values, blocks=10):
    """Mean of a time series and its standard error from consecutive block means.

    Parameters
    ----------
    values : array_like, shape (n,) or (n, ...)
        The series along axis 0.
    blocks : int, default 10
        Number of blocks; each should be longer than the correlation time.

    Returns
    -------
    (mean, stderr)
        ``mean`` is the series' own mean (blocks of unequal length, when ``n`` is not
        a multiple of ``B``, would weight their values unequally); ``stderr`` is the
        standard deviation of the block means over :math:`\\sqrt{B}`.
    """
    values = np.asarray(values, dtype=float)
    if blocks < 2 or len(values) < blocks:
        raise ValueError(f"block_average: {len(values)} values cannot make {blocks} blocks "
                         "(need at least 2 blocks of one value)")
    means = np.array([b.mean(axis=0) for b in np.array_split(values, blocks)])
    return values.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(blocks)


def dipole_moment_debye(model):
    """Dipole moment of one molecule of a :class:`~rigidmd.water.WaterModel` (D)."""
    mu = model.charges(1) @ model.molecule().positions
    return float(np.linalg.norm(mu) / DEBYE)


def polarization_energy(model):
    r"""Self-polarisation energy :math:`(\mu - \mu_\mathrm{gas})^2 / (2\alpha)` (eV per molecule).

    With the polarisability volume :math:`\alpha_V` = 1.44 Å³
    (:math:`\alpha = 4\pi\varepsilon_0\alpha_V`) this is
    :math:`k_e (\Delta\mu)^2 / (2 \alpha_V)`.  SPC/E (2.351 D) gives
    5.24 kJ/mol; Berendsen et al. quote 5.22 kJ/mol.
    """
    dmu = (dipole_moment_debye(model) - GAS_DIPOLE_DEBYE) * DEBYE
    return float(COULOMB * dmu**2 / (2 * POLARIZABILITY_A3))


def ewald_parameter(calc):
    """The Ewald splitting parameter g (1/Å) a LAMMPS calculator pinned (after its first call).

    Parameters
    ----------
    calc : rigidmd.lammps.LAMMPSCalculator
        One that has run with a ``kspace_style`` (its ``kspace_parameters``
        is ``kspace_modify gewald G ...``).
    """
    text = getattr(calc, "kspace_parameters", None)
    found = re.match(r"kspace_modify gewald\s+(\S+)", text or "")
    if found is None:
        raise ValueError("ewald_parameter: the calculator has no pinned k-space parameters "
                         f"(kspace_parameters is {text!r}); compute an energy with it first")
    return float(found.group(1))


def excluded_kspace_energy(model, g_ewald, n_molecules=1):
    r"""Reciprocal-space energy of the excluded intramolecular pairs (eV).

    .. math::
        E = N \sum_{i<j \in \mathrm{molecule}} k_e\, q_i q_j\,
            \frac{\operatorname{erf}(g\, r_{ij})}{r_{ij}}

    What LAMMPS's k-space energy holds beyond the intermolecular energy when
    intramolecular pairs are excluded from the pair list: subtract it from
    the calculator's energy for the intermolecular energy.

    Parameters
    ----------
    model : rigidmd.water.WaterModel
    g_ewald : float
        Ewald parameter (1/Å), e.g. :func:`ewald_parameter`.
    n_molecules : int
    """
    x = model.molecule().positions
    q = model.charges(1)
    i, j = np.triu_indices(len(q), k=1)
    keep = (q[i] != 0) & (q[j] != 0)
    i, j = i[keep], j[keep]
    r = np.linalg.norm(x[i] - x[j], axis=1)
    return float(n_molecules * COULOMB * np.sum(q[i] * q[j] * erf(g_ewald * r) / r))


class HeatOfVaporization:
    r"""Heat of vaporisation of a rigid-molecule liquid from its potential energies.

    :math:`\Delta H = -\langle U - U_0\rangle/N + k_B T` per molecule, with
    its standard error from block averages; for a model in
    :data:`POLARIZATION_CORRECTED` also :math:`\Delta H - E_\mathrm{pol}`
    (:func:`polarization_energy`), the number its paper compares with
    experiment.

    Parameters
    ----------
    potential_energies : array_like, shape (n_frames,)
        The liquid's potential energy (eV) along an equilibrium run (NPT at
        the pressure of interest).
    n_molecules : int
        A whole number (216.0 is taken as 216; 215.6 is refused).
    temperature_K : float
    model : rigidmd.water.WaterModel or str, optional
        For the polarisation correction; a name (``"spce"``) is looked up
        with :func:`rigidmd.water.water_model`.
    energy_offset : float, default 0
        :math:`U_0`, eV, taken off every energy: what the energies hold
        beyond the intermolecular energy (:func:`excluded_kspace_energy` for
        LAMMPS with excluded intramolecular pairs and k-space).
    blocks : int, default 10

    Attributes
    ----------
    results.potential_energy_kj_mol, results.potential_energy_stderr_kj_mol : float
        :math:`\langle U - U_0\rangle / N`.
    results.delta_h_kj_mol, results.delta_h_stderr_kj_mol : float
    results.polarization_energy_kj_mol : float or None
        None for a model whose paper applies no correction.
    results.delta_h_corrected_kj_mol : float or None
    results.correction_reference : str or None
    """

    def __init__(self, potential_energies, n_molecules, temperature_K, model=None,
                 energy_offset=0.0, blocks=10):
        self.energies = np.asarray(potential_energies, dtype=float).ravel()
        if isinstance(n_molecules, bool) or not isinstance(n_molecules, (int, float, np.number)) \
                or not np.isfinite(n_molecules) or n_molecules != int(n_molecules) \
                or n_molecules < 1:
            raise ValueError(f"HeatOfVaporization: n_molecules must be a positive whole number "
                             f"of molecules, got {n_molecules!r}")
        if isinstance(model, str):
            from rigidmd.water import water_model

            try:
                model = water_model(model)
            except ValueError as err:
                raise ValueError(f"HeatOfVaporization: model: {err}") from None
        if not temperature_K > 0:
            raise ValueError(f"HeatOfVaporization: temperature_K must be positive, "
                             f"got {temperature_K}")
        if not np.all(np.isfinite(self.energies)):
            raise ValueError("HeatOfVaporization: potential_energies holds a non-finite value")
        self.n_molecules = int(n_molecules)
        self.temperature_K = float(temperature_K)
        self.model = model
        self.energy_offset = float(energy_offset)
        self.blocks = int(blocks)
        self.results = Results()

    def run(self):
        """Compute; returns ``self``."""
        res = self.results
        per = (self.energies - self.energy_offset) / self.n_molecules / KJ_PER_MOL
        mean, err = block_average(per, self.blocks)
        rt = units.kB * self.temperature_K / KJ_PER_MOL
        res.potential_energy_kj_mol = float(mean)
        res.potential_energy_stderr_kj_mol = float(err)
        res.delta_h_kj_mol = float(-mean + rt)
        res.delta_h_stderr_kj_mol = float(err)
        name = getattr(self.model, "name", None)
        if name in POLARIZATION_CORRECTED:
            res.polarization_energy_kj_mol = polarization_energy(self.model) / KJ_PER_MOL
            res.delta_h_corrected_kj_mol = res.delta_h_kj_mol - res.polarization_energy_kj_mol
            res.correction_reference = POLARIZATION_CORRECTED[name]
        else:
            res.polarization_energy_kj_mol = None
            res.delta_h_corrected_kj_mol = None
            res.correction_reference = None
        return self
