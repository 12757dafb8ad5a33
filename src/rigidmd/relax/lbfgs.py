r"""The default optimizer of :func:`rigidmd.relax.filter.relax`: preconditioned limited-memory BFGS.

:class:`RigidLBFGS` is L-BFGS (Nocedal & Wright, *Numerical Optimization*,
2nd ed., algorithm 7.4) whose initial inverse Hessian is the inverse of a
preconditioner (by default :class:`rigidmd.relax.precon.RigidPrecon`),
scaled at every step by :math:`\gamma_k = s^\mathsf{T}y / y^\mathsf{T}P^{-1}y`
(their eq. 7.20, in the metric of :math:`P`), so that no ``alpha`` needs
tuning: the curvature comes from the preconditioner's estimate (one force
call at the start) and then from the steps themselves.

Each step costs one force call.  A step that raises the energy is halved
(from the last accepted point, at most :data:`MAX_HALVINGS` times) and the
memory is cleared; every step is capped at ``maxstep`` (Å, the largest row,
as ASE's ``LBFGS``).  Memory and time per step are O(n) (``memory`` pairs of
vectors, a sparse preconditioner solved once per step for both vectors it
is applied to), and every sum is a compiled loop in a fixed order
(:mod:`rigidmd.relax._numba`) rather than a BLAS dot product, so that the
path does not depend on the number of BLAS threads.
"""

import time

import numpy as np
from ase.optimize.optimize import Optimizer

from rigidmd.relax import _numba
from rigidmd.relax.optimizerstate import split
from rigidmd.relax.precon import RigidPrecon

__all__ = ["RigidLBFGS", "MAX_HALVINGS", "SCALE_TOLERANCE"]

#: Halvings of a step that raised the energy before it is accepted anyway.
MAX_HALVINGS = 8

#: Relative residual of the solve for :math:`P^{-1}y`, whose only use is the scalar
#: :math:`y^\mathsf{T}P^{-1}y` of the scale :math:`\gamma_k` (the error of a quadratic form
#: falls faster than the residual: 5e-4 relative at 3e-2 in 3 iterations, as at 1e-2 in 6,
#: 6e-2 at 1e-1 in 1; 1728 waters).  Once it is reached, the conjugate gradients go on
#: with the other vector's three columns only (0.64-0.67 against 0.69-0.74 ms CPU a step
#: at 1728 waters).  Force calls of relax()'s defaults to fmax 0.05 / 0.01 eV/Å summed over
#: the 21 systems of :data:`rigidmd.relax.precon.CG_TOLERANCE`: 979 / 1824 at 3e-2, 968 /
#: 1882 at 1e-2 (that is, at CG_TOLERANCE), 966 / 1914 at 1e-1 (``benchmarks/relax.txt``).
SCALE_TOLERANCE = 3e-2


def _dot(a, b):
    """:math:`a \\cdot b` in a fixed order (:func:`rigidmd.relax._numba.dot`; no BLAS)."""
    return float(_numba.dot(a, b))


