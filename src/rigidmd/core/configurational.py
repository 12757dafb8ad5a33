r"""Configurational temperatures of rigid bodies, translational and rotational.

The kinetic temperature says how fast the bodies move; the configurational
temperature says at which temperature their *positions* were sampled, from
the forces alone.  At a finite time step the two part (the step's error), so
comparing them measures it.  For rigid bodies (Chialvo, Cummings & Evans;
the rotational estimator is what Davidchack, Ouldridge & Tretyakov use to
test their quaternion Langevin schemes),

.. math::
    k_B T^\mathrm{conf}_\mathrm{tr} = \frac{\langle \sum_b |F_b|^2\rangle}
        {\langle \sum_b \nabla_{X_b}^2 U\rangle},\qquad
    k_B T^\mathrm{conf}_\mathrm{rot} = \frac{\langle \sum_b |\tau_b|^2\rangle}
        {\langle \sum_b \sum_a \mathcal{L}_{b,a}^2 U\rangle},

where :math:`\mathcal L_{b,a}` rotates body :math:`b` about the lab axis
:math:`a` through its centre of mass.  These are invariant vector fields on
SO(3): the Haar measure (the orientations' measure in the Boltzmann
distribution of rigid bodies) is invariant under them, so the integration by
parts that gives the Cartesian estimator holds for them too, and
:math:`\tau_{b,a} = -\mathcal L_{b,a} U`.  Point particles (atoms in no body)
count with the bodies' centres in the translational sums.

Calculators give forces, not their derivatives, so the Laplacians come from
Hutchinson's trace estimator (:func:`hutchinson_laplacians`): random ±1
vectors :math:`w` over all generalised coordinates, the forces and torques
at the configurations displaced by :math:`\pm\epsilon w` (centres moved by
:math:`\epsilon_\mathrm{tr} w`, bodies turned by :math:`\epsilon_\mathrm{rot} w`
about lab axes), :math:`-w\cdot(G(+) - G(-))/2\epsilon`, averaged over the
probes.  Each probe costs **two force calls**; a sample of ``probes`` probes
costs ``2 * probes`` calls (8 by default), one more when the calculator's
results are not those of the current positions.

What the displacement changes, measured on 64 TIP3P waters at 300 K
(``validation/configurational_eps.py``, the same vectors at every ε, relative
to ε = 1e-3): the central difference's bias grows as :math:`\epsilon^2`:
1.1e-3 (translation) and 9e-5 (rotation) at ε = 5e-3 Å and rad, 1.1e-2 and
1.4e-3 at 2e-2, 6e-2 and 8e-3 at 5e-2; rounding takes over below 1e-4 (3e-4
and 2e-5 at 1e-4).  The defaults, 2e-3 Å and 5e-3 rad, keep both below 2e-4
(0.06 K at 300 K; at 2e-3 Å by the ε² scaling).  What dominates a sample's noise is the probes' own
variance (the off-diagonal second derivatives, which average to zero): one
probe's value scatters by 13 % (translation) and 9 % (rotation) of the mean
for 64 waters, independently of ε; it falls as one over the number of probes
and samples, like any other fluctuation.

:class:`ConfigurationalTemperature` is the observer a dynamics runs
periodically (``dyn.attach(tconf, interval=100)``).  It does not disturb the
trajectory: the displaced configurations are evaluated on a copy of the
Atoms, and the calculator's results (and cached atoms) are put back after
each sample, so the run with and without it is the same bit for bit; an
engine with state of its own (LAMMPS) needs a calculator of its own for that
(the ``calculator`` argument).
"""

import numpy as np
from ase import units

from rigidmd.core import operators as ops
from rigidmd.core import quaternion as quat

__all__ = ["ConfigurationalTemperature", "hutchinson_laplacians", "block_mean",
           "block_ratio", "rotation_quaternions", "EPS_TRANSLATION", "EPS_ROTATION", "PROBES"]

#: Default displacement of the centres (Å) and of the orientations (rad) in the estimator.
EPS_TRANSLATION, EPS_ROTATION = 2e-3, 5e-3
#: Default number of Hutchinson probes per sample (two force calls each).
PROBES = 4


