r"""The per-step record: what one step computed, each quantity at most once.

The force evaluator (:mod:`rigidmd.core.forces`) fills a :class:`StepRecord` at
every force call (body forces and torques, the lab displacements of the body
atoms, the molecular virial and the potential energy when they were asked
for); the volume and the kinetic quantities are computed on first request
and kept until the state they depend on changes.  Coupling parts read the
record instead of asking again, and tell it how they changed the velocities
(:meth:`StepRecord.scale_translation`, :meth:`StepRecord.scale_translation_about`,
:meth:`StepRecord.scale_rotation`) so that a known scaling updates the kinetic
tensor and the rotational energy instead of recomputing them.

Over one step with a Nosé–Hoover thermostat and the MTK barostat this gives
one calculator call, one volume, one kinetic tensor, one rotational kinetic
energy and one stress (a test counts them).
"""

from typing import TYPE_CHECKING

import numpy as np

from rigidmd.core import _numba
from rigidmd.core import observables as obs
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
    cell_move : object or None
        What a barostat's drift query returned during this step (see
        :meth:`rigidmd.core.coupling.Coupling.drift_matrices`); None before the drift.
    link : rigidmd.core.link.BodyLink or None
        The body link whose backend the record's sums follow (None: NumPy).
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
        self.cell_move = None
        self._volume = None
        self._kinetic = None
        self._rotational = None

    @property
    def compiled(self) -> bool:
        """The sums run the compiled loops of :mod:`rigidmd.core._numba`: the link's backend
        (``link.compiled``; the dynamics' ``"numba"``), not :mod:`rigidmd.core.observables`."""
        return self.link is not None and self.link.compiled

    # ------------------------------------------------------------ derived, once
    @property
    def volume(self) -> float:
        """Volume of ``state.cell`` (Å³), computed once per cell."""
        if self._volume is None:
            self._volume = obs.volume(self.state.cell)
        return self._volume

    @property
    def kinetic_tensor(self) -> np.ndarray:
        """Translational kinetic tensor (eV, 3x3; :func:`.observables.kinetic_tensor`)."""
        if self._kinetic is None:
            if self.compiled:
                s, m = self.state, self.model
                self._kinetic = _numba.kinetic_tensor(s.V, s.v, m.mass, m.free_masses)
            else:
                self._kinetic = obs.kinetic_tensor(self.state, self.model)
        return self._kinetic

    @property
    def translational_energy(self) -> float:
        """Kinetic energy of the centres of mass and point particles (eV)."""
        K = self.kinetic_tensor
        return 0.5 * float(K[0, 0] + K[1, 1] + K[2, 2])  # the trace, summed in its order

    @property
    def rotational_energy(self) -> float:
        """Rotational kinetic energy of the bodies (eV)."""
        if self._rotational is None:
            if self.compiled:
                s = self.state
                self._rotational = _numba.rotational_energy(s.q, s.p, self.model.inv_moments)
            else:
                self._rotational = obs.rotational_kinetic_energy(self.state, self.model)
        return self._rotational

    # ------------------------------------------------------------ what changed
    def cell_changed(self) -> None:
        """The cell moved: the volume is asked again."""
        self._volume = None

    def velocities_changed(self) -> None:
        """Velocities or angular momenta changed in a way the record cannot follow."""
        self._kinetic = None
        self._rotational = None

    def scale_translation(self, factor) -> None:
        """Every translational velocity was multiplied by ``factor`` (a number or a 3x3 matrix).

        A matrix acts on each velocity as :math:`V \\leftarrow F V`; the kinetic
        tensor becomes :math:`F K F^\\mathsf{T}` (a number: :math:`s^2 K`) without a
        new sum over bodies.
        """
        K = self._kinetic
        if K is None:
            return
        if isinstance(factor, np.ndarray) and factor.ndim == 2:
            self._kinetic = (_numba.congruence(factor, K) if self.compiled
                             else factor @ K @ factor.T)
        else:
            self._kinetic = K * float(factor) ** 2

    def scale_translation_about(self, factor: float, centre: np.ndarray, mass: float) -> None:
        r"""Every translational velocity became :math:`U + s\,(V - U)`, :math:`U = P/M`.

        With :math:`\sum m (V - U) = 0` the kinetic tensor becomes
        :math:`M\,U\otimes U + s^2 (K - M\,U\otimes U)`: the centre of mass's part
        kept, the rest scaled, without a new sum over bodies.  ``centre`` is
        :math:`U` (Å / ASE time, shape (3,)), ``mass`` :math:`M` (amu), the total.
        """
        K = self._kinetic
        if K is None:
            return
        K_cm = mass * np.multiply.outer(centre, centre)
        self._kinetic = K_cm + float(factor) ** 2 * (K - K_cm)

    def scale_rotation(self, factor: float) -> None:
        """Every angular momentum was multiplied by ``factor``."""
        if self._rotational is not None:
            self._rotational = self._rotational * float(factor) ** 2

    def net_force(self) -> tuple[float, float]:
        """``(|sum of the forces|, sum of their magnitudes)`` of the last force call (eV/Å).

        Body forces and point-particle forces together: zero for forces that
        conserve the momentum, to roundoff.  One pass over the forces, on the
        link's backend.
        """
        if self.compiled:
            net, size = _numba.net_force(self.F, self.f)
            return float(net), float(size)
        net = float(np.linalg.norm(self.F.sum(axis=0) + self.f.sum(axis=0)))
        return net, float(np.abs(self.F).sum() + np.abs(self.f).sum())

    # ------------------------------------------------------------ rollback and checkpoints
    def get_state(self) -> dict:
        """Copies of everything the record holds (for a rollback or a checkpoint)."""
        return {"F": self.F.copy(), "tau": self.tau.copy(), "f": self.f.copy(),
                "r": self.r.copy(),
                "virial": None if self.virial is None else self.virial.copy(),
                "energy": self.energy, "scratch": dict(self.scratch),
                "volume": self._volume,
                "kinetic": None if self._kinetic is None else self._kinetic.copy(),
                "rotational": self._rotational}

    def set_state(self, saved: dict) -> None:
        """Restore what :meth:`get_state` returned; absent keys leave a quantity to recompute."""
        for name in _FORCE_FIELDS:
            if saved.get(name) is not None:
                setattr(self, name, np.array(saved[name], dtype=float))
        self.virial = None if saved.get("virial") is None else np.array(saved["virial"])
        self.energy = saved.get("energy")
        self.scratch = dict(saved.get("scratch", {}))
        self.cell_move = None
        volume, kinetic = saved.get("volume"), saved.get("kinetic")
        self._volume = None if volume is None else float(volume)
        self._kinetic = None if kinetic is None else np.array(kinetic, dtype=float)
        rotational = saved.get("rotational")
        self._rotational = None if rotational is None else float(rotational)

    def backup(self, copy: bool = True) -> tuple:
        """A token for :meth:`restore` within one step.

        ``copy=False`` keeps references only: enough when nothing that can fail
        comes after the arrays are written (the fused kernel writes them in place
        after the force call succeeded; a coupling part's second half comes after
        that, so the stepper copies when there are couplings).
        """
        if copy:
            return (self.F.copy(), self.tau.copy(), self.f.copy(), self.virial, self.energy,
                    self._volume, self._kinetic, self._rotational, dict(self.scratch))
        return (self.F, self.tau, self.f, self.virial, self.energy, self._volume,
                self._kinetic, self._rotational, self.scratch)

    def restore(self, token: tuple) -> None:
        """Put back what :meth:`backup` returned (a failed step)."""
        (self.F, self.tau, self.f, self.virial, self.energy, self._volume, self._kinetic,
         self._rotational, self.scratch) = token
        self.cell_move = None
