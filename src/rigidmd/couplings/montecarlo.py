r"""A Monte Carlo barostat for rigid molecules: NPT with any calculator, energies only.

Every ``every`` steps :class:`MonteCarloBarostat` proposes a new cell
:math:`h'` (cell vectors as rows), moves the centres of mass :math:`X` of the
bodies and the point particles :math:`x` with it, keeping their fractional
coordinates (:math:`X' = X h^{-1} h'`) and every orientation, calls the
calculator once and accepts or rejects.  No stress is needed, so it works
with calculators that have none (ASE's ``TIP3P``/``TIP4P``, many
machine-learning wrappers) or an expensive one.

Ensemble and acceptance
-----------------------
For :math:`N` rigid molecules and point particles (:math:`N` = bodies + free
atoms) the isothermal–isobaric distribution of the cell and the centres in
fractional coordinates :math:`s = X h^{-1}` is, after integrating out momenta
and orientations (which the move does not touch),

.. math::
    \pi(h, s) \propto V^{N} e^{-\beta [U(h, s) + P_0 V]}\, d\mu(h)\, ds,

:math:`V = |\det h|`, where :math:`d\mu(h)` is the measure on the cell
degrees of freedom that ``couple`` lets move.  A move is a deterministic map
:math:`h \mapsto h' = T_\epsilon(h)` with :math:`\epsilon` drawn from a
symmetric density and :math:`T_{-\epsilon} = T_\epsilon^{-1}`; it is
accepted (Metropolis–Hastings) with probability
:math:`\min(1, e^{a})`,

.. math::
    a = -\beta\,[\Delta U + P_0 \Delta V] + N \ln\frac{V'}{V}
        + \ln\Big|\frac{\partial h'}{\partial h}\Big|_\mu ,

the last term being the Jacobian of the map in the measure :math:`\mu`.
The cells each ``couple`` moves, their measure and moves:

``"iso"``
    :math:`h = \lambda h_0`, :math:`d\mu = dV`.  Move in the logarithm of the
    volume, :math:`\ln V' = \ln V + \epsilon`: the Jacobian is
    :math:`dV'/dV = V'/V`, so :math:`a` carries :math:`(N+1)\ln(V'/V)`.
    (A move linear in the volume, :math:`V' = V + \epsilon`, has Jacobian 1
    and carries :math:`N\ln(V'/V)`, OpenMM's form; it can propose
    :math:`V' \le 0`.  The logarithmic move cannot, and its size is relative,
    so it needs no rescaling as the volume changes.)
``"aniso"``
    :math:`h = h_0\,\mathrm{diag}(\lambda_x, \lambda_y, \lambda_z)` (the three
    lengths of an orthorhombic cell), :math:`d\mu = d\lambda_x d\lambda_y
    d\lambda_z`.  Move one axis :math:`k`, chosen at random, in its logarithm,
    :math:`\ln\lambda_k' = \ln\lambda_k + \epsilon`: Jacobian
    :math:`\lambda_k'/\lambda_k = V'/V`, again :math:`(N+1)\ln(V'/V)`.
``"tri"``
    A lower-triangular cell (LAMMPS's form: :math:`a` along x, :math:`b` in
    the xy plane) with lengths :math:`a_x, b_y, c_z` and tilts
    :math:`b_x = t_1 a_x`, :math:`c_x = t_2 a_x`, :math:`c_y = t_3 b_y`;
    :math:`d\mu = da_x\, db_y\, dc_z\, dt_1 dt_2 dt_3`.  Six moves, chosen at
    random: the three lengths in their logarithm (scaling column :math:`k` of
    :math:`h` leaves the reduced tilts :math:`t` unchanged; Jacobian
    :math:`V'/V`) and the reduced tilts, :math:`t_j' = t_j + \epsilon`
    (Jacobian 1, volume unchanged).

So every move here is accepted with

.. math::
    a = -\beta\,[\Delta U + P_0 \Delta V] + (N + 1)\ln\frac{V'}{V}.

Exact results for an ideal gas (:math:`U = 0`): for ``"iso"``
:math:`V \sim \mathrm{Gamma}(N+1, k_BT/P_0)`, mean :math:`(N+1)k_BT/P_0`,
variance :math:`(N+1)(k_BT/P_0)^2`.  For ``"aniso"`` and ``"tri"`` the
density depends on the cell only through :math:`V` in the coordinates
:math:`(\ln\lambda, t)`, so the volume has the same Gamma distribution
whatever the shape, independently of it, and the shape (length ratios,
reduced tilts) has no restoring force: it performs an unbiased random walk
(zero mean increment).  These are the results the tests check, and a wrong
Jacobian (:math:`N` for :math:`N+1`) moves the mean volume by :math:`k_BT/P_0`.

Move sizes
----------
Each move kind has its own size :math:`\delta` (:math:`\epsilon` uniform in
:math:`[-\delta, \delta]`).  During the first ``adapt_moves`` attempts (the
equilibration window) every block of :data:`ADAPT_BLOCK` attempts of a kind
scales its :math:`\delta` by :data:`ADAPT_FACTOR` up (acceptance above 50 %)
or down (below 25 %).  After the window the sizes are frozen: the proposal
density is then fixed and symmetric, so the chain satisfies detailed balance
and samples the distribution above.  (A size that kept adapting to the
recent history would make the chain depend on its past and bias it.)
Samples from the window are equilibration and should be discarded.

Bodies that would span half the cell
------------------------------------
A trial cell in which a body would reach across half of the cell's smallest
width (twice the largest distance of a body's atom from its centre of mass,
against half the distance between opposite faces: the one rule of
:func:`rigidmd.core.bodies.body_too_wide`, as for the MD barostats and cell
relaxation) is rejected without
calling the calculator, as a move to infinite energy.  The minimum-image
reading of a body's atoms (by rigidmd and by most calculators) fails there;
treating it as a hard wall keeps detailed balance, whereas stopping the run
would end a valid simulation on one unlucky proposal.  A cell already like
that at the start is refused.

Cells the calculator cannot take
--------------------------------
Some calculators take only some cells: ASE's ``TIP3P`` and ``TIP4P`` need an
orthorhombic cell whose every length is at least twice their cut-off
``rc`` (:func:`calculator_cell_limits`).  A trial cell below that is
rejected in the same way, as a hard wall, without calling the calculator
(the NPT distribution is then sampled over the cells the calculator can
take; the log's ``MCwall`` column counts both kinds of wall).  What can
never work is refused at set-up, naming the cut-off: a start cell below
``2 rc``, a tilted cell, or ``couple="tri"`` with such a calculator.
"""

