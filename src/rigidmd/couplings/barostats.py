r"""Barostats as coupling parts: Martyna–Tobias–Klein (MTK) and stochastic cell rescaling.

Rigid molecules feel the pressure through their centres of mass: the
molecular pressure tensor is

.. math::
    \mathsf P = \frac{1}{V}\Big(\sum_b M_b V_b \otimes V_b + \sum_{free} m v\otimes v
        + \mathsf W_\mathrm{atom} - \sum_b \sum_{i\in b} d_i \otimes f_i\Big)

(the atomic virial less its intramolecular part; see
:meth:`rigidmd.core.dynamics.RigidDynamics.get_stress`).  Under a barostat the
centres of mass and the point particles move with the cell and the
orientations do not.  Both barostats here make the cell move inside the
integrator's drift, through :meth:`drift_matrices` (the matrices ``A, B, S``
of :func:`rigidmd.core.operators.affine_drift`), so they work with every
integrator scheme; their other work is done in the half steps around it.

``couple`` says which cell degrees of freedom move: ``"iso"`` (the volume,
shape kept), ``"aniso"`` (the three lengths along x, y, z) or ``"tri"``
(every symmetric strain: lengths and shears; the cell may leave LAMMPS's
lower-triangular form, which rigidmd's own LAMMPS calculator handles).
"""

import numpy as np
from ase import units

from rigidmd.core import observables as obs
from rigidmd.core.backend import register as register_operation
from rigidmd.core.bodies import check_bodies_fit
from rigidmd.core.checks import real_number
from rigidmd.couplings import _numba
from rigidmd.couplings._numpy import exprel, symmetric_exp
from rigidmd.couplings.base import (
    TEMPERATURE,
    Coupling,
    CouplingView,
    LammpsFix,
    NoseHooverChain,
    NotExportable,
    Parameter,
    TargetTemperature,
    check_positive_integer,
    check_rng,
    check_temperature,
    check_time,
    register,
    rng_state,
    set_rng_state,
)

__all__ = ["Barostat", "MTKBarostat", "CRescaleBarostat",
           "BarostatError", "COUPLE", "symmetric_exp", "exprel"]

#: Allowed values of ``couple`` and the number of cell degrees of freedom each moves.
COUPLE = {"iso": 1, "aniso": 3, "tri": 6}

#: Largest relative volume change accepted in one step.
MAX_VOLUME_CHANGE = 0.1

#: The drift's velocity map ``S`` of a barostat that does not scale in the drift (read-only).
_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False


class BarostatError(ValueError):
    """The barostat cannot go on (a volume jump, a collapsing cell); the step was undone."""


def check_couple(couple):
    if couple not in COUPLE:
        raise ValueError(f"couple must be one of {', '.join(COUPLE)}, got {couple!r}")
    return couple


def check_pressure(pressure_au):
    value = real_number("pressure_au", pressure_au, "a number (eV/Å³)")
    if not np.isfinite(value):
        raise ValueError(f"pressure_au must be finite, got {pressure_au!r}")
    # 1 bar is 6.2e-7 eV/Å³; above 1 eV/Å³ (1.6 Mbar) the unit is almost surely wrong.
    if abs(value) > 1.0:
        raise ValueError(
            f"pressure_au = {value:g} eV/Å³ is {value / units.GPa:g} GPa: pressure_au is in "
            f"eV/Å³ (1 bar = ase.units.bar = {units.bar:.4g} eV/Å³)")
    return value


PRESSURE = Parameter("pressure_au", "pressure", "pressure", example="1 bar")
COUPLING = Parameter("couple", "couple", "choice", required=False, default="iso",
                     choices=tuple(COUPLE))


