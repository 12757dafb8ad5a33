r"""MDAnalysis interoperability and rigid-water analyses.

This module makes a rigid-body run one call away from `MDAnalysis
<https://www.mdanalysis.org>`_:

* :func:`to_universe` builds an :class:`MDAnalysis.core.universe.Universe`
  from a list of :class:`ase.Atoms`, an ASE trajectory file (``.traj``) or a
  :class:`~rigidmd.RigidVerlet` (or thermostat) object.  Rigid bodies become
  residues; atoms carry names, types, elements, masses and charges; bonds
  inside bodies are present; cell dimensions and times (ps) are set.
* :class:`MDAWriter` is an observer for ``dyn.attach(writer, interval=...)``
  that streams frames to an XTC or DCD trajectory (topology written once, as
  PSF by default), molecules kept whole.
* :class:`RadialDistribution`, :class:`MeanSquaredDisplacement` and
  :class:`RotationalCorrelation` are thin layers over MDAnalysis's analysis
  framework (``run()`` returns the analysis, results live in ``.results``,
  ``plot(path)`` saves a PNG): the O–O radial distribution function, the
  mean-squared displacement with a diffusion coefficient, and the
  rotational correlation :math:`C_\ell(t) = \langle P_\ell(\mathbf u(0)\cdot
  \mathbf u(t))\rangle` (:math:`\ell = 1, 2`) of a molecular axis with its
  relaxation times.

For water's properties: :class:`HeatOfVaporization` (with the polarisation
correction of the models fitted with one), :class:`DielectricConstant`
(MDAnalysis's, with a jackknife error), :class:`ShearViscosity` (Green–Kubo
from the molecular stress that :class:`StressRecorder` records during a run)
and :func:`yeh_hummer_correction` (also
``MeanSquaredDisplacement.finite_size_corrected``).

The package is split by concern: :mod:`~rigidmd.mdanalysis.topology`
(:func:`to_universe`, :func:`write_psf`), :mod:`~rigidmd.mdanalysis.writer`
(:class:`MDAWriter`), :mod:`~rigidmd.mdanalysis.rdf`,
:mod:`~rigidmd.mdanalysis.diffusion` and :mod:`~rigidmd.mdanalysis.rotation`;
every public name is importable from ``rigidmd.mdanalysis``.

MDAnalysis is an optional dependency (``pip install "rigidmd[analysis]"``).
This module imports without it; every function and class raises an
:class:`ImportError` saying how to install it when it is used.

Conventions.  Residue names: water (one O and two H) is ``"SOL"`` (GROMACS's
name; change it with ``water_resname``), CO₂ is ``"CO2"``, a single atom is
its element in capitals (``"NA"``, ``"CL"``), any other body is its chemical
formula (Hill order).  Water atoms are named ``OW``, ``HW1``, ``HW2``; other
atoms by element, numbered within the residue when the element repeats
(``C``, ``O1``, ``O2``).  Types are the element symbols.  Lengths are Å, times
ps (MDAnalysis's units), diffusion coefficients Å²/ps (also given in cm²/s;
1 Å²/ps = 1e-4 cm²/s).  In ASE time units one picosecond is
``1000 * ase.units.fs`` (:data:`PS`).
"""

from rigidmd.mdanalysis._base import ANGSTROM2_PER_PS_IN_CM2_PER_S, PS
from rigidmd.mdanalysis.dielectric import DielectricConstant, dielectric_from_dipoles
from rigidmd.mdanalysis.diffusion import (
    YEH_HUMMER_XI,
    MeanSquaredDisplacement,
    mean_squared_displacement,
    yeh_hummer_correction,
)
from rigidmd.mdanalysis.rdf import RadialDistribution
from rigidmd.mdanalysis.rotation import (
    RotationalCorrelation,
    body_dipole_directions,
    orientational_correlation,
    relaxation_time,
)
from rigidmd.mdanalysis.thermo import (
    HeatOfVaporization,
    block_average,
    excluded_kspace_energy,
    polarization_energy,
)
from rigidmd.mdanalysis.topology import to_universe, write_psf
from rigidmd.mdanalysis.viscosity import ShearViscosity, StressRecorder, shear_components
from rigidmd.mdanalysis.writer import MDAWriter

__all__ = [
    "PS",
    "ANGSTROM2_PER_PS_IN_CM2_PER_S",
    "to_universe",
    "write_psf",
    "MDAWriter",
    "RadialDistribution",
    "MeanSquaredDisplacement",
    "RotationalCorrelation",
    "mean_squared_displacement",
    "orientational_correlation",
    "relaxation_time",
    "body_dipole_directions",
    "DielectricConstant",
    "dielectric_from_dipoles",
    "YEH_HUMMER_XI",
    "yeh_hummer_correction",
    "HeatOfVaporization",
    "block_average",
    "excluded_kspace_energy",
    "polarization_energy",
    "ShearViscosity",
    "StressRecorder",
    "shear_components",
]