import numpy as np
from ase.calculators.tip3p import TIP3P

from rigidmd.core import observables as obs
from rigidmd.core.bodies import body_too_wide, cell_widths, check_bodies_fit
from rigidmd.couplings.barostats import COUPLING, PRESSURE, Barostat
from rigidmd.couplings.base import (
    TEMPERATURE,
    Coupling,
    CouplingView,
    NotExportable,
    Parameter,
    check_positive_integer,
    check_rng,
    register,
    rng_state,
    set_rng_state,
)

__all__ = ["MonteCarloBarostat", "n_move_kinds", "propose_cell",
           "log_acceptance", "log_jacobian", "metropolis", "adapt_step", "cell_widths",
           "body_span", "calculator_cell_limits", "ADAPT_BLOCK", "ADAPT_FACTOR",
           "TARGET_ACCEPTANCE", "LARGEST_STEP"]

#: Attempts of one move kind between two adjustments of its size.
ADAPT_BLOCK = 10
#: Factor by which a move size grows or shrinks at an adjustment.
ADAPT_FACTOR = 1.1
#: Acceptance window the sizes are adjusted toward.
TARGET_ACCEPTANCE = (0.25, 0.5)
#: Largest move size: a log-volume or log-length change of 0.5, a tilt change of 0.5.
LARGEST_STEP = 0.5


# ---------------------------------------------------------------- pure functions
def n_move_kinds(couple):
    """Number of move kinds of a ``couple`` mode: 1 (iso), 3 (aniso) or 6 (tri)."""
    return {"iso": 1, "aniso": 3, "tri": 6}[couple]