class Barostat(TargetTemperature, Coupling):
    """Shared parts of the barostats: target pressure, cell checks, the molecular pressure."""

    section = "barostat"
    needs_stress = True
    moves_cell = True
    drift_moves_cell = True

    def __init__(self, temperature_K, pressure_au, couple):
        self._temperature_K = self.checked_temperature(temperature_K)
        self.pressure_au = check_pressure(pressure_au)
        self.couple = check_couple(couple)

    def checked_temperature(self, temperature_K) -> float:
        value = check_temperature(temperature_K)
        if value == 0:
            raise ValueError(f"temperature_K = 0: {self.zero_kelvin}")
        return value

    def check(self, atoms, model, dt):
        super().check(atoms, model, dt)
        if not atoms.pbc.all():
            raise ValueError(f"a barostat needs a periodic cell in all three directions; "
                             f"atoms.pbc is {atoms.pbc.tolist()}")
        if atoms.cell.volume <= 0:
            raise ValueError("a barostat needs a cell with a positive volume")
        calc = atoms.calc
        if calc is None:
            raise ValueError("a barostat needs a calculator (with stress) on the atoms")
        implemented = getattr(calc, "implemented_properties", ("stress",))
        if "stress" not in implemented:
            raise ValueError(
                f"a barostat needs the pressure, but the calculator {type(calc).__name__} "
                f"provides no stress (it implements {', '.join(implemented)}); use a "
                "calculator with stress, e.g. rigidmd.lammps.LAMMPSCalculator")
        if self.couple == "tri" and getattr(calc, "orthorhombic_only", False):
            raise ValueError(
                f"couple='tri' shears the cell, but the calculator {type(calc).__name__} needs "
                "an orthorhombic cell; use couple='aniso' or 'iso'")
        check_bodies_fit(model, atoms.cell.array, atoms.pbc, "use a larger cell")

    @staticmethod
    def pressure_tensor(view: CouplingView) -> np.ndarray:
        """Molecular pressure tensor (eV/Å³) at the current state, symmetric, shape (3, 3)."""
        record = view.record
        return -obs.stress_tensor(record.virial, record.kinetic_tensor, record.volume)

    def check_volume_change(self, A, det=None):
        """Refuse a step that changes the volume by more than 10 % (``det``: of ``A``, known)."""
        ratio = abs(np.linalg.det(A) if det is None else det)
        if not (abs(ratio - 1.0) <= MAX_VOLUME_CHANGE):
            raise BarostatError(
                f"{self.kind} barostat: the volume would change by {100 * (ratio - 1):+.1f}% "
                f"in one step (more than {100 * MAX_VOLUME_CHANGE:.0f}%); the step was undone. "
                "Start closer to the target density, or use a longer damping time or a "
                "smaller time step")

    def todict(self):
        return {"kind": self.kind, "temperature_K": self.temperature_K,
                "pressure_au": self.pressure_au, "couple": self.couple}


