"""Checks of what a user hands a rigid dynamics, run before any state changes.

Each raises one ``ValueError`` (or ``TypeError``) naming the atom, the cell
vector or the parameter at fault.
"""

import numpy as np
from ase import Atoms
from ase.constraints import FixCom

from rigidmd.dof import RigidBodyDOF

__all__ = ["check_finite", "check_massless_momenta", "check_timestep", "check_constraints"]


def check_timestep(timestep: float) -> float:
    """``timestep`` as a positive finite float (ASE time units), or a clear error."""
    try:
        dt = float(timestep)
    except (TypeError, ValueError):
        raise TypeError(f"timestep must be a number, got {timestep!r}") from None
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"timestep must be positive and finite, got {timestep!r}")
    return dt


def check_finite(values, quantity: str, unit: str, when: str = "") -> None:
    """Raise a ValueError naming the first atom whose ``quantity`` is NaN or infinite.

    One reduction when everything is finite (a NaN or an infinity anywhere
    makes the sum non-finite).
    """
    values = np.asarray(values, dtype=float)
    if np.isfinite(values.sum()):
        return
    bad = np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))
    what = "cell vector" if quantity == "cell" else "atom"
    raise ValueError(f"{what} {int(bad[0])} has a non-finite {quantity} "
                     f"{values[bad[0]].tolist()} ({unit}){' ' + when if when else ''}"
                     f"{f'; {len(bad)} in all' if len(bad) > 1 else ''}")


def check_massless_momenta(atoms: Atoms, when: str = "") -> None:
    """Refuse a momentum on an atom of mass 0: a virtual site only moves with its body.

    ASE's velocity tools (``MaxwellBoltzmannDistribution``, ``Stationary``,
    ``set_velocities``) give such atoms zero momentum; a non-zero one was set
    by hand and has no rigid-body meaning, so it is refused, not dropped.
    """
    masses = atoms.get_masses()
    if np.all(masses > 0):
        return
    momenta = atoms.get_momenta()
    bad = np.flatnonzero((masses == 0) & np.any(momenta != 0, axis=1))
    if bad.size:
        a = int(bad[0])
        raise ValueError(
            f"atom {a} ({atoms[a].symbol}) has mass 0 but momentum {momenta[a].tolist()} "
            f"(amu Å / ASE time){' ' + when if when else ''}: a massless atom (a virtual site) "
            "moves with its body; give it zero momentum")


def check_constraints(atoms: Atoms) -> bool:
    """Refuse ASE constraints other than FixCom; returns whether FixCom is there."""
    others = [c for c in atoms.constraints if not isinstance(c, (RigidBodyDOF, FixCom))]
    if others:
        raise ValueError(
            f"rigid-body dynamics cannot honour other ASE constraints ({others[0]!r}); "
            "remove them (rigid bodies replace bond constraints; atoms in no body are "
            "free point particles; FixCom is honoured)"
        )
    return any(isinstance(c, FixCom) for c in atoms.constraints)