def propose_cell(cell, couple, kind, epsilon):
    r"""The trial cell of one move.

    Parameters
    ----------
    cell : numpy.ndarray, shape (3, 3)
        Cell vectors as rows (Å); lower-triangular for ``"tri"``.
    couple : {"iso", "aniso", "tri"}
    kind : int
        Which move: 0 for ``"iso"``; the axis 0-2 for ``"aniso"``; for
        ``"tri"`` 0-2 the lengths :math:`a_x, b_y, c_z` and 3-5 the reduced
        tilts :math:`t_1 = b_x/a_x`, :math:`t_2 = c_x/a_x`, :math:`t_3 = c_y/b_y`.
    epsilon : float
        The move: the change of :math:`\ln V` (iso), of the logarithm of a
        length (aniso, tri 0-2) or of a reduced tilt (tri 3-5).

    Returns
    -------
    numpy.ndarray, shape (3, 3)
    """
    cell = np.asarray(cell, dtype=float)
    if couple == "iso":
        return cell * np.exp(epsilon / 3.0)
    new = cell.copy()
    if kind < 3:  # scale column `kind`: that Cartesian axis
        new[:, kind] *= np.exp(epsilon)
        return new
    row, column, length = {3: (1, 0, (0, 0)), 4: (2, 0, (0, 0)), 5: (2, 1, (1, 1))}[kind]
    new[row, column] += epsilon * cell[length]
    return new


def log_jacobian(volume, new_volume):
    r"""Log-Jacobian :math:`\ln|\partial h'/\partial h|_\mu` of a move: :math:`\ln(V'/V)`.

    The log-volume and log-length moves have Jacobian :math:`V'/V`; the tilt
    moves 1, with :math:`V' = V` (see the module's derivation).
    """
    return float(np.log(new_volume / volume))


def log_acceptance(delta_energy, volume, new_volume, n, kT, pressure_au):
    r"""Logarithm of the Metropolis ratio of a cell move of :func:`propose_cell`.

    .. math::
        a = -\frac{\Delta U + P_0 (V' - V)}{k_BT} + N\ln\frac{V'}{V}
            + \ln\Big|\frac{\partial h'}{\partial h}\Big|

    Parameters
    ----------
    delta_energy : float
        :math:`U' - U` (eV); ``inf`` for a forbidden move.
    volume, new_volume : float
        Å³.
    n : int
        Bodies plus point particles.
    kT : float
        eV.
    pressure_au : float
        eV/Å³.

    Returns
    -------
    float
        ``-inf`` for a forbidden move or a non-positive trial volume.
    """
    if not new_volume > 0 or delta_energy == np.inf:
        return -np.inf
    return (-(delta_energy + pressure_au * (new_volume - volume)) / kT
            + n * np.log(new_volume / volume) + log_jacobian(volume, new_volume))


def metropolis(log_a, uniform):
    """Accept when ``uniform`` (in [0, 1)) is below :math:`e^a`."""
    return bool(log_a >= 0 or uniform < np.exp(log_a))


def adapt_step(step, accepted, attempted, low=TARGET_ACCEPTANCE[0], high=TARGET_ACCEPTANCE[1],
               factor=ADAPT_FACTOR, largest=LARGEST_STEP):
    """A move size adjusted for a block's acceptance ``accepted/attempted``.

    Smaller by ``factor`` below ``low``, larger by ``factor`` above ``high``
    (at most ``largest``), unchanged inside the window.
    """
    rate = accepted / attempted
    if rate < low:
        return step / factor
    if rate > high:
        return min(step * factor, largest)
    return step


def body_span(body_coordinates, starts):
    """Twice the largest distance of an atom from its body's centre of mass, per body (Å)."""
    if len(starts) == 0:
        return np.zeros(0)
    radius = np.linalg.norm(body_coordinates, axis=1)
    return 2.0 * np.maximum.reduceat(radius, starts)


def calculator_cell_limits(calc):
    """The cells a calculator takes: (orthorhombic only, smallest length or width in Å, name).

    ASE's ``TIP3P`` and ``TIP4P`` (and subclasses) assert an orthorhombic
    cell with every periodic length at least ``2 rc``; another calculator
    that takes only orthorhombic cells says so with ``orthorhombic_only =
    True`` (as :class:`rigidmd.lammps.LAMMPSCalculator` can).  Any other
    calculator takes any cell: ``(False, 0.0, name)``.
    """
    name = type(calc).__name__
    if isinstance(calc, TIP3P):
        return True, 2.0 * float(calc.rc), f"ASE's {name} (rc = {float(calc.rc):g} Å)"
    levels = getattr(calc, "levels", None)  # a MultipleTimeStep (or its full less fast)
    if levels:
        limits = [(calculator_cell_limits(level_calc), level) for level, level_calc in levels]
        (_, smallest, named), level = max(limits, key=lambda pair: pair[0][1])
        return (any(limit[0] for limit, _ in limits), smallest,
                f"{named}, the {level} level of {name}")
    return bool(getattr(calc, "orthorhombic_only", False)), 0.0, name


