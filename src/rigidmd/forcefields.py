"""Water and CO2 force-field parameters and their LAMMPS commands, in one place.

TIP3P here is ASE's (:mod:`ase.calculators.tip3p`): O-O Lennard-Jones
``sigma0``, ``epsilon0`` and charges ``-2 qH`` / ``qH``, which LAMMPS reproduces
with ``lj/cut/coul/cut`` and intramolecular exclusion.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from ase import Atoms
from ase.calculators.tip3p import epsilon0, qH, sigma0

__all__ = ["tip3p_pair_commands", "tip3p_charges"]


def tip3p_pair_commands(
    cutoff: float = 40.0, oxygen_types: Sequence[str | int] = ("O",)
) -> list[str]:
    """LAMMPS pair commands for TIP3P as ``ase.calculators.tip3p.TIP3P``.

    Lennard-Jones between oxygens only (``sigma0``, ``epsilon0`` of ASE's
    module), plain cut-off Coulomb between all atoms, no interactions inside a
    molecule.  The charges come from the data file, see
    :func:`tip3p_charges` and :func:`write_data`.

    ASE's ``TIP3P(rc, width)`` switches whole molecule pairs off smoothly for
    O–O distances between ``rc - width`` and ``rc``; LAMMPS cuts atom pairs
    at ``cutoff``.  The two agree when every O–O distance is below
    ``rc - width`` and every atom pair is within ``cutoff`` (e.g. a cluster
    smaller than 39 Å with ``rc = cutoff = 40``).

    Parameters
    ----------
    cutoff : float, default 40.0
        LJ and Coulomb cut-off, Å.
    oxygen_types : sequence of str or int, default ("O",)
        LAMMPS atom type labels or numbers of the oxygens, as returned in
        :attr:`LammpsData.types` by :func:`write_data` (the label is the
        element symbol when an element has a single mass).

    Returns
    -------
    list of str
        ``pair_style``, ``pair_coeff`` and ``neigh_modify`` commands.
    """
    cmds = [
        f"pair_style lj/cut/coul/cut {float(cutoff)!r}",
        "pair_coeff * * 0.0 1.0",
    ]
    types = [str(t) for t in oxygen_types]
    for i, ti in enumerate(types):
        for tj in types[i:]:
            cmds.append(f"pair_coeff {ti} {tj} {epsilon0!r} {sigma0!r}")
    cmds.append("neigh_modify exclude molecule/intra all")
    return cmds


def tip3p_charges(atoms: Atoms) -> np.ndarray:
    """TIP3P charges of ASE's ``TIP3P`` calculator.

    Parameters
    ----------
    atoms : ase.Atoms
        Water molecules (only O and H atoms).

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``-2 * qH`` on O and ``qH`` on H, in units of e.

    Raises
    ------
    ValueError
        If ``atoms`` contains elements other than O and H.
    """
    numbers = atoms.numbers
    other = sorted(set(atoms.symbols[(numbers != 1) & (numbers != 8)]))
    if other:
        raise ValueError(f"TIP3P has charges for O and H only, not {other}")
    return np.where(numbers == 8, -2.0 * qH, qH)