def hutchinson_laplacians(displaced, n_translational: int, n_rotational: int, rng,
                          probes: int = PROBES, eps_translation: float = EPS_TRANSLATION,
                          eps_rotation: float = EPS_ROTATION) -> tuple[float, float]:
    r"""Hutchinson estimates of :math:`\sum\nabla^2 U` (translation) and :math:`\sum\mathcal L^2U`.

    Parameters
    ----------
    displaced : callable
        ``displaced(dX, rotvec) -> (F, tau)``: the translational forces
        (shape ``(n_translational, 3)``) and lab torques (``(n_rotational, 3)``)
        with every centre moved by ``dX`` and every body turned by the lab
        rotation vector ``rotvec`` (its angle in rad) about its centre.
        Any units: the results are in the units of ``F / dX`` and ``tau / rotvec``.
    n_translational, n_rotational : int
        Centres (and point particles), bodies.
    rng : numpy.random.Generator
        Draws the ±1 vectors (per probe: translation, then rotation).
    probes : int
        Random vectors; each costs two calls of ``displaced``.
    eps_translation, eps_rotation : float
        Displacements of the central differences.

    Returns
    -------
    lap_translation, lap_rotation : float
        Unbiased (up to :math:`O(\epsilon^2)`) estimates of the two sums of
        second derivatives.
    """
    lap_t = lap_r = 0.0
    for _ in range(probes):
        wt = rng.choice((-1.0, 1.0), size=(n_translational, 3))
        wr = rng.choice((-1.0, 1.0), size=(n_rotational, 3))
        Fp, tp = displaced(eps_translation * wt, eps_rotation * wr)
        Fm, tm = displaced(-eps_translation * wt, -eps_rotation * wr)
        lap_t -= float(np.sum(wt * (Fp - Fm))) / (2 * eps_translation * probes)
        lap_r -= float(np.sum(wr * (tp - tm))) / (2 * eps_rotation * probes)
    return lap_t, lap_r