def _orthorhombic(cell):
    cell = np.asarray(cell)
    return bool(np.all(cell == np.diag(np.diag(cell))))


# ---------------------------------------------------------------- the coupling part
@register
class MonteCarloBarostat(Barostat):
    r"""Monte Carlo barostat for rigid molecules: volume (or shape) moves, energies only.

    See the module's documentation for the moves and the acceptance rule.
    Composes with every thermostat (the MD steps sample the canonical
    distribution at the current cell; the moves, every ``every`` steps,
    sample the cell).  Velocities, orientations and angular momenta are not
    changed by a move.  :meth:`energy` is minus the potential energy the
    accepted moves put in, so that the conserved energy still measures the
    integration error.

    The move is made in the part's first half step, through the dynamics'
    :class:`~rigidmd.couplings.base.CouplingView`: the old energy is the record's
    (:attr:`needs_energy` makes every force call compute it), the trial
    energy one call of ``view.evaluator.trial_energy``; a rejection puts the
    atoms and the calculator's results back (``restore_results``, no call),
    an acceptance copies the trial into the state and gives the next kick
    its forces (``evaluate``, which adopts the forces the trial call computed
    when the calculator computed them with the energy, as most do: then no
    call either).  The integrator's drift leaves the cell alone
    (:meth:`drift_matrices` is the identity).

    Parameters
    ----------
    temperature_K : float
        K.
    pressure_au : float
        External pressure (eV/Å³).
    couple : {"iso", "aniso", "tri"}, default "iso"
    every : int, default 25
        Attempt a move at the start of every ``every``-th step.
    rng : numpy.random.Generator, optional
    adapt_moves : int, default 500
        Attempts during which the move sizes adapt toward 25-50 % acceptance;
        frozen after (0: never adapt).
    step : float, default 0.01
        Initial move size of every kind (a log-volume change of 1 %).

    Attributes
    ----------
    steps : numpy.ndarray
        Current move size of each kind.
    attempted, accepted : numpy.ndarray of int
        Attempts and acceptances of each kind since the start.
    too_thin : int
        Moves rejected because a body would span half the trial cell.
    refused : int
        Moves rejected because the calculator cannot take the trial cell
        (:func:`calculator_cell_limits`: below ``2 rc`` for ASE's TIP3P/TIP4P).
    exchanged : float
        Potential energy the accepted moves put in (eV).

    References
    ----------
    I. R. McDonald, Mol. Phys. 23, 41 (1972); K.-H. Chow and D. M. Ferguson,
    Comput. Phys. Commun. 91, 283 (1995); J. Åqvist, P. Wennerström, M.
    Nervall, S. Bjelic and B. O. Brandsdal, Chem. Phys. Lett. 384, 288 (2004);
    D. Frenkel and B. Smit, *Understanding Molecular Simulation*, 2nd ed.,
    section 5.4.
    """

    drift_moves_cell = False  # the drift leaves the cell alone (drift_matrices)
    kind = "monte_carlo"
    zero_kelvin = "a Monte Carlo barostat needs a temperature"
    needs_stress = False
    needs_energy = True
    parameters = (TEMPERATURE, PRESSURE, COUPLING,
                  Parameter("every", "every", "integer", required=False, default=25),
                  Parameter("rng", "seed", "seed", required=False),
                  Parameter("adapt_moves", "adapt_moves", "integer", required=False,
                            default=500))
    log_columns = ("MCacc[%]", "MCwall")

    def __init__(self, temperature_K, pressure_au, couple="iso", every=25, rng=None,
                 adapt_moves=500, step=0.01):
        super().__init__(temperature_K, pressure_au, couple)
        self.every = check_positive_integer("every", every)
        if isinstance(adapt_moves, bool) or not isinstance(adapt_moves, (int, np.integer)) \
                or adapt_moves < 0:
            raise ValueError(f"adapt_moves must be a whole number >= 0, got {adapt_moves!r}")
        self.adapt_moves = int(adapt_moves)
        try:
            step = float(step)
        except (TypeError, ValueError):
            raise TypeError(f"step must be a number, got {step!r}") from None
        if not 0 < step <= LARGEST_STEP:
            raise ValueError(f"step must be in (0, {LARGEST_STEP}], got {step!r}")
        self.step = step
        self.rng = check_rng(rng)
        n = n_move_kinds(self.couple)
        self.steps = np.full(n, step)
        self.attempted = np.zeros(n, dtype=np.int64)
        self.accepted = np.zeros(n, dtype=np.int64)
        self.block = np.zeros((n, 2), dtype=np.int64)  # (accepted, attempted) in this block
        self.too_thin = 0
        self.refused = 0
        self.exchanged = 0.0
        self.n_particles = 0  # N of the acceptance rule, set by bind
        self._limits = (False, 0.0, "")  # the calculator's cell limits, set by check

    # -------------------------------------------------------------- set-up
    def check(self, atoms, model, dt):
        """A periodic cell with volume, a calculator, bodies under half the cell; no stress."""
        Coupling.check(self, atoms, model, dt)
        if not atoms.pbc.all():
            raise ValueError(f"a barostat needs a periodic cell in all three directions; "
                             f"atoms.pbc is {atoms.pbc.tolist()}")
        cell = atoms.cell.array
        if not abs(np.linalg.det(cell)) > 0:
            raise ValueError("a barostat needs a cell with a positive volume")
        if atoms.calc is None:
            raise ValueError("a barostat needs a calculator on the atoms")
        if self.couple == "tri" and np.abs(cell[[0, 0, 1], [1, 2, 2]]).max() > \
                1e-12 * np.abs(cell).max():
            raise ValueError("couple='tri' moves a lower-triangular cell (a along x, b in the xy "
                             "plane, as LAMMPS); rotate the system into that form first "
                             "(ase.cell.Cell.standard_form)")
        self._limits = orthorhombic, smallest, name = calculator_cell_limits(atoms.calc)
        if orthorhombic and self.couple == "tri":
            raise ValueError(
                f"couple='tri' shears the cell, but the calculator {name} takes only "
                "orthorhombic cells; use couple='aniso' or 'iso'")
        if orthorhombic and not _orthorhombic(cell):
            raise ValueError(f"the calculator {name} takes only orthorhombic cells, and this "
                             f"cell is not one ({cell.round(6).tolist()})")
        if smallest and self._refuses(cell):
            raise ValueError(
                f"the cell's lengths {np.diag(cell).round(4).tolist()} Å must be at least "
                f"{smallest:g} Å (twice the cut-off) for the calculator {name}; use a larger "
                "cell or a smaller rc")
        check_bodies_fit(model, cell, atoms.pbc, "use a larger cell")

    def bind(self, view: CouplingView) -> None:
        super().bind(view)
        model = view.model
        self.n_particles = int(model.n_bodies + model.n_free)

    # -------------------------------------------------------------- the step
    def first_half(self, view: CouplingView, h: float) -> None:
        """Attempt a move at the start of every ``every``-th step."""
        if view.step % self.every == 0:
            self.attempt(view)

    def second_half(self, view: CouplingView, h: float) -> None:
        """Nothing: the move was made in the first half."""

    def drift_matrices(self, view: CouplingView, h: float) -> tuple:
        """The integrator's drift leaves the cell alone: ``A = S = 1``, ``B = h``; no note."""
        return np.eye(3), h * np.eye(3), np.eye(3), None

    def attempt(self, view: CouplingView) -> bool:
        """One Monte Carlo move of the cell; returns whether it was accepted.

        Reads ``view.state`` (centres, point particles, cell),
        ``view.record`` (volume, the energy of the last force call) and asks
        ``view.evaluator`` for the trial's energy (one call).  A trial cell
        in which a body would span half the cell is rejected before any
        call.  A rejection restores the atoms and the calculator's results
        without a call; an acceptance copies the trial into the state and
        evaluates its forces for the next kick.
        """
        rng, state, record, evaluator = self.rng, view.state, view.record, view.evaluator
        n = len(self.steps)
        kind = int(rng.integers(n)) if n > 1 else 0
        epsilon = self.steps[kind] * (2.0 * rng.random() - 1.0)
        uniform = rng.random()
        cell = state.cell.copy()
        new_cell = propose_cell(cell, self.couple, kind, epsilon)
        if body_too_wide(view.model, new_cell, (True, True, True)) is not None:
            self.too_thin += 1  # a move to infinite energy: no calculator call
            self._count(kind, False)
            return False
        if self._refuses(new_cell):
            self.refused += 1  # the calculator cannot take it: a wall as well
            self._count(kind, False)
            return False
        volume, new_volume = record.volume, obs.volume(new_cell)
        energy = record.energy
        if energy is None:  # a calculator that left the energy out of the force call
            energy = evaluator.trial_energy(state)
        saved = evaluator.save_results()
        trial = state.copy()
        deformation = np.linalg.solve(cell, new_cell)
        trial.X[...] = state.X @ deformation
        trial.x[...] = state.x @ deformation
        trial.cell[...] = new_cell
        new_energy = evaluator.trial_energy(trial)
        log_a = log_acceptance(new_energy - energy, volume, new_volume, self.n_particles,
                               self.kT, self.pressure_au)
        accepted = metropolis(log_a, uniform)
        if accepted:
            trial.copy_into(state)  # every version of the state moves
            record.scratch = {}  # what a scheme derived from the old forces
            evaluator.evaluate(state)
            self.exchanged += new_energy - energy
        else:
            evaluator.restore_results(saved, state)
        self._count(kind, accepted)
        return accepted

    def _refuses(self, cell):
        """Whether the calculator cannot take ``cell`` (see :func:`calculator_cell_limits`)."""
        orthorhombic, smallest, _ = self._limits
        if orthorhombic and not _orthorhombic(cell):
            return True
        return bool(smallest) and bool(np.diag(cell).min() < smallest)

    def _count(self, kind, accepted):
        self.attempted[kind] += 1
        self.accepted[kind] += accepted
        if self.attempted.sum() > self.adapt_moves:
            return  # the sizes are frozen
        self.block[kind] += (int(accepted), 1)
        if self.block[kind, 1] == ADAPT_BLOCK:
            self.steps[kind] = adapt_step(self.steps[kind], *self.block[kind])
            self.block[kind] = 0

    # -------------------------------------------------------------- reports
    @property
    def acceptance(self) -> float:
        """Fraction of the attempts accepted since the start (NaN before the first)."""
        total = self.attempted.sum()
        return float(self.accepted.sum() / total) if total else float("nan")

    @property
    def adapting(self) -> bool:
        """Whether the move sizes still adapt (the equilibration window)."""
        return bool(self.attempted.sum() < self.adapt_moves)

    def log_values(self) -> tuple:
        """The acceptance since the start (%) and the moves rejected as walls since the start."""
        return (100.0 * self.acceptance, float(self.too_thin + self.refused))

    def report(self) -> str:
        """One line on the moves: accepted, and rejected as walls (for the run's summary)."""
        total = int(self.attempted.sum())
        line = f"Monte Carlo barostat: {int(self.accepted.sum())} of {total} moves accepted"
        if self.too_thin:
            line += f"; {self.too_thin} rejected because a body would span half the cell"
        if self.refused:
            line += (f"; {self.refused} rejected because the calculator {self._limits[2]} "
                     f"cannot take the cell (below {self._limits[1]:g} Å or tilted)")
        return line

    def energy(self, view: CouplingView) -> float:
        return -self.exchanged

    def get_state(self):
        return {"steps": self.steps.copy(), "attempted": self.attempted.copy(),
                "accepted": self.accepted.copy(), "block": self.block.copy(),
                "too_thin": self.too_thin, "refused": self.refused,
                "exchanged": self.exchanged,
                "rng": rng_state(self.rng)}

    def set_state(self, state):
        self.steps[...] = state["steps"]
        self.attempted[...] = state["attempted"]
        self.accepted[...] = state["accepted"]
        self.block[...] = state["block"]
        self.too_thin = int(state["too_thin"])
        self.refused = int(state.get("refused", 0))  # (absent from older checkpoints)
        self.exchanged = float(state["exchanged"])
        set_rng_state(self.rng, state["rng"])

    def lammps_fix(self, time_unit, seed=None):
        raise NotExportable(
            "barostat.kind: LAMMPS has no Monte Carlo barostat for rigid bodies (fix box/relax "
            "minimises the enthalpy, it samples nothing; fix gcmc does no volume moves); the "
            "nearest native NPT for rigid bodies is fix rigid/npt/small: use kind mtk")

    def todict(self):
        return super().todict() | {"every": self.every, "adapt_moves": self.adapt_moves,
                                   "step": self.step}
