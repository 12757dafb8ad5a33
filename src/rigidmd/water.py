r"""Rigid water models: geometry, charges, Lennard-Jones parameters and LAMMPS commands.

Three-site models put the negative charge on the oxygen; four-site models put
it on a massless site M on the H–O–H bisector, ``d_om`` from the oxygen.
rigidmd carries M as an explicit atom (chemical symbol ``X``, mass 0) inside
the rigid body of its molecule: any calculator that sees it as a charged atom
gives the right forces, the body takes the force on M into its own force and
torque, and M adds no mass and no degree of freedom (see
:mod:`rigidmd.core.model`).  Molecules are ordered O, H, H (, M).

==============  ========  =========  ========  ========  ========  =============
model           r_OH (Å)  HOH (deg)  d_OM (Å)  q_H (e)   σ_OO (Å)  ε_OO (kJ/mol)
==============  ========  =========  ========  ========  ========  =============
``tip3p``       0.9572    104.52     0         0.417     3.15061   0.6364
``spce``        1.0       109.47     0         0.4238    3.166     0.650
``tip4p``       0.9572    104.52     0.15      0.52      3.15358   0.6487
``tip4p2005``   0.9572    104.52     0.1546    0.5564    3.1589    0.7749
``tip4pew``     0.9572    104.52     0.125     0.52422   3.16435   0.680946
``opc``         0.8724    103.6      0.1594    0.6791    3.16655   0.89036
==============  ========  =========  ========  ========  ========  =============

``tip3p`` and ``tip4p`` are the parameters of ASE's
:class:`~ase.calculators.tip3p.TIP3P` and :class:`~ase.calculators.tip4p.TIP4P`
(Jorgensen et al. 1983), so explicit-site runs can be checked against them.
``spce`` is SPC/E [5]_: SPC's tetrahedral geometry and Lennard-Jones with the
charges raised to a dipole of 2.35 D, its paper's liquid energy counting the
self-polarisation cost (see :mod:`rigidmd.mdanalysis.thermo`).
ASE's TIP3P σ (3.15061 Å, CHARMM's R_min 3.5365 Å / 2^(1/6)) differs from
the 1983 A, C coefficients' 3.15066 Å by 2e-5 relative.  Checked against
other sources: SPC/E (SklogWiki; Mark & Nilsson, J. Phys. Chem. A 105, 9954
(2001), Table 1), TIP4P-Ew and TIP4P/2005 (LAMMPS "TIP4P water model" howto),
OPC (ε 0.2128 kcal/mol and R_min/2 1.77717 Å in the OpenFF port
``opc-1.0.2.offxml``; q_H and geometry in the OPC GROMACS topology).

References
----------
.. [1] W. L. Jorgensen, J. Chandrasekhar, J. D. Madura, R. W. Impey and
   M. L. Klein, J. Chem. Phys. 79, 926 (1983) (TIP3P, TIP4P).
.. [2] J. L. F. Abascal and C. Vega, J. Chem. Phys. 123, 234505 (2005)
   (TIP4P/2005: ε/k = 93.2 K).
.. [3] H. W. Horn, W. C. Swope, J. W. Pitera, J. D. Madura, T. J. Dick,
   G. L. Hura and T. Head-Gordon, J. Chem. Phys. 120, 9665 (2004) (TIP4P-Ew).
.. [4] S. Izadi, R. Anandakrishnan and A. V. Onufriev, J. Phys. Chem. Lett.
   5, 3863 (2014) (OPC).
.. [5] H. J. C. Berendsen, J. R. Grigera and T. P. Straatsma, J. Phys. Chem.
   91, 6269 (1987) (SPC/E: σ = 3.166 Å, ε = 0.650 kJ/mol, q_O = −0.8476 e).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
from ase import Atoms, units
from ase.calculators import tip3p as ase_tip3p
from ase.calculators import tip4p as ase_tip4p
from ase.data import atomic_masses
from ase.geometry import find_mic

from rigidmd.core.checks import real_number

__all__ = ["WaterModel", "WATER_MODELS", "water_model", "M_SYMBOL", "tip3p_pair_commands",
           "tip3p_charges"]

#: Chemical symbol of the massless charge site M (ASE's dummy element, Z = 0).
M_SYMBOL = "X"

_KJ = units.kJ / units.mol

#: The k-space solvers :meth:`WaterModel.lammps_commands` writes (``lj/cut/coul/long``
#: takes both; ``pppm/tip4p`` and the like need another pair style).
KSPACE_STYLES = ("pppm", "ewald")


def whole_argument(where, name, value, minimum):
    """``value`` as an int, refused unless a whole number (int, or float without fraction).

    Raises
    ------
    TypeError
        Not a number (a bool is not one).
    ValueError
        Not finite, with a fraction, or below ``minimum``.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{where}: {name} must be a whole number >= {minimum}, got {value!r}")
    if not (np.isfinite(value) and value == np.floor(value) and value >= minimum):
        raise ValueError(f"{where}: {name} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def real_argument(where, name, value, minimum=0.0, strict=True, unit=""):
    """``value`` as a finite float above ``minimum`` (at or above it with ``strict=False``).

    Raises
    ------
    TypeError
        Not a number (:func:`rigidmd.core.checks.real_number`'s rule: bools and text are
        not).
    ValueError
        Not finite, or below the bound.
    """
    bound = f"{'>' if strict else '>='} {minimum:g}{unit}"
    number = real_number(f"{where}: {name}", value, f"a finite number {bound}")
    if not (np.isfinite(number) and (number > minimum if strict else number >= minimum)):
        raise ValueError(f"{where}: {name} must be a finite number {bound}, got {value!r}")
    return number


@dataclass(frozen=True)
class WaterModel:
    """One rigid water model.

    Attributes
    ----------
    name : str
        Key in :data:`WATER_MODELS`.
    r_oh : float
        O–H bond length, Å.
    angle_hoh : float
        H–O–H angle, degrees.
    d_om : float
        O–M distance, Å; 0 for a three-site model (charge on O).
    q_h : float
        Charge of each hydrogen, e (O or M carries ``-2 q_h``).
    sigma : float
        O–O Lennard-Jones σ, Å (no Lennard-Jones on H or M).
    epsilon : float
        O–O Lennard-Jones ε, eV.
    reference : str
        Where the parameters come from.
    """

    name: str
    r_oh: float
    angle_hoh: float
    d_om: float
    q_h: float
    sigma: float
    epsilon: float
    reference: str

    @property
    def sites(self):
        """Atoms per molecule: 3, or 4 with the M site."""
        return 4 if self.d_om > 0 else 3

    @property
    def symbols(self):
        """Chemical symbols of one molecule: ``OH2`` or ``OH2X``."""
        return "OH2" + (M_SYMBOL if self.sites == 4 else "")

    def molecule(self):
        """One molecule, oxygen at the origin, in the xy plane, bisector along +y.

        Returns
        -------
        ase.Atoms
            O, H, H (, M); with M, the masses are set (ASE's for O and H, 0
            for M).
        """
        half = np.radians(self.angle_hoh) / 2
        positions = [[0.0, 0.0, 0.0],
                     [self.r_oh * np.sin(half), self.r_oh * np.cos(half), 0.0],
                     [-self.r_oh * np.sin(half), self.r_oh * np.cos(half), 0.0]]
        if self.sites == 4:
            positions.append([0.0, self.d_om, 0.0])
        atoms = Atoms(self.symbols, positions=positions)
        if self.sites == 4:
            atoms.set_masses(self.masses())  # ASE's default for X is 1 amu
        return atoms

    def masses(self):
        """Masses of one molecule's sites, amu: O, H, H (, 0)."""
        m = [atomic_masses[8], atomic_masses[1], atomic_masses[1]]
        return np.array(m + [0.0] * (self.sites - 3))

    def charges(self, n_molecules=1):
        """Charges of ``n_molecules`` molecules in order (e).

        ``(-2 q_h, q_h, q_h)`` per molecule, or ``(0, q_h, q_h, -2 q_h)``
        with the M site.

        Raises
        ------
        TypeError, ValueError
            ``n_molecules`` not a whole number >= 0.
        """
        n = whole_argument(self.name, "n_molecules", n_molecules, 0)
        one = [-2 * self.q_h, self.q_h, self.q_h] if self.sites == 3 else [
            0.0, self.q_h, self.q_h, -2 * self.q_h]
        return np.tile(one, n)

    def check(self, atoms, tolerance=1e-3):
        """Refuse atoms that are not whole molecules of this model, in order, in its geometry.

        Each molecule (its sites relative to its oxygen, minimum image across
        a periodic cell) is superposed on the model's molecule, least squares
        over all its sites (O, H, H and M, unweighted), and every site must lie
        within ``tolerance`` of the model's place for it.  Pair distances alone
        would not do: an M reflected across the O–H1 line keeps its O–M and
        H1–M distances, and one moved out of the plane by δ changes them by
        only δ²/2r.

        Parameters
        ----------
        atoms : ase.Atoms
        tolerance : float, default 1e-3
            Largest distance of a site from the model's place for it (Å),
            after that superposition.  The builders place sites to roundoff
            (1e-15 Å); positions rounded to three decimals (PDB) move a site
            up to 8e-4 Å (measured on 216 waters of each model), four decimals
            8e-5 Å; the closest other model, ``tip4p`` against ``tip4p2005``
            (O–M 0.15 against 0.1546 Å), is 3.45e-3 Å off, and ``tip3p``
            against ``spce`` 0.060 Å.

        Raises
        ------
        ValueError
            Naming the first atom whose symbol differs, or whose position is
            not finite, a count that is not a multiple of :attr:`sites`, or
            the first molecule not in this model's geometry (another
            model's, say, or with a site misplaced).
        """
        tolerance = real_argument(self.name, "tolerance", tolerance, minimum=0.0)
        k = self.sites
        if len(atoms) % k:
            raise ValueError(f"{self.name}: {len(atoms)} atoms is not a whole number of "
                             f"{k}-site molecules ({self.symbols})")
        expected = np.tile(self.molecule().numbers, len(atoms) // k)
        bad = np.flatnonzero(atoms.numbers != expected)
        if bad.size:
            a = int(bad[0])
            raise ValueError(f"{self.name}: atom {a} is {atoms[a].symbol}, expected "
                             f"{Atoms(expected[a:a + 1]).get_chemical_symbols()[0]} "
                             f"(molecules in the order {self.symbols})")
        if len(atoms) == 0:
            return
        bad = np.flatnonzero(~np.isfinite(atoms.positions).all(axis=1))
        if bad.size:
            a = int(bad[0])
            raise ValueError(f"{self.name}: atom {a} ({atoms[a].symbol}) has the position "
                             f"{atoms.positions[a].tolist()}; positions must be finite")
        self._check_masses(atoms)
        x = atoms.positions.reshape(-1, k, 3)
        d = (x[:, 1:] - x[:, :1]).reshape(-1, 3)
        if atoms.pbc.any():
            d = find_mic(d, atoms.cell, atoms.pbc)[0]
        d = d.reshape(len(x), k - 1, 3)
        worst, site = self._site_errors(np.concatenate([np.zeros((len(x), 1, 3)), d], axis=1))
        bad = np.flatnonzero(worst > tolerance)
        if bad.size:
            m = int(bad[0])
            oh = np.linalg.norm(d[m, 0])
            raise ValueError(
                f"{self.name}: molecule {m} (atoms {k * m}-{k * m + k - 1}) is not in this "
                f"model's geometry (atom {k * m + site[m]} is {worst[m]:.3g} Å from the "
                f"model's place, tolerance {tolerance:g} Å; O-H {oh:.4f} Å, the model's "
                f"{self.r_oh} Å); build it with this model")

    def _site_errors(self, sites):
        """Each molecule's largest site distance from the model's after the best superposition.

        Parameters
        ----------
        sites : numpy.ndarray, shape (n, k, 3)
            Whole molecules, sites in the model's order.

        Returns
        -------
        worst : numpy.ndarray, shape (n,)
            Largest distance (Å).
        site : numpy.ndarray, shape (n,)
            Index within the molecule of the site that is that far.
        """
        own = self.molecule().positions
        reference = own - own.mean(axis=0)
        target = sites - sites.mean(axis=1, keepdims=True)
        # Kabsch: the proper rotation R minimising sum |R reference - target|^2.
        h = np.einsum("ki,nkj->nij", reference, target)
        u, _, vt = np.linalg.svd(h)
        flip = np.ones((len(h), 3))
        flip[:, 2] = np.sign(np.linalg.det(np.einsum("nij,njk->nik", u, vt)))
        rotation = np.einsum("nji,nj,nkj->nik", vt, flip, u)
        fitted = np.einsum("nij,kj->nki", rotation, reference)
        error = np.linalg.norm(target - fitted, axis=2)
        return error.max(axis=1), error.argmax(axis=1)

    def _check_masses(self, atoms):
        """Refuse an M site with mass (it would move as an atom) or an O or H without.

        Isotopes (D, 18O) are masses like any other: only the sign is checked.
        """
        masses = atoms.get_masses()
        massless = atoms.numbers == 0
        bad = np.flatnonzero(massless & (masses != 0))
        if bad.size:
            a = int(bad[0])
            raise ValueError(
                f"{self.name}: atom {a} (X, the M site of molecule {a // self.sites}) has mass "
                f"{masses[a]:g} amu but M is massless; give the M sites mass 0 "
                "(atoms.set_masses), or keep the structure in a format that stores masses "
                "(.traj, extended XYZ): PDB and XYZ files have none, and ASE gives X 1 amu")
        bad = np.flatnonzero(~massless & ~(masses > 0))
        if bad.size:
            a = int(bad[0])
            raise ValueError(f"{self.name}: atom {a} ({atoms[a].symbol}) has mass "
                             f"{masses[a]:g} amu; O and H need a positive mass")

    def lammps_commands(self, cutoff, kspace="pppm", accuracy=1e-5, tail=None,
                        oxygen_type="O"):
        """LAMMPS interaction commands for explicit sites (``lj/cut/coul/long``).

        Lennard-Jones between oxygens only, Coulomb between all charged
        sites, long-range electrostatics by ``kspace``; pairs within a
        molecule excluded (:class:`~rigidmd.lammps.LAMMPSCalculator` and
        exported decks exclude them through the molecule IDs).  M is a type
        of its own with neither Lennard-Jones nor a special pair style.

        Parameters
        ----------
        cutoff : float
            Real-space cut-off of Lennard-Jones and Coulomb, Å; positive and
            finite.
        kspace : {"pppm", "ewald"} or None
            ``None``: plain cut-off Coulomb (``lj/cut/coul/cut``), for clusters.
            Other LAMMPS styles are refused: ``pppm/tip4p`` and the like need
            another pair style, and LAMMPS's names are lower case.
        accuracy : float
            Relative force accuracy of the k-space solver, between 0 and 1
            (not read without k-space).
        tail : bool or None, default None
            Long-range Lennard-Jones corrections to energy and pressure
            (``pair_modify tail yes``), as the TIP4P/2005, TIP4P-Ew and OPC
            papers use; ``None`` means with k-space and not without.  The
            correction assumes a homogeneous periodic system: for a cluster
            (``kspace=None``) it would depend on the box LAMMPS draws around
            it, so ``tail=True`` is refused there.
        oxygen_type : str or int
            The oxygens' LAMMPS type (label or number).

        Returns
        -------
        list of str
            ``pair_style``, its ``pair_coeff``, ``pair_modify`` and
            ``kspace_style`` commands.

        Raises
        ------
        TypeError
            ``cutoff`` or ``accuracy`` not a number, ``tail`` not a bool or None.
        ValueError
            ``cutoff`` not positive and finite, an unknown ``kspace``,
            ``accuracy`` not between 0 and 1, or ``tail=True`` without k-space.
        """
        cutoff = real_argument(self.name, "cutoff", cutoff, unit=" Å")
        if kspace is not None and kspace not in KSPACE_STYLES:
            raise ValueError(f"{self.name}: kspace must be one of {', '.join(KSPACE_STYLES)} "
                             f"or None (plain cut-off Coulomb, for clusters), got {kspace!r}")
        if kspace is not None:
            accuracy = real_argument(self.name, "accuracy", accuracy)
            if not accuracy < 1:
                raise ValueError(f"{self.name}: accuracy is a relative force accuracy, "
                                 f"between 0 and 1, got {accuracy!r}")
        if tail is None:
            tail = kspace is not None
        elif not isinstance(tail, (bool, np.bool_)):
            raise TypeError(f"{self.name}: tail must be True, False or None (with k-space), "
                            f"got {tail!r}")
        if tail and kspace is None:
            raise ValueError(f"{self.name}: tail=True needs k-space (a periodic box); without "
                             "it (kspace=None, a cluster) the Lennard-Jones tail correction "
                             "depends on the box LAMMPS draws: use tail=False or None")
        coulomb = "cut" if kspace is None else "long"
        cmds = [f"pair_style lj/cut/coul/{coulomb} {cutoff!r}",
                "pair_coeff * * 0.0 1.0",
                f"pair_coeff {oxygen_type} {oxygen_type} {self.epsilon!r} {self.sigma!r}"]
        if tail:
            cmds.append("pair_modify tail yes")
        if kspace is not None:
            cmds.append(f"kspace_style {kspace} {accuracy!r}")
        return cmds

    def lammps_short_range_commands(self, cutoff, alpha=0.2, smooth=True, oxygen_type="O"):
        """LAMMPS commands for a cheap short-range form of the model: a split's fast level.

        Damped shifted-force Coulomb (``coul/dsf``, Fennell & Gezelter, J. Chem. Phys.
        124, 234104 (2006)) between all charged sites, M included, and Lennard-Jones
        between oxygens, both cut at ``cutoff``; no k-space.  With ``smooth``, the
        Lennard-Jones force is shifted to zero at the cut-off too (``lj/smooth/linear``
        beside ``coul/dsf`` under ``hybrid/overlay``), so that the slow level of a split
        ``full - fast`` (:class:`~rigidmd.MultipleTimeStep` with :meth:`lammps_commands`
        as the full model) has no jump there; without, one pair style
        (``lj/cut/coul/dsf``, the Lennard-Jones energy shifted to zero at the cut-off,
        its force not), about a quarter cheaper on 216 waters at 5 Å.  Pairs within a
        molecule are excluded as for :meth:`lammps_commands`.

        Parameters
        ----------
        cutoff : float
            Cut-off of both terms, Å (the split distance).
        alpha : float, default 0.2
            Damping of the Coulomb term, 1/Å.
        smooth : bool, default True
            Lennard-Jones force shifted to zero at ``cutoff`` as well.
        oxygen_type : str or int
            The oxygens' LAMMPS type (label or number).

        Returns
        -------
        list of str
            ``pair_style``, its ``pair_coeff`` and ``pair_modify`` commands.

        Raises
        ------
        ValueError
            ``cutoff`` not positive, or ``alpha`` negative.
        """
        cutoff, alpha = float(cutoff), float(alpha)
        if not cutoff > 0 or not alpha >= 0:
            raise ValueError(f"{self.name}: short-range LAMMPS commands need a positive cutoff "
                             f"and a non-negative alpha, got cutoff={cutoff}, alpha={alpha}")
        lj = f"{oxygen_type} {oxygen_type}"
        if not smooth:
            return [f"pair_style lj/cut/coul/dsf {alpha!r} {cutoff!r} {cutoff!r}",
                    "pair_coeff * * 0.0 1.0",
                    f"pair_coeff {lj} {self.epsilon!r} {self.sigma!r}",
                    "pair_modify shift yes"]
        return [f"pair_style hybrid/overlay lj/smooth/linear {cutoff!r} "
                f"coul/dsf {alpha!r} {cutoff!r}",
                "pair_coeff * * lj/smooth/linear 0.0 1.0",
                f"pair_coeff {lj} lj/smooth/linear {self.epsilon!r} {self.sigma!r}",
                "pair_coeff * * coul/dsf"]


WATER_MODELS = {
    "tip3p": WaterModel("tip3p", ase_tip3p.rOH, ase_tip3p.angleHOH, 0.0, ase_tip3p.qH,
                        ase_tip3p.sigma0, ase_tip3p.epsilon0,
                        "Jorgensen et al. 1983, as ase.calculators.tip3p"),
    "spce": WaterModel("spce", 1.0, 109.47, 0.0, 0.4238, 3.166, 0.650 * _KJ,
                       "Berendsen, Grigera & Straatsma, J. Phys. Chem. 91, 6269 (1987)"),
    "tip4p": WaterModel("tip4p", ase_tip4p.rOH, ase_tip4p.angleHOH, 0.15, ase_tip4p.qH,
                        ase_tip4p.sigma0, ase_tip4p.epsilon0,
                        "Jorgensen et al. 1983, as ase.calculators.tip4p"),
    "tip4p2005": WaterModel("tip4p2005", 0.9572, 104.52, 0.1546, 0.5564, 3.1589,
                            93.2 * units.kB, "Abascal & Vega, J. Chem. Phys. 123, 234505 (2005)"),
    "tip4pew": WaterModel("tip4pew", 0.9572, 104.52, 0.125, 0.52422, 3.16435, 0.680946 * _KJ,
                          "Horn et al., J. Chem. Phys. 120, 9665 (2004)"),
    "opc": WaterModel("opc", 0.8724, 103.6, 0.1594, 0.6791, 3.16655, 0.89036 * _KJ,
                      "Izadi, Anandakrishnan & Onufriev, J. Phys. Chem. Lett. 5, 3863 (2014)"),
}


def water_model(name):
    """The :class:`WaterModel` called ``name`` (a :data:`WATER_MODELS` key, any case).

    ``name`` may be a :class:`WaterModel` already: it is returned as it is, so that
    every function taking a model takes either.

    Raises
    ------
    ValueError
        An unknown name, listing the known ones.
    """
    if isinstance(name, WaterModel):
        return name
    key = str(name).lower().replace("/", "").replace("-", "")
    if key not in WATER_MODELS:
        raise ValueError(f"unknown water model {name!r}; use one of {', '.join(WATER_MODELS)}")
    return WATER_MODELS[key]


# ---------------------------------------------------------------- ASE's TIP3P in LAMMPS
def tip3p_pair_commands(cutoff: float = 40.0, oxygen_types=("O",)) -> list[str]:
    """LAMMPS pair commands for TIP3P as ``ase.calculators.tip3p.TIP3P``.

    Lennard-Jones between oxygens only (the ``tip3p`` model's σ and ε, ASE's
    ``sigma0`` and ``epsilon0``), plain cut-off Coulomb between all atoms, no
    interactions inside a molecule.  The charges come from the data file, see
    :func:`tip3p_charges` and :func:`rigidmd.lammps.write_data`.

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
        :attr:`LammpsData.types` by :func:`rigidmd.lammps.write_data` (the
        label is the element symbol when an element has a single mass).

    Returns
    -------
    list of str
        ``pair_style``, ``pair_coeff`` and ``neigh_modify`` commands.
    """
    model = WATER_MODELS["tip3p"]
    cmds = [f"pair_style lj/cut/coul/cut {float(cutoff)!r}", "pair_coeff * * 0.0 1.0"]
    types = [str(t) for t in oxygen_types]
    for i, ti in enumerate(types):
        for tj in types[i:]:
            cmds.append(f"pair_coeff {ti} {tj} {model.epsilon!r} {model.sigma!r}")
    cmds.append("neigh_modify exclude molecule/intra all")
    return cmds


def tip3p_charges(atoms: Atoms) -> np.ndarray:
    """TIP3P charges of ASE's ``TIP3P`` calculator: ``-2 qH`` on O, ``qH`` on H (e).

    Parameters
    ----------
    atoms : ase.Atoms
        Water molecules (only O and H atoms), in any order.

    Returns
    -------
    numpy.ndarray, shape (n,)

    Raises
    ------
    ValueError
        If ``atoms`` contains elements other than O and H.
    """
    numbers = atoms.numbers
    other = sorted(set(atoms.symbols[(numbers != 1) & (numbers != 8)]))
    if other:
        raise ValueError(f"TIP3P has charges for O and H only, not {other}")
    q_h = WATER_MODELS["tip3p"].q_h
    return np.where(numbers == 8, -2.0 * q_h, q_h)
