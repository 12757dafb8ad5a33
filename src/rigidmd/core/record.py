r"""The per-step record: what one step computed, each quantity at most once.

The force evaluator (:mod:`rigidmd.core.forces`) fills a :class:`StepRecord` at
every force call (body forces and torques, the lab displacements of the body
atoms, the molecular virial and the potential energy when they were asked
for); the volume and the kinetic quantities are computed on first request
and kept with the versions of the state they were computed at
(:attr:`rigidmd.core.state.RigidState.versions`): when the state's positions,
momenta or cell change, the counter moves and the next request computes the
quantity again.  Nobody invalidates the record by hand.  Coupling parts read
the record instead of asking again; a part that scales the velocities in place
by a known factor says so through :meth:`StepRecord.scaled`, the one mutator
that moves the momenta's version and carries the kinetic tensor and the
rotational energy to it, scaled, instead of summing again.

Over one step with a Nosé–Hoover thermostat and the MTK barostat this gives
one calculator call, one volume, one kinetic tensor, one rotational kinetic
energy and one stress (a test counts them).
"""

from typing import TYPE_CHECKING

import numpy as np

from rigidmd.core import observables as obs
from rigidmd.core.backend import NUMPY, Backend
from rigidmd.core.model import BodyModel
from rigidmd.core.state import RigidState

if TYPE_CHECKING:
    from rigidmd.core.link import BodyLink

__all__ = ["StepRecord"]

#: Names of the array fields a step overwrites and a rollback restores.
_FORCE_FIELDS = ("F", "tau", "f", "r")