def rotation_quaternions(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` of lab rotation vectors (angle in rad), shape (n, 4)."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1)
    # sin(θ/2)/θ, finite at θ = 0 (np.sinc(x) = sin(πx)/(πx))
    half = 0.5 * np.sinc(angle / (2 * np.pi))
    return np.concatenate([np.cos(0.5 * angle)[..., None], half[..., None] * rotvec], axis=-1)


def block_mean(values, blocks: int = 5) -> tuple[float, float]:
    """Mean of a series and its standard error from ``blocks`` consecutive block means.

    The error is NaN with fewer than two blocks' worth of values.
    """
    values = np.asarray(values, dtype=float)
    if len(values) < blocks or blocks < 2:
        return (float(values.mean()) if len(values) else np.nan), np.nan
    means = np.array([part.mean() for part in np.array_split(values, blocks)])
    return float(values.mean()), float(means.std(ddof=1) / np.sqrt(blocks))


def block_ratio(numerator, denominator, blocks: int = 5) -> tuple[float, float]:
    """:math:`\\langle a\\rangle/\\langle b\\rangle` of paired series and its jackknife error
    over ``blocks`` consecutive blocks (NaN error with too few values)."""
    a, b = np.asarray(numerator, dtype=float), np.asarray(denominator, dtype=float)
    if not len(a) or b.sum() == 0:
        return np.nan, np.nan
    value = float(a.sum() / b.sum())
    if len(a) < blocks or blocks < 2:
        return value, np.nan
    parts = np.array_split(np.arange(len(a)), blocks)
    leave = np.array([(a.sum() - a[p].sum()) / (b.sum() - b[p].sum()) for p in parts])
    error = np.sqrt((blocks - 1) / blocks * np.sum((leave - leave.mean()) ** 2))
    return value, float(error)


class ConfigurationalTemperature:
    r"""Periodic translational and rotational configurational temperatures of a dynamics.

    An ASE observer: ``dyn.attach(ConfigurationalTemperature(dyn), interval=100)``
    takes a sample every 100 steps.  **Cost: ``2 * probes`` force calls per
    sample** (8 with the default 4 probes; one more when the calculator's
    results are not those of the current positions), so every 100 steps costs
    8 % more force calls.  The trajectory is not disturbed (see
    :mod:`rigidmd.core.configurational`); its own random numbers come from
    ``rng``, never from the dynamics'.

    Parameters
    ----------
    dyn : rigidmd.RigidDynamics
        The dynamics sampled (its state, model, forces and calculator).
    probes : int, default 4
        Hutchinson vectors per sample (two force calls each).
    eps_translation : float, default 2e-3
        Displacement of the centres (Å).
    eps_rotation : float, default 5e-3
        Rotation of the bodies (rad).
    rng : numpy.random.Generator, int or tuple of int, optional
        The probes' random numbers.  A seed (default 0; a tuple of whole
        numbers is one seed too): each sample draws from
        ``numpy.random.default_rng((*seed, step))``, so its probes depend on
        the seed and the dynamics' step alone, and a run continued from a
        checkpoint takes the samples an uninterrupted one takes at the same
        steps.  A generator (anything with numpy's ``choice``): the samples
        draw from it in turn.
    blocks : int, default 5
        Blocks of the jackknife error in :attr:`results` (at least 2).
    calculator : ase.calculators.calculator.Calculator, optional
        Evaluates the displaced configurations (default: the dynamics' own,
        whose results and cached atoms are put back after each sample).  An
        engine with state of its own beyond its results (LAMMPS keeps its
        neighbour lists and the positions it was sent) then continues from the
        displaced positions, and the trajectory may part from the unobserved
        one by rounding (3e-14 Å after 100 steps for 27 waters with LAMMPS in
        process); a calculator of its own, of the same interactions, keeps it
        bit for bit.

    Attributes
    ----------
    results : dict
        The running estimates: ``"T_conf_tr"``, ``"T_conf_rot"`` (K) and their
        errors ``"T_conf_tr_err"``, ``"T_conf_rot_err"`` (jackknife over
        ``blocks`` consecutive blocks of samples; NaN with fewer samples),
        ``"samples"`` and ``"force_calls"``.
    sums : list of tuple
        Per sample: :math:`\sum|F|^2` (eV²/Å²), :math:`\sum\nabla^2U` (eV/Å²),
        :math:`\sum|\tau|^2` (eV²), :math:`\sum\mathcal L^2U` (eV), and the step.
    """

    modifies_atoms = False  # the displaced configurations live on a copy of the Atoms
    wants_properties = False  # it reads the step's forces, never its energy or stress

    def __init__(self, dyn, probes: int = PROBES, eps_translation: float = EPS_TRANSLATION,
                 eps_rotation: float = EPS_ROTATION, rng=None, blocks: int = 5,
                 calculator=None):
        if isinstance(probes, bool) or not isinstance(probes, (int, np.integer)) or probes < 1:
            raise ValueError(f"ConfigurationalTemperature: probes must be a whole number >= 1, "
                             f"got {probes!r}")
        for name, value in (("eps_translation", eps_translation),
                            ("eps_rotation", eps_rotation)):
            if isinstance(value, bool) or not (isinstance(value, (int, float, np.floating))
                                               and np.isfinite(value) and value > 0):
                raise ValueError(f"ConfigurationalTemperature: {name} must be a positive "
                                 f"number, got {value!r}")
        if eps_rotation > 0.1:
            raise ValueError(f"ConfigurationalTemperature: eps_rotation {eps_rotation!r} rad "
                             "is not small; the central difference needs < 0.1 rad")
        for name in ("state", "model", "record", "atoms"):
            if not hasattr(dyn, name):
                raise TypeError(f"ConfigurationalTemperature needs a rigidmd dynamics, got "
                                f"{type(dyn).__name__}")
        if isinstance(blocks, bool) or not isinstance(blocks, (int, np.integer)) or blocks < 2:
            raise ValueError(f"ConfigurationalTemperature: blocks must be a whole number >= 2 "
                             f"(the jackknife's blocks), got {blocks!r}")
        self.dyn = dyn
        self.probes, self.blocks = int(probes), int(blocks)
        self.eps_translation, self.eps_rotation = float(eps_translation), float(eps_rotation)
        # A generator (anything with numpy's ``choice``), or a seed of each sample's own.
        if hasattr(rng, "choice"):
            self.rng, self.seed = rng, None
        else:
            seed = (0,) if rng is None else tuple(rng) if isinstance(rng, (tuple, list)) \
                else (rng,)
            if not seed or any(isinstance(v, bool) or not isinstance(v, (int, np.integer))
                               or v < 0 for v in seed):
                raise ValueError(f"ConfigurationalTemperature: rng must be a numpy Generator "
                                 f"or a seed (a whole number >= 0, or a tuple of them), got "
                                 f"{rng!r}")
            self.rng, self.seed = None, tuple(int(v) for v in seed)
        self.sums = []
        self.force_calls = 0
        #: The calculator of the displaced configurations (None: the dynamics').
        self.calculator = calculator

    def __call__(self) -> None:
        self.sample()

    # ------------------------------------------------------------ one sample
    def sample(self) -> tuple:
        """Take one sample at the dynamics' current positions; returns its sums."""
        dyn = self.dyn
        state, model, atoms = dyn.state, dyn.model, dyn.atoms
        calc = atoms.calc if self.calculator is None else self.calculator
        saved = _save_calculator(calc)
        probe = atoms.copy()
        probe.constraints = []
        probe.calc = calc
        r0 = quat.rotate(state.q[model.atom_body], model.body_coordinates)
        base = probe.positions

        def forces_at(X, q, x):
            r = quat.rotate(q[model.atom_body], model.body_coordinates)
            positions = base.copy()
            positions[model.order] = X[model.atom_body] + r
            positions[model.free] = x
            probe.positions = positions
            forces = np.asarray(calc.get_forces(probe), dtype=float)
            self.force_calls += 1
            if not np.isfinite(forces.sum()):
                raise ValueError(f"ConfigurationalTemperature: the calculator returned "
                                 f"non-finite forces at a configuration displaced by "
                                 f"{self.eps_translation:g} Å and {self.eps_rotation:g} rad "
                                 f"after step {dyn.nsteps} (the arguments eps_translation and "
                                 f"eps_rotation set them)")
            return forces, r

        nb = model.n_bodies
        try:
            current = _current_forces(atoms.calc, atoms)  # the step's own, if current
            if current is None:
                current, r = forces_at(state.X, state.q, state.x)
            else:
                r = r0
            F, tau = ops.reduce_forces(current, r, model)
            F = np.concatenate([F, current[model.free]])

            def displaced(dT, rotvec):
                q = quat.multiply(rotation_quaternions(rotvec), state.q)
                forces, r = forces_at(state.X + dT[:nb], q, state.x + dT[nb:])
                Fd, taud = ops.reduce_forces(forces, r, model)
                return np.concatenate([Fd, forces[model.free]]), taud

            rng = self.rng if self.seed is None else np.random.default_rng(
                (*self.seed, int(dyn.nsteps)))
            lap_t, lap_r = hutchinson_laplacians(
                displaced, nb + model.n_free, nb, rng, self.probes,
                self.eps_translation, self.eps_rotation)
        finally:
            _restore_calculator(calc, saved)
        sums = (float(np.sum(F * F)), lap_t, float(np.sum(tau * tau)), lap_r, int(dyn.nsteps))
        self.sums.append(sums)
        return sums

    # ------------------------------------------------------------ the estimates
    @property
    def results(self) -> dict:
        """The running estimates (K), their errors, the samples and force calls made."""
        data = np.array([s[:4] for s in self.sums]).reshape(-1, 4)
        tr, tr_err = block_ratio(data[:, 0], data[:, 1], self.blocks)
        rot, rot_err = block_ratio(data[:, 2], data[:, 3], self.blocks)
        kelvin = 1.0 / units.kB
        return {"T_conf_tr": tr * kelvin, "T_conf_tr_err": tr_err * kelvin,
                "T_conf_rot": rot * kelvin, "T_conf_rot_err": rot_err * kelvin,
                "samples": len(self.sums), "force_calls": self.force_calls}

    def report(self) -> str:
        """One line: the estimates with their errors, samples and force calls."""
        res = self.results

        def text(name):
            err = res[f"{name}_err"]
            return f"{res[name]:.1f}" + ("" if np.isnan(err) else f" ± {err:.1f}")

        return (f"configurational temperature: translational {text('T_conf_tr')} K, "
                f"rotational {text('T_conf_rot')} K ({res['samples']} samples, "
                f"{res['force_calls']} extra force calls)")


def _current_forces(calc, atoms):
    """The calculator's forces when its results are those of ``atoms`` as they are, else None."""
    check = getattr(calc, "check_state", None)
    results = getattr(calc, "results", None)
    if check is None or not isinstance(results, dict) or "forces" not in results:
        return None
    if getattr(calc, "atoms", None) is None or check(atoms):
        return None
    forces = np.array(results["forces"], dtype=float)
    return forces if forces.shape == (len(atoms), 3) else None


def _save_calculator(calc):
    """The calculator's results (arrays copied) and cached atoms, to put back."""
    results = getattr(calc, "results", None)
    if isinstance(results, dict):
        results = {key: (value.copy() if isinstance(value, np.ndarray) else value)
                   for key, value in results.items()}
    return results, getattr(calc, "atoms", None)


def _restore_calculator(calc, saved) -> None:
    results, cached = saved
    if results is not None:
        calc.results = results
    if hasattr(calc, "atoms"):
        calc.atoms = cached