@register
class MTKBarostat(Barostat):
    r"""Martyna–Tobias–Klein barostat on the centres of mass, with its own Nosé–Hoover chain.

    The cell momentum :math:`p_g` (a symmetric 3x3 matrix, restricted by
    ``couple``) drives the centres of mass and point particles
    (:math:`N` of them, :math:`N_f = 3N` degrees of freedom):

    .. math::
        \dot X = V + \frac{p_g}{W} X,\qquad
        \dot P = F - \Big(\frac{p_g}{W} + \frac{\mathrm{Tr}\,p_g}{N_f W}\Big) P,\qquad
        \dot h = \frac{p_g}{W} h,\\
        \dot p_g = V(\mathsf P - P_0) + \frac{2K_t}{N_f}\mathbb 1,

    with :math:`W = (N + 1) k_B T \tau_p^2` per component (for ``"iso"``
    the mean of the diagonal, as ASE's ``IsotropicMTKNPT``).  Orientations and
    angular momenta are not coupled: the rotations are a separate canonical
    subsystem, thermostatted by the particle chains.  Per step, around the
    integrator's step (whose drift moves the cell), each half step
    propagates the barostat's chain, kicks :math:`p_g` with the current
    pressure and scales the translational momenta.  :meth:`energy` is
    :math:`\mathrm{Tr}(p_g^2)/2W + P_0 V` plus the chain's energy.

    Parameters
    ----------
    temperature_K : float
        K (the barostat's mass and chain).
    pressure_au : float
        External pressure (eV/Å³; ``1 * ase.units.bar`` for 1 bar).
    pdamp : float
        Barostat time constant :math:`\tau_p` (ASE time units); at least 10
        time steps (1000 is typical).
    couple : {"iso", "aniso", "tri"}
    pchain, ploop : int
        Length of the barostat's chain and its sub-steps.

    References
    ----------
    G. J. Martyna, D. J. Tobias and M. L. Klein, J. Chem. Phys. 101, 4177 (1994);
    G. J. Martyna, M. E. Tuckerman, D. J. Tobias and M. L. Klein, Mol. Phys. 87,
    1117 (1996); H. Kamberaj, R. J. Low and M. P. Neal, J. Chem. Phys. 122,
    224114 (2005).
    """

    kind = "mtk"
    zero_kelvin = "the MTK barostat's mass is (N+1) k_B T pdamp^2"
    parameters = (TEMPERATURE, PRESSURE, Parameter("pdamp", "pdamp", "time", example="1 ps"),
                  COUPLING,
                  Parameter("pchain", "pchain", "integer", required=False, default=3),
                  Parameter("ploop", "ploop", "integer", required=False, default=1))

    def __init__(self, temperature_K, pressure_au, pdamp, couple="iso", pchain=3, ploop=1):
        super().__init__(temperature_K, pressure_au, couple)
        self.pdamp = check_time("pdamp", pdamp)
        self.pchain = check_positive_integer("pchain", pchain)
        self.ploop = check_positive_integer("ploop", ploop)
        self.p_g = np.zeros((3, 3))
        self.chain = NoseHooverChain(COUPLE[self.couple], self.pdamp, self.pchain, self.ploop)
        self._couple_code = _numba.COUPLE_CODES[self.couple]

    def check_timestep(self, dt):
        # Below about 10 steps per period the barostat's oscillation is not resolved.
        if self.pdamp < 10 * dt:
            raise ValueError(f"pdamp = {self.pdamp:g} is under 10 time steps ({10 * dt:g}): "
                             "the barostat cannot be integrated (1000 steps is typical)")

    def bind(self, view: CouplingView) -> None:
        super().bind(view)
        #: :math:`N_f`, the centres of mass' and point particles' degrees of freedom.
        self.n_f = view.model.translational_dof

    @property
    def W(self):
        """Barostat mass per cell component (eV · ASE time²)."""
        return (self.n_f / 3 + 1) * self.kT * self.pdamp**2

    def cell_kinetic_energy(self):
        r""":math:`\mathrm{Tr}(p_g^2)/2W` (eV)."""
        p = self.p_g.ravel()
        return float(p @ p) / (2 * self.W)

    # Each operator runs on the view's backend: its kernel (:mod:`._numba`) or the NumPy
    # reference of the same name (:mod:`._numpy`).
    def _thermostat(self, view, h):
        """The barostat's own chain over ``h``, driven by the cell's kinetic energy."""
        self.chain.act_on(self.p_g, self.W, self.kT, h, view.backend)

    def _kick(self, view, h):
        """:math:`p_g \\mathrel{+}= h\\,G` with the pressure at the current state."""
        record = view.record
        view.backend.mtk_kick(self.p_g, record.virial, record.kinetic_tensor, record.volume,
                              self.pressure_au, self.n_f, h, self._couple_code)

    def _scale_momenta(self, view, h):
        """The friction: :math:`V \\leftarrow e^{-\\kappa h} V`, and of the point particles."""
        s = view.state
        factor = view.backend.mtk_friction(s.data, len(s.X), len(s.x), self.p_g, self.W,
                                           self.n_f, h)
        view.record.scaled(factor)

    def first_half(self, view: CouplingView, h: float) -> None:
        self._thermostat(view, h)
        self._kick(view, h)
        self._scale_momenta(view, h)

    def second_half(self, view: CouplingView, h: float) -> None:
        self._scale_momenta(view, h)
        self._kick(view, h)
        self._thermostat(view, h)

    def drift_matrices(self, view: CouplingView, h: float) -> tuple:
        A, B, det = view.backend.symmetric_exp_det(self.p_g / self.W, h)
        self.check_volume_change(A, det)
        return A, B, _IDENTITY, None

    def energy(self, view: CouplingView) -> float:
        return (self.cell_kinetic_energy() + self.pressure_au * view.record.volume
                + self.chain.energy(self.kT))

    def get_state(self):
        return {"p_g": self.p_g.copy(), "chain": self.chain.get_state()}

    def set_state(self, state):
        self.p_g[...] = state["p_g"]
        self.chain.set_state(state["chain"])

    def lammps_fix(self, time_unit, seed=None):
        """The ``iso``/``aniso`` keyword of ``fix rigid/npt/small`` (pressure in bar)."""
        if self.couple == "tri":
            raise NotExportable("barostat.couple: LAMMPS's rigid barostats (fix rigid/npt) "
                                "handle orthogonal boxes only; couple 'tri' has no equivalent")
        if self.ploop != 1:
            raise NotExportable(f"barostat.ploop: LAMMPS's fix rigid/npt has no ploop (its "
                                f"barostat's chain is integrated once a step); export works "
                                f"with ploop 1, not {self.ploop}")
        bar = self.pressure_au / units.bar
        args = f"{self.couple} {bar!r} {bar!r} {self.pdamp / time_unit!r}"
        if self.pchain != 3:
            args += f" pchain {self.pchain}"
        return LammpsFix("npt", args)

    def todict(self):
        return super().todict() | {"pdamp": self.pdamp, "pchain": self.pchain,
                                   "ploop": self.ploop}