class StepRecord:
    r"""Forces of the last call and the quantities derived from the state, computed once.

    Attributes
    ----------
    state : RigidState
        The state the derived quantities describe (the same object the step advances).
    model : BodyModel
    F, tau : numpy.ndarray, shape (n_bodies, 3)
        Body forces (eV/Å) and lab torques (eV) of the last force call.
    f : numpy.ndarray, shape (n_free, 3)
        Forces on the point particles (eV/Å).
    r : numpy.ndarray, shape (n_body_atoms, 3)
        Lab displacements :math:`R(q)\,d_i` of the body atoms at the last
        placement (Å), in ``model.order``.
    virial : numpy.ndarray, shape (3, 3), or None
        Molecular virial of the last call (eV) when the stress was asked for.
    energy : float or None
        Potential energy of the last call (eV) when it was asked for.
    scratch : dict
        Values an operator hands to a later one (exaDEM's accelerations,
        PCDM's start-of-step values); kept across steps.
    link : rigidmd.core.link.BodyLink or None
        The body link whose backend the record's sums follow (None: NumPy).
    forces_known : bool
        Whether the forces, torques and virial are a calculator call's for the state:
        False from construction until a run's start has them (a dynamics exported
        before its first force call holds zeros, and its restored copy calls the
        calculator at its start, as the original would).
    """

    def __init__(self, state: RigidState, model: BodyModel, link: "BodyLink | None" = None):
        nb, nf = model.n_bodies, model.n_free
        self.state, self.model, self.link = state, model, link
        self.F, self.tau = np.zeros((nb, 3)), np.zeros((nb, 3))
        self.f = np.zeros((nf, 3))
        self.r = np.zeros((len(model.order), 3))
        self.virial = None
        self.energy = None
        self.scratch = {}
        self.forces_known = False
        # Each derived quantity with the state's version it describes (-1: none yet).
        self._volume, self._volume_at = None, -1
        self._kinetic, self._kinetic_at = None, -1
        self._rotational, self._rotational_at = None, (-1, -1)

    @property
    def backend(self) -> Backend:
        """The backend the sums run on: the link's (:data:`~rigidmd.core.backend.NUMPY`
        without a link)."""
        link = self.link
        return NUMPY if link is None else link.backend

    # ------------------------------------------------------------ derived, once per version
    @property
    def volume(self) -> float:
        """Volume of ``state.cell`` (Å³), computed once per version of the cell."""
        at = self.state.versions[2]
        if self._volume_at != at:
            self._volume, self._volume_at = obs.volume(self.state.cell), at
        return self._volume

    @property
    def kinetic_tensor(self) -> np.ndarray:
        """Translational kinetic tensor (eV, 3x3; :func:`.observables.kinetic_tensor`),
        computed once per version of the momenta."""
        at = self.state.versions[1]
        if self._kinetic_at != at:
            self._kinetic = self.backend.kinetic_tensor(self.state, self.model)
            self._kinetic_at = at
        return self._kinetic

    @property
    def translational_energy(self) -> float:
        """Kinetic energy of the centres of mass and point particles (eV)."""
        K = self.kinetic_tensor
        return 0.5 * float(K[0, 0] + K[1, 1] + K[2, 2])  # the trace, summed in its order

    @property
    def rotational_energy(self) -> float:
        """Rotational kinetic energy of the bodies (eV), computed once per version of the
        orientations and momenta."""
        versions = self.state.versions
        at = (versions[0], versions[1])
        if self._rotational_at != at:
            self._rotational = self.backend.rotational_energy(self.state, self.model)
            self._rotational_at = at
        return self._rotational

    def current(self) -> tuple:
        """``(volume, kinetic tensor, rotational energy)`` as kept for the state's present
        versions; None for each that is not (it would be computed on request)."""
        versions = self.state.versions
        return (self._volume if self._volume_at == versions[2] else None,
                self._kinetic if self._kinetic_at == versions[1] else None,
                self._rotational if self._rotational_at == (versions[0], versions[1])
                else None)

    def adopt(self, volume, kinetic, rotational) -> None:
        """Keep these values as the state's present ones (None: computed on request).

        For a state put back as it was when :meth:`current` gave them (a rollback,
        a checkpoint): the values describe it bit for bit.
        """
        versions = self.state.versions
        self._volume, self._volume_at = volume, (-1 if volume is None else versions[2])
        self._kinetic, self._kinetic_at = kinetic, (-1 if kinetic is None else versions[1])
        self._rotational = rotational
        self._rotational_at = (-1, -1) if rotational is None else (versions[0], versions[1])

    # ------------------------------------------------------------ the one scaling mutator
    def scaled(self, translation=None, rotation=None, about=None) -> None:
        r"""The velocities were just scaled in place: move the momenta's version, carry the sums.

        Call it right after writing the scaled arrays in place (``state.V[...] = ...``,
        ``state.p[...] *= s``, a kernel on ``state.data``: writes that do not move the
        version themselves); the kinetic tensor and rotational energy kept for the
        version before the scaling are carried to the new one without a new sum over
        bodies.  A quantity not kept is computed on request, as always.

        Parameters
        ----------
        translation : float, numpy.ndarray of shape (3, 3), or None
            Every translational velocity became :math:`s V` (a number) or :math:`F V`
            (a matrix): the kinetic tensor becomes :math:`s^2 K` or
            :math:`F K F^\mathsf{T}`.  None: the translational velocities did not change.
        rotation : float or None
            Every angular momentum was multiplied by it: the rotational energy by its
            square.  None: the angular momenta did not change.
        about : tuple (U, M), optional
            With a number ``translation``: the velocities became :math:`U + s\,(V - U)`,
            :math:`U = P/M` (Å / ASE time, shape (3,)) and :math:`M` the total mass (amu).
            With :math:`\sum m (V - U) = 0` the kinetic tensor becomes
            :math:`M\,U\otimes U + s^2 (K - M\,U\otimes U)`.
        """
        versions = self.state.versions
        K = self._kinetic if self._kinetic_at == versions[1] else None
        R = self._rotational if self._rotational_at == (versions[0], versions[1]) else None
        versions[1] += 1  # the state's touched(momenta=True), inline
        if K is not None and translation is not None:
            if about is not None:
                centre, mass = about
                K_cm = mass * np.multiply.outer(centre, centre)
                K = K_cm + float(translation) ** 2 * (K - K_cm)
            elif isinstance(translation, np.ndarray) and translation.ndim == 2:
                K = self.backend.congruence(translation, K)
            else:
                K = K * float(translation) ** 2
        if R is not None and rotation is not None:
            R = R * float(rotation) ** 2
        self._kinetic, self._kinetic_at = K, (-1 if K is None else versions[1])
        self._rotational = R
        self._rotational_at = (-1, -1) if R is None else (versions[0], versions[1])

    def net_force(self) -> tuple[float, float]:
        """``(|sum of the forces|, sum of their magnitudes)`` of the last force call (eV/Å).

        Body forces and point-particle forces together: zero for forces that
        conserve the momentum, to roundoff.  One pass over the forces, on the
        link's backend.
        """
        return self.backend.net_force(self.F, self.f)

    # ------------------------------------------------------------ rollback and checkpoints
    def get_state(self) -> dict:
        """Copies of everything the record holds (for a rollback or a checkpoint)."""
        volume, kinetic, rotational = self.current()
        return {"F": self.F.copy(), "tau": self.tau.copy(), "f": self.f.copy(),
                "r": self.r.copy(),
                "virial": None if self.virial is None else self.virial.copy(),
                "energy": self.energy, "scratch": dict(self.scratch),
                "volume": volume,
                "kinetic": None if kinetic is None else kinetic.copy(),
                "rotational": rotational, "forces_known": self.forces_known}

    def set_state(self, saved: dict) -> None:
        """Restore what :meth:`get_state` returned, for the state as it is now (restored
        first); absent keys leave a quantity to recompute (``forces_known`` absent: the
        forces are taken as known, as a rigidmd that did not store the key did)."""
        for name in _FORCE_FIELDS:
            if saved.get(name) is not None:
                setattr(self, name, np.array(saved[name], dtype=float))
        self.virial = None if saved.get("virial") is None else np.array(saved["virial"])
        self.energy = saved.get("energy")
        self.scratch = dict(saved.get("scratch", {}))
        self.forces_known = bool(saved.get("forces_known", True))
        volume, kinetic, rotational = (saved.get("volume"), saved.get("kinetic"),
                                       saved.get("rotational"))
        self.adopt(None if volume is None else float(volume),
                   None if kinetic is None else np.array(kinetic, dtype=float),
                   None if rotational is None else float(rotational))

    def backup(self, copy: bool = True) -> tuple:
        """A token for :meth:`restore` within one step.

        ``copy=False`` keeps references only: enough when nothing that can fail
        comes after the arrays are written (the fused kernel writes them in place
        after the force call succeeded; a coupling part's second half comes after
        that, so the stepper copies when there are couplings).
        """
        derived = self.current()
        if copy:
            return (self.F.copy(), self.tau.copy(), self.f.copy(), self.virial, self.energy,
                    derived, dict(self.scratch))
        return (self.F, self.tau, self.f, self.virial, self.energy, derived, self.scratch)

    def restore(self, token: tuple) -> None:
        """Put back what :meth:`backup` returned (a failed step), for the state as it was
        then (restored first: the derived values describe it)."""
        (self.F, self.tau, self.f, self.virial, self.energy, derived, self.scratch) = token
        self.adopt(*derived)
