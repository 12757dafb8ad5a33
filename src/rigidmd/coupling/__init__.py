r"""Coupling parts: thermostats (and barostats) composed into a rigid dynamics.

A :class:`~rigidmd.dynamics.RigidDynamics` holds an integrator scheme and a
list of coupling parts.  Each step of :math:`\Delta t` is the symmetric
splitting

.. code-block:: text

    part_1.first_half(Δt/2) ... part_n.first_half(Δt/2)
    the integrator's deterministic step (forces, drift, rotation)
    part_n.second_half(Δt/2) ... part_1.second_half(Δt/2)

A part acts on the body state (centre-of-mass velocities, NO_SQUISH
momenta, point particles; a barostat also on the cell), contributes a term to
the conserved energy, saves and restores its own variables (for the rollback
of a failed step and for checkpoints), and says what it is in a LAMMPS deck.

:data:`COUPLINGS` maps each kind's name (``"langevin"``, ``"bussi"``,
``"nose_hoover"``, ...) to its class; the class's :attr:`Coupling.parameters`
say which parameters it takes, with which units, so that the configuration
checker, the command line and the LAMMPS export all read one registry.
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["Coupling", "Parameter", "COUPLINGS", "register", "NotExportable", "LammpsFix"]

#: Registered coupling kinds, name -> class.
COUPLINGS = {}


class NotExportable(ValueError):
    """A coupling part has no LAMMPS equivalent."""


@dataclass(frozen=True)
class Parameter:
    """One parameter of a coupling kind, as the configuration file spells it.

    Attributes
    ----------
    name : str
        Keyword of the class's constructor (``"temperature_K"``, ``"taut"``).
    field : str
        Key in the configuration section (``"temperature"``, ``"taut"``).
    quantity : str
        How the value is written and converted: ``"temperature"`` (``"300 K"``),
        ``"time"`` (``"100 fs"``, to ASE time), ``"rate"`` (``"0.01 1/fs"``, to
        1/ASE time), ``"pressure"`` (``"1 bar"``, to eV/Å³),
        ``"compressibility"`` (``"4.5e-5 1/bar"``, to Å³/eV), ``"integer"``,
        ``"seed"`` (an integer or absent, becomes ``rng``), ``"choice"``,
        ``"flag"`` (``true`` or ``false``).
    required : bool
    default : object
        Value used when the field is absent and not required.
    example : str
        Shown in the error message when the field is missing.
    choices : tuple of str
        Allowed values of a ``"choice"``.
    """

    name: str
    field: str
    quantity: str
    required: bool = True
    default: object = None
    example: str = ""
    choices: tuple = ()


@dataclass(frozen=True)
class LammpsFix:
    """What a coupling part is in a LAMMPS deck.

    Attributes
    ----------
    body_style : str
        Suffix of the rigid fix style (``"nve"``, ``"nvt"``, ``"npt"``) for
        ``fix ... rigid/<body_style>/small molecule``.
    body_keywords : str
        Keywords appended to that fix (``"temp 300 300 0.1"``, ``"langevin ..."``),
        in LAMMPS metal units.
    free_fixes : tuple of str
        Fix styles with arguments for the atoms in no body (``"nvt temp ..."``,
        ``"langevin ..."``), without ``fix ID group``.
    notes : tuple of str
        Where LAMMPS does something else than the part; written as comments.
    """

    body_style: str
    body_keywords: str = ""
    free_fixes: tuple = ()
    notes: tuple = ()


def register(cls):
    """Class decorator: add a coupling kind to :data:`COUPLINGS` under ``cls.kind``."""
    if cls.kind in COUPLINGS:
        raise ValueError(f"coupling kind {cls.kind!r} registered twice")
    COUPLINGS[cls.kind] = cls
    return cls


class Coupling:
    r"""Base class of the parts a rigid dynamics is composed of.

    Subclasses set :attr:`kind`, :attr:`section` and :attr:`parameters`,
    validate their parameters in ``__init__`` (before any dynamics exists),
    check them against the system in :meth:`bind`, and implement
    :meth:`first_half` (and :meth:`second_half` when the two half steps
    differ), :meth:`energy`, :meth:`get_state` and :meth:`set_state`.

    A part is bound to one dynamics; :attr:`dyn` is that dynamics after
    :meth:`bind`.
    """

    #: Name in the registry and in configuration files.
    kind: ClassVar[str] = ""
    #: Configuration section: ``"thermostat"`` or ``"barostat"``.
    section: ClassVar[str] = ""
    #: Parameters, in constructor order.
    parameters: ClassVar[tuple] = ()

    dyn = None
    #: Whether the dynamics must ask the calculator for the stress at every force call.
    needs_stress: ClassVar[bool] = False
    #: Whether the part moves the cell (a barostat; at most one per dynamics).
    moves_cell: ClassVar[bool] = False

    def check(self, dyn):
        """Check the parameters against a dynamics' system and time step; change nothing.

        Called by the dynamics' constructor after the atoms and bodies were
        validated and before anything is changed: raising here leaves
        everything as it was.
        """
        if self.dyn is not None and self.dyn is not dyn:
            raise ValueError(f"this {type(self).__name__} already belongs to another dynamics; "
                             "make a new one for each dynamics")
        self.check_timestep(dyn.dt)

    def check_timestep(self, dt):
        """Refuse a time step (ASE units) the part cannot work with; change nothing."""

    def bind(self, dyn):
        """Attach to a dynamics (after :meth:`check`), creating the part's variables."""
        self.dyn = dyn

    def first_half(self, h):
        """Act on the dynamics' state for a time ``h`` before the integrator's step."""
        raise NotImplementedError

    def second_half(self, h):
        """Act for a time ``h`` after the integrator's step (by default as before it)."""
        self.first_half(h)

    def energy(self):
        """This part's term in the conserved energy (eV)."""
        return 0.0

    def get_state(self):
        """The part's own variables, as a dict of floats, arrays and RNG states (copies)."""
        return {}

    def set_state(self, state):
        """Restore variables returned by :meth:`get_state`."""

    def lammps_fix(self):
        """The LAMMPS equivalent (:class:`LammpsFix`); raises :class:`NotExportable` if none."""
        raise NotExportable(f"{self.section} kind {self.kind!r} has no LAMMPS equivalent")

    def todict(self):
        """Parameters of this part, for trajectories and logs."""
        return {"kind": self.kind}