def _deviatoric_basis(couple):
    """Orthonormal (Frobenius) traceless symmetric matrices spanning ``couple``'s shape changes."""
    if couple == "iso":
        return np.zeros((0, 3, 3))
    basis = [np.diag([1.0, -1.0, 0.0]) / np.sqrt(2), np.diag([1.0, 1.0, -2.0]) / np.sqrt(6)]
    if couple == "tri":
        for i, j in ((0, 1), (0, 2), (1, 2)):
            E = np.zeros((3, 3))
            E[i, j] = E[j, i] = 1.0 / np.sqrt(2)
            basis.append(E)
    return np.array(basis)


@register
class CRescaleBarostat(Barostat):
    r"""Stochastic cell rescaling (Bernetti & Bussi 2020): a first-order barostat.

    The volume follows the overdamped Langevin equation of Bernetti and
    Bussi, integrated in :math:`\lambda = \sqrt V` where its noise is additive
    (their time-reversible "T" scheme):

    .. math::
        d\lambda = \frac{D}{k_BT} f_\lambda\,dt + \sqrt{2 D\,dt}\,\xi,\quad
        f_\lambda = 2\lambda\Big(P - P_0 + \frac{k_B T}{2V}\Big),\quad
        D = \frac{k_B T \beta_T}{4\tau_p},

    with :math:`P` the instantaneous molecular pressure and :math:`\beta_T`
    the compressibility.  For ``"aniso"`` and ``"tri"`` the shape moves too:
    each traceless strain component :math:`\eta_k` (an orthonormal basis of
    the shape changes ``couple`` allows) follows

    .. math::
        d\eta_k = \frac{\beta_T}{3\tau_p V} f_k\,dt
                  + \sqrt{\frac{2 k_BT \beta_T\,dt}{3\tau_p V}}\,\xi_k

    with :math:`f_k = V\langle \mathsf P, E_k\rangle`, the mobility of the
    isotropic strain.  The cell strain of one step,
    :math:`\mu = \exp(\tfrac13\Delta\varepsilon_V + \Delta\eta)`, is applied in
    the integrator's first drift of the step: centres of mass
    :math:`X \leftarrow \mu X + \tfrac{\Delta t}{2}(\mu + \mu^{-1}) V`, velocities
    :math:`V \leftarrow \mu^{-1} V`, cell :math:`h \leftarrow \mu h`.
    :meth:`energy` is :math:`P_0 V` plus the bookkeeping of the scheme, so
    that total energy plus the thermostat's and barostat's terms is an
    effective energy whose drift measures the integration error.

    Parameters
    ----------
    temperature_K : float
        K.
    pressure_au : float
        External pressure (eV/Å³).
    taup : float
        Relaxation time of the volume (ASE time units); at least 10 time steps.
    compressibility_au : float
        Isothermal compressibility :math:`\beta_T` (Å³/eV; water's 4.5e-5 /bar is
        ``4.5e-5 / ase.units.bar``).  It only sets the speed of the relaxation.
    couple : {"iso", "aniso", "tri"}
    rng : numpy.random.Generator, optional
    every : int, default 1
        Move the cell every ``every`` steps, by the move of ``every`` time
        steps (GROMACS's ``nstpcouple``; the reference implementation's
        ``nstbaro``).  A calculator for which a cell change is expensive (a
        LAMMPS set-up with PPPM) then pays it once in ``every`` steps; 10 is
        common, and fine while ``every`` time steps stay well below ``taup``.

    References
    ----------
    M. Bernetti and G. Bussi, J. Chem. Phys. 153, 114107 (2020).
    """

    kind = "crescale"
    zero_kelvin = ("stochastic cell rescaling's drift is D f / k_B T with D proportional to "
                   "k_B T: it has no 0 K limit; use the MTK barostat or a positive temperature")
    parameters = (TEMPERATURE, PRESSURE, Parameter("taup", "taup", "time", example="1 ps"),
                  Parameter("compressibility_au", "compressibility", "compressibility",
                            example="4.5e-5 1/bar"),
                  COUPLING, Parameter("rng", "seed", "seed", required=False),
                  Parameter("every", "every", "integer", required=False, default=1))

    def __init__(self, temperature_K, pressure_au, taup, compressibility_au, couple="iso",
                 rng=None, every=1):
        super().__init__(temperature_K, pressure_au, couple)
        self.every = check_positive_integer("every", every)
        self.taup = check_time("taup", taup)
        beta = real_number("compressibility_au", compressibility_au, "a number (Å³/eV)")
        if not (np.isfinite(beta) and beta > 0):
            raise ValueError(f"compressibility_au must be positive (Å³/eV), got "
                             f"{compressibility_au!r}")
        self.compressibility_au = beta
        self.rng = check_rng(rng)
        self.basis = _deviatoric_basis(self.couple)
        #: The scheme's bookkeeping (eV): P0 V + this is the barostat's energy term.
        self.work = 0.0
        self._noise = None  # this step's random numbers, drawn in the first half
        self._span = 0.0    # the time this step's move stands for (every * dt)

    def check_timestep(self, dt):
        if self.taup < 10 * self.every * dt:
            raise ValueError(f"taup = {self.taup:g} is under 10 moves of the cell "
                             f"({10 * self.every * dt:g}): the volume cannot relax smoothly "
                             "(1000 steps is typical)")

    def _forces(self, pressure, volume):
        """(f_λ, f_η): the forces on λ = √V and on the shape components."""
        mean = np.trace(pressure) / 3.0
        f_lambda = 2.0 * np.sqrt(volume) * (mean - self.pressure_au + 0.5 * self.kT / volume)
        f_eta = volume * np.einsum("kij,ij->k", self.basis, pressure)
        return f_lambda, f_eta

    def first_half(self, view: CouplingView, h: float) -> None:
        """Draw this step's noise when the cell moves this step (the drift only asks)."""
        self._noise = None
        if view.step % self.every == 0:
            self._span = self.every * (2.0 * h)  # the time the move stands for
            self._noise = (self.rng.standard_normal(),
                           self.rng.standard_normal(len(self.basis)))

    def drift_matrices(self, view: CouplingView, h: float) -> tuple:
        """The cell's move in the step's first drift, from this step's noise; changes nothing."""
        record = view.record
        if view.cell_note is not None or self._noise is None:  # moved already, or not now
            return _IDENTITY, h * _IDENTITY, _IDENTITY, None
        return view.backend.crescale_drift(self, view, record.volume, h)

    def _drift_reference(self, view, volume, h):
        """:meth:`drift_matrices` on the NumPy backend (the reference of the next)."""
        kT, dt = self.kT, self._span
        f_lambda, f_eta = self._forces(self.pressure_tensor(view), volume)
        d_lambda = 0.25 * kT * self.compressibility_au / self.taup
        d_eta = kT * self.compressibility_au / (3.0 * self.taup * volume)
        lam = np.sqrt(volume)
        xi_lambda, xi_eta = self._noise
        step_lambda = d_lambda / kT * f_lambda * dt + np.sqrt(2.0 * d_lambda * dt) * xi_lambda
        step_eta = d_eta / kT * f_eta * dt + np.sqrt(2.0 * d_eta * dt) * xi_eta
        if not step_lambda / lam > -1.0:
            raise BarostatError(f"{self.kind} barostat: the volume would collapse in one step; "
                                "the step was undone (use a longer taup)")
        strain = (2.0 / 3.0) * np.log1p(step_lambda / lam) * np.eye(3)
        strain += np.einsum("k,kij->ij", step_eta, self.basis)
        mu, _ = symmetric_exp(strain, 1.0)
        self.check_volume_change(mu)
        inverse = np.linalg.inv(mu)
        # Bookkeeping of the reversible scheme's first half, added in the second half.
        first = (0.5 * step_lambda * f_lambda
                 - 0.25 * d_lambda / kT * dt * f_lambda**2 + 0.5 * kT * np.log(volume)
                 + 0.5 * step_eta @ f_eta - 0.25 * d_eta / kT * dt * f_eta @ f_eta)
        state = view.state
        kinetic = state.V @ inverse.T, state.v @ inverse.T
        note = (step_lambda, step_eta, d_lambda, d_eta, kinetic, first)
        return mu, 0.5 * h * (mu + inverse), inverse, note

    def _drift_compiled(self, view, volume, h):
        """:meth:`drift_matrices` in one compiled call (:func:`._numba.crescale_move`)."""
        xi_lambda, xi_eta = self._noise
        record = view.record
        # The kinetic tensor is the record's (one sum per step; the kernel also gives it
        # as the drift leaves the velocities, S V with S = mu^-1).
        mu, B, inverse, det, step_lambda, step_eta, d_lambda, d_eta, first, kinetic = \
            _numba.crescale_move(record.virial, record.kinetic_tensor, volume,
                                   self.pressure_au, self.kT, self.compressibility_au,
                                   self.taup, self._span, xi_lambda, xi_eta, self.basis, h)
        if det == 0.0:
            raise BarostatError(f"{self.kind} barostat: the volume would collapse in one step; "
                                "the step was undone (use a longer taup)")
        self.check_volume_change(mu, det)
        note = (step_lambda, step_eta, d_lambda, d_eta, kinetic, first)
        return mu, B, inverse, note

    # The move as an operation of the backends: the kernel takes the kinetic tensor, the
    # reference the velocities, so the pair is a pair of methods (called with the part).
    register_operation("crescale_drift", _drift_reference, _drift_compiled)

    def second_half(self, view: CouplingView, h: float) -> None:
        if view.cell_note is None:
            return
        first = view.cell_note[5]
        self.work += first
        self.work += view.backend.crescale_bookkeeping(self, view)

    def _bookkeeping_reference(self, view):
        """The second half's work (eV) less the first half's, on the NumPy backend."""
        record = view.record
        step_lambda, step_eta, d_lambda, d_eta, kinetic, _ = view.cell_note
        kT, dt = self.kT, self._span
        volume = record.volume
        # The pressure right after the force call: the velocities as the drift left them.
        kinetic = obs.kinetic_tensor_of(*kinetic, view.model)
        pressure = record.virial / volume + kinetic / volume
        f_lambda, f_eta = self._forces(pressure, volume)
        return (0.5 * step_lambda * f_lambda
                + 0.25 * d_lambda / kT * dt * f_lambda**2 - 0.5 * kT * np.log(volume)
                + 0.5 * step_eta @ f_eta + 0.25 * d_eta / kT * dt * f_eta @ f_eta)

    def _bookkeeping_compiled(self, view):
        """:meth:`_bookkeeping_reference` in one compiled call (:func:`._numba.crescale_work`)."""
        record = view.record
        step_lambda, step_eta, d_lambda, d_eta, kinetic, _ = view.cell_note
        return _numba.crescale_work(record.virial, kinetic, record.volume, self.pressure_au,
                                    self.kT, self._span, self.basis, step_lambda, step_eta,
                                    d_lambda, d_eta)

    register_operation("crescale_bookkeeping", _bookkeeping_reference, _bookkeeping_compiled)

    def energy(self, view: CouplingView) -> float:
        return self.pressure_au * view.record.volume + self.work

    def get_state(self):
        return {"work": self.work, "rng": rng_state(self.rng)}

    def set_state(self, state):
        self.work = float(state["work"])
        set_rng_state(self.rng, state["rng"])
        self._noise = None

    def lammps_fix(self, time_unit, seed=None):
        raise NotExportable("barostat.kind: LAMMPS has no stochastic cell rescaling for rigid "
                            "bodies; use mtk (fix rigid/npt/small)")

    def todict(self):
        return super().todict() | {"taup": self.taup,
                                   "compressibility_au": self.compressibility_au,
                                   "every": self.every}