class RigidLBFGS(Optimizer):
    """Preconditioned L-BFGS with a scaled initial Hessian (see the module docstring).

    Parameters
    ----------
    atoms : rigidmd.relax.filter.RigidFilter
        Or any ASE optimizable when ``precon`` is None (then the initial
        inverse Hessian is the identity times :math:`\\gamma_k`).
    restart, logfile, trajectory, append_trajectory :
        As for every ASE optimizer.
    maxstep : float, default 0.2
        Largest displacement of one row in one step (Å).
    memory : int, default 20
        Pairs of steps remembered.
    precon : RigidPrecon, None or "auto", default "auto"
        ``"auto"``: a new :class:`~rigidmd.relax.precon.RigidPrecon`.
    **kwargs
        Further arguments of :class:`ase.optimize.optimize.Optimizer`.
    """

    defaults = {**Optimizer.defaults, "maxstep": 0.2}

    def __init__(self, atoms, restart=None, logfile="-", trajectory=None, maxstep=None,
                 memory=20, precon="auto", **kwargs):
        if maxstep is None:
            maxstep = self.defaults["maxstep"]
        if not (np.isfinite(maxstep) and maxstep > 0):
            raise ValueError(f"RigidLBFGS: maxstep={maxstep!r} Å must be positive")
        if int(memory) != memory or memory < 1:
            raise ValueError(f"RigidLBFGS: memory={memory!r} must be a whole number >= 1")
        self.maxstep = float(maxstep)
        self.memory = int(memory)
        self.precon = RigidPrecon() if isinstance(precon, str) and precon == "auto" else precon
        self._target = atoms
        self._anchored = 0
        self._quiet = logfile is None
        super().__init__(atoms, restart=restart, logfile=logfile, trajectory=trajectory,
                         **kwargs)

    def initialize(self):
        self.s, self.y, self.rho = [], [], []
        self.x0 = self.g0 = self.e0 = None
        self.halvings = 0
        self._anchored = getattr(self._target, "reanchored", 0)

    def read(self):
        (self.s, self.y, self.rho, self.x0, self.g0, self.e0,
         self.halvings) = self.load()

    def todict(self):
        d = super().todict()
        d.update(maxstep=self.maxstep, memory=self.memory)
        return d

    def _solve(self, *vectors, tolerances=None):
        """:math:`P^{-1} v` for each of ``vectors`` (one solve for all with a RigidPrecon,
        each to its relative residual in ``tolerances``, None: the preconditioner's own)."""
        if self.precon is None:
            return [v.copy() for v in vectors]
        self.precon.make_precon(self._target)
        if isinstance(self.precon, RigidPrecon):
            return list(self.precon.solve(np.stack(vectors), tolerances))
        return [self.precon.solve(v) for v in vectors]

    def step(self, forces=None):
        """One step: accept (or halve) the last one, update the memory, move."""
        opt = self.optimizable
        x = opt.get_x()
        g = opt.get_gradient() if forces is None else -np.asarray(forces).ravel()
        e = opt.get_value()
        anchored = getattr(self._target, "reanchored", 0)
        if anchored != self._anchored:  # rows of re-anchored bodies jumped: a fresh start
            self._anchored = anchored
            self.s, self.y, self.rho = [], [], []
            self.x0 = None
        if self.x0 is not None and e > self.e0 and self.halvings < MAX_HALVINGS:
            # The energy went up: back to half the step, forget the curvature pairs.
            self.halvings += 1
            self.s, self.y, self.rho = [], [], []
            opt.set_x(self.x0 + 0.5 * (x - self.x0))
            self.dump(self._state())
            return
        if self.x0 is not None:
            s, y = x - self.x0, g - self.g0
            sy = _dot(s, y)
            if sy > 1e-12 * np.sqrt(_dot(s, s) * _dot(y, y)):  # curvature condition
                self.s.append(s)
                self.y.append(y)
                self.rho.append(1.0 / sy)
                if len(self.s) > self.memory:
                    del self.s[0], self.y[0], self.rho[0]
        self.halvings = 0
        q = g.copy()
        a = np.empty(len(self.s))
        for i in range(len(self.s) - 1, -1, -1):
            a[i] = self.rho[i] * _dot(self.s[i], q)
            _numba.axpy(-a[i], self.y[i], q)
        if self.s:
            z, Hy = self._solve(q, self.y[-1], tolerances=(None, SCALE_TOLERANCE))
            z *= _dot(self.s[-1], self.y[-1]) / _dot(self.y[-1], Hy)
        else:
            (z,) = self._solve(q)
        for i in range(len(self.s)):
            b = self.rho[i] * _dot(self.y[i], z)
            _numba.axpy(a[i] - b, self.s[i], z)
        dx = -z.reshape(-1, 3)
        longest = np.sqrt(np.sum(dx * dx, axis=1)).max() if len(dx) else 0.0
        if longest > self.maxstep:
            dx *= self.maxstep / longest
        self.x0, self.g0, self.e0 = x, g, e
        opt.set_x(x + dx.ravel())
        self.dump(self._state())

    def get_state(self):
        """Everything the next step depends on, as a dict of arrays (and the preconditioner's,
        under ``precon.``): :func:`rigidmd.relax.filter.relax` writes it when a relaxation
        stops early, so that a continued one takes the steps an uninterrupted one would."""
        n = 3 * len(self._target) if self.x0 is None else len(self.x0)
        state = {"s": np.array(self.s).reshape(-1, n), "y": np.array(self.y).reshape(-1, n),
                 "rho": np.array(self.rho, dtype=float), "halvings": np.array(self.halvings),
                 "anchored": np.array(self._anchored), "memory": np.array(self.memory),
                 "maxstep": np.array(self.maxstep)}
        if self.x0 is not None:
            state.update(x0=self.x0, g0=self.g0, e0=np.array(self.e0))
        if isinstance(self.precon, RigidPrecon):
            state.update({f"precon.{k}": v for k, v in self.precon.get_state().items()})
        return state

    def set_state(self, state):
        """Continue from :meth:`get_state` (on the view the state was taken from, restored).

        Raises
        ------
        ValueError
            A state of another memory length or step size, or of other rows.
        """
        for name in ("memory", "maxstep"):
            if float(state[name]) != getattr(self, name):
                raise ValueError(f"RigidLBFGS: the state was taken with {name}="
                                 f"{state[name].item()!r}, this optimizer has "
                                 f"{getattr(self, name)!r}")
        n = 3 * len(self._target)
        if state["s"].shape[1:] != (n,) or ("x0" in state and len(state["x0"]) != n):
            raise ValueError(f"RigidLBFGS: the state holds vectors of {state['s'].shape[1]} "
                             f"components, this view {n}")
        self.s, self.y = [v.copy() for v in state["s"]], [v.copy() for v in state["y"]]
        self.rho = [float(v) for v in state["rho"]]
        self.halvings, self._anchored = int(state["halvings"]), int(state["anchored"])
        self.x0 = self.g0 = self.e0 = None
        if "x0" in state:
            self.x0, self.g0 = state["x0"].copy(), state["g0"].copy()
            self.e0 = float(state["e0"])
        if isinstance(self.precon, RigidPrecon):
            self.precon.set_state(split(state, "precon"), self._target)

    def log(self, gradient):
        """ASE's log line, when there is a log (ASE's own writes to ``os.devnull`` without
        one, forming the norm and the energy first: 0.1 ms a step at 1728 waters).

        Its ``fmax`` is the convergence test's: on a
        :class:`~rigidmd.relax.filter.RigidFilter` the largest of its
        :meth:`~rigidmd.relax.filter.RigidFilter.force_norms` (every torque as
        ``|τ|/ℓ``), not the rows' largest norm as ASE's log has it.
        """
        if self._quiet or self.logfile is None:
            return
        norms = getattr(self._target, "force_norms", None)
        if callable(norms):
            fmax = float(norms().max()) if len(self._target) else 0.0
        else:
            fmax = self.optimizable.gradient_norm(gradient)
        e = self.optimizable.get_value()
        T = time.localtime()
        name = self.__class__.__name__
        if self.nsteps == 0:  # ASE's format
            self.logfile.write(f"{' ' * len(name)}  {'Step':>4s} {'Time':>8s} "
                               f"{'Energy':>15s}  {'fmax':>12s}\n")
        self.logfile.write(f"{name}:  {self.nsteps:3d} {T[3]:02d}:{T[4]:02d}:{T[5]:02d} "
                           f"{e:15.6f} {fmax:15.6f}\n")

    def _state(self):
        return (self.s, self.y, self.rho, self.x0, self.g0, self.e0, self.halvings)