def check_rng(rng):
    """Accept what ASE's stochastic integrators accept as ``rng``.

    A :class:`numpy.random.Generator`, a :class:`numpy.random.RandomState`,
    or the module :mod:`numpy.random` itself (ASE's default); None gives a new
    unseeded Generator.  Each of these can save and restore its state, which
    the rollback of a failed step and checkpoints need.
    """
    if rng is None:
        return np.random.default_rng()
    if isinstance(rng, np.random.Generator) or isinstance(rng, np.random.RandomState) \
            or rng is np.random:
        return rng
    raise TypeError(f"rng must be a numpy.random.Generator, a numpy.random.RandomState or "
                    f"numpy.random, got {type(rng).__name__}")


def rng_state(rng):
    """A copy of the state of an ``rng`` accepted by :func:`check_rng`."""
    if isinstance(rng, np.random.Generator):
        return {"generator": dict(rng.bit_generator.state)}
    return {"legacy": rng.get_state(legacy=False)}


def set_rng_state(rng, state):
    """Restore a state returned by :func:`rng_state`."""
    if "generator" in state:
        rng.bit_generator.state = state["generator"]
    else:
        rng.set_state(state["legacy"])


def _register_builtin_kinds():
    """Import the modules that register the built-in kinds (thermostats, barostats)."""
    from rigidmd.coupling import barostats, thermostats  # noqa: F401


_register_builtin_kinds()
