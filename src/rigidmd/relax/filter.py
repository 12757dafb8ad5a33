r"""Relax rigid bodies (and the cell) with ASE's optimizers.

:class:`RigidFilter` shows an :class:`ase.Atoms` to an ASE optimizer as ASE's
filters do (:mod:`ase.filters`): ``get_positions``/``set_positions`` of a
generalized coordinate array of shape ``(n, 3)``, ``get_forces`` (minus the
gradient), ``get_potential_energy``, ``len``.  The rows are

=====================  ===========================  ====================================
rows                   coordinate                   generalized force
=====================  ===========================  ====================================
one per body           centre of mass :math:`s_b`   body force :math:`F_b` (eV/Å)
one per body           :math:`\ell_b\varphi_b` (Å)  :math:`J_r^\mathsf{T}\tau_b/\ell_b` (eV/Å)
one per free atom      position (Å)                 force (eV/Å)
three, with ``cell``   :math:`c\,(D - 1)`           :mod:`rigidmd.relax.cell`
=====================  ===========================  ====================================

Orientation :math:`q_b = q_{\mathrm{ref},b} \otimes \exp(\varphi_b)`: the
rotation vector :math:`\varphi_b` is in the body's principal frame about a
reference orientation; when :math:`|\varphi_b|` exceeds
:data:`ANCHOR_ANGLE` the reference becomes the current orientation and the
row 0, when the optimizer next reads the coordinates (the rotation vector's
chart stays well conditioned: the right Jacobian :math:`J_r(\varphi)` has
singular values between :math:`\sin(|\varphi|/2)/(|\varphi|/2) \ge 0.76`
and 1 below 2.5 rad).  The row jumps then: an optimizer's memory of earlier
steps no longer fits it.  :class:`rigidmd.relax.lbfgs.RigidLBFGS` clears its
memory, and :func:`relax` clears the memory of ASE's optimizers before the
step that reads the new rows (BFGS's Hessian, the pairs of LBFGS and
PreconLBFGS, the velocities of FIRE and MDMin, GPMin's training points,
BFGSLineSearch's ``reset()``).  A plain ASE optimizer on a ``RigidFilter``
(``BFGS(RigidFilter(atoms))``) is not told: it takes the jump for a step,
and the line search of BFGSLineSearch can fail after it ("LineSearch
failed!" on a water dimer turned 2.9 rad; with an anchor angle of 2 rad,
on one at 2 rad, which is why the angle is 2.5, not less): relax such a
start with :func:`relax`.  The
body-frame torque :math:`\tau_b` (eV) becomes a force in eV/Å through the
body's length :math:`\ell_b`, the root-mean-square distance of its atoms
from its centre of mass (0.75 Å for a TIP3P water): a torque :math:`\tau`
reads as the force :math:`\tau/\ell_b` on an atom at the body's typical
radius.  For a linear body the component about its axis is no coordinate:
its gradient is 0 and its value is ignored (2 rotational degrees of freedom).

Convergence is every row's norm below ``fmax`` in the chart anchored at the
current structure (:meth:`RigidFilter.force_norms`: what a new
``RigidFilter`` of the structure reads, whatever the chart the optimizer
came by): :math:`|F_b| < f_\max` for the force on each body,
:math:`|\tau_b|/\ell_b < f_\max` for its torque, the force on each free atom,
and with the cell :math:`|g_{\mathrm{cell}}| < f_\max` per row of the cell
gradient at :math:`D = 1` (:func:`rigidmd.relax.cell.cell_gradient`, eV per
``cell_factor``).  The rotation rows' own force, :math:`J_r^\mathsf{T}\tau_b/
\ell_b`, reads as low as 0.76 :math:`|\tau_b|/\ell_b` below 2.5 rad, so ASE's
test of the rows (every row's norm below ``fmax``) would stop with a torque
above it.  The rows' forces stay minus the gradient of the energy in these
coordinates (what the optimizers' steps and line searches need); the
criterion is the view's: :meth:`RigidFilter.__ase_optimizable__` gives ASE's
optimizers an optimizable whose ``converged(gradient, fmax)`` is
:meth:`RigidFilter.converged` at the current coordinates, which every
optimizer of :mod:`ase.optimize` that keeps ASE's test calls (BFGS, LBFGS,
FIRE, BFGSLineSearch, GPMin, MDMin, :class:`~rigidmd.relax.lbfgs.RigidLBFGS`).
ASE's ``PreconLBFGS`` and ``PreconFIRE`` test the rows' norms themselves
(``get_forces``): on their own they may stop with a torque up to 1/0.76 of
``fmax``; :func:`relax` gives them the view's test.  The column ``fmax`` of
ASE's log is the rows' largest norm (RigidLBFGS logs the view's).  Massless
atoms (the M site of four-site water) are placed rigidly with their body and
the force on them enters its force and torque.
"""

from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError

from rigidmd.core import observables as obs
from rigidmd.core.bodies import RigidBodies, check_bodies_fit
from rigidmd.core.checks import check_finite
from rigidmd.core.dof import RigidBodyDOF
from rigidmd.core.forces import ForceEvaluator
from rigidmd.core.link import BodyLink
from rigidmd.core.model import BodyModel, describe_atoms
from rigidmd.core.quaternion import rotate_inverse
from rigidmd.core.record import StepRecord
from rigidmd.relax import _numba
from rigidmd.relax import cell as relaxcell
from rigidmd.relax import optimizerstate as relaxstate
from rigidmd.relax.facade import AtomsFacade, OptimizableFilter
from rigidmd.relax.rotationvector import right_jacobian_transpose, rotation_quaternion
from rigidmd.relax.stops import Interrupt, Interrupted, RelaxationFailed, WholeStep, failed

__all__ = ["RigidFilter", "relax", "Relaxation", "RelaxationFailed", "OPTIMIZERS",
           "optimizer_class", "ANCHOR_ANGLE", "rotation_quaternion", "right_jacobian_transpose"]

#: Rotation (rad) beyond which a body's reference orientation is moved to its current one.
ANCHOR_ANGLE = 2.5


_NOT_IN_A_CELL_FILTER = ("RigidFilter: ASE's cell filters (FrechetCellFilter, UnitCellFilter) "
                         "cannot wrap it; relax the cell with RigidFilter(atoms, bodies, "
                         "cell='full') (or 'iso', 'aniso')")


class RigidFilter(AtomsFacade):
    r"""An :class:`ase.Atoms` seen by ASE's optimizers as rigid bodies (and a cell).

    Use it where an optimizer takes atoms (``BFGS(RigidFilter(atoms)).run(fmax=0.05)``).
    See the module docstring for the coordinates and the convergence criterion.

    Parameters
    ----------
    atoms : ase.Atoms
        With a calculator.  Its positions (and cell) change as the optimizer
        moves the coordinates; nothing changes on construction.
    bodies : optional
        Body specification, as for :class:`~rigidmd.RigidVerlet`
        (:meth:`rigidmd.RigidBodies.resolve`).
    cell : bool or str, default False
        Also relax the cell: ``True`` or ``"full"`` (symmetric strain),
        ``"aniso"`` (the three axes) or ``"iso"`` (the volume only), with
        molecular scaling.  Needs a cell periodic in all directions and a
        calculator with stress.
    scalar_pressure : float, default 0.0
        Target pressure (eV/Å³), as for :class:`ase.filters.FrechetCellFilter`.
    cell_factor : float, optional
        :math:`c` of the cell rows; default the number of bodies plus free atoms.

    Raises
    ------
    ValueError
        Atoms without a calculator; ``cell`` with a cell not periodic in
        all directions or a calculator without stress; a constraint the
        bodies cannot honour (only ``FixAtoms`` on whole bodies or free atoms,
        ``FixBondLengths`` within bodies and :class:`~rigidmd.RigidBodyDOF`
        are); a cell not finite or degenerate in its periodic directions; a
        bad ``cell``, ``scalar_pressure`` or ``cell_factor``; every error of
        :meth:`rigidmd.RigidBodies.geometry`.  All before anything changes.
    """

    def __init__(self, atoms, bodies=None, *, cell=False, scalar_pressure=0.0,
                 cell_factor=None):
        if atoms.calc is None:
            raise ValueError("RigidFilter: the atoms have no calculator")
        if len(atoms) == 0:
            raise ValueError("RigidFilter: no atoms to relax")
        mode = relaxcell.cell_mode(cell)
        if isinstance(scalar_pressure, bool) or not isinstance(scalar_pressure, Real) \
                or not np.isfinite(scalar_pressure):
            raise ValueError(f"RigidFilter: scalar_pressure={scalar_pressure!r} eV/Å³ is not "
                             "a finite number")
        if mode is None and scalar_pressure != 0:
            raise ValueError(f"RigidFilter: scalar_pressure={scalar_pressure!r} eV/Å³ acts "
                             "only on a relaxing cell; give cell (iso, aniso or full)")
        if mode is not None:
            if not atoms.pbc.all():
                raise ValueError(f"RigidFilter: cell={cell!r} needs a cell periodic in all "
                                 f"three directions; atoms.pbc is {atoms.pbc.tolist()}")
            implemented = getattr(atoms.calc, "implemented_properties", ())
            if "stress" not in implemented:
                raise ValueError(f"RigidFilter: cell={cell!r} needs the stress, which the "
                                 f"calculator {type(atoms.calc).__name__} does not provide")
        check_finite(atoms.positions, "position", "Å", "in RigidFilter")
        _check_cell(atoms)
        rigid = RigidBodies.resolve(atoms, bodies)
        geometry = rigid.geometry(atoms)
        model = geometry.model
        check_bodies_fit(model, atoms.cell.array, atoms.pbc, "in RigidFilter; use a larger cell")
        self._fixed_bodies, self._fixed_free = _honoured_constraints(atoms, model)
        n_units = model.n_bodies + model.n_free
        if cell_factor is None:
            cell_factor = float(max(n_units, 1))
        if not (np.isfinite(cell_factor) and cell_factor > 0):
            raise ValueError(f"RigidFilter: cell_factor={cell_factor!r} must be positive")
        self.atoms = atoms
        self.model = model
        self.mode = mode
        self.scalar_pressure = float(scalar_pressure)
        self.cell_factor = float(cell_factor)
        self.reanchored = 0
        self.lengths = _body_lengths(model)
        self._q_ref = geometry.quaternions.copy()
        # The machinery of the dynamics: the body link places the atoms, the force evaluator
        # calls the calculator (energy, forces and with the cell the stress in one call) and
        # reduces the forces to the bodies, with the molecular virial.
        self._link = BodyLink(atoms, model)
        self._state = self._link.initial_state(geometry)
        self._record = StepRecord(self._state, model)
        self._evaluator = ForceEvaluator(self._link, self._record, stress=mode is not None)
        self._evaluator.begin_step(0, energy=True)  # the energy with every call
        self._cell0 = atoms.cell.array.copy()
        nb, nf = model.n_bodies, model.n_free
        self._slices = (slice(0, nb), slice(nb, 2 * nb), slice(2 * nb, 2 * nb + nf),
                        slice(2 * nb + nf, 2 * nb + nf + (3 if mode else 0)))
        x = np.zeros((2 * nb + nf + (3 if mode else 0), 3))
        x[self._slices[0]] = geometry.com
        x[self._slices[2]] = atoms.positions[model.free]
        self._x = x
        self._key = x.tobytes()  # of the coordinates, for the results below (set by _place)
        t, r, f, c = (np.arange(len(x))[s] for s in self._slices)
        self._rows = {"translation_rows": np.concatenate([t, f]), "rotation_rows": r,
                      "rotation_centre": np.arange(len(r)), "cell_rows": c, "n_rows": len(x)}
        self._placed = None  # (positions array, r) last written, to notice outside moves
        self._start_positions = atoms.positions.copy()  # (the same, before the first)
        self._results = {}  # coordinates (bytes) -> {energy, free_energy, forces}, at most 2
        self.constraints = []
        self.info = atoms.info

    # ------------------------------------------------------------ coordinates
    def _deformation(self):
        if self.mode is None:
            return np.eye(3)
        return relaxcell.deformation(self._x[self._slices[3]], self.mode, self.cell_factor)

    def _phi(self):
        phi = self._x[self._slices[1]] / self.lengths[:, None]
        return np.where(self.model.linear[:, None] & (np.arange(3) == 0), 0.0, phi)

    def _orientations(self):
        q = np.empty_like(self._q_ref)
        _numba.orientations(self._q_ref, self._x[self._slices[1]], self.lengths,
                             self.model.linear, q)
        return q

    def _place(self):
        """Write positions (and cell) of the coordinates into the atoms, through the body link."""
        model, D, state = self.model, self._deformation(), self._state
        q = self._orientations()
        fixed_cell = self.mode is None  # D is the identity: no product
        X, x = self._x[self._slices[0]], self._x[self._slices[2]]
        state.X = X if fixed_cell else X @ D.T  # copied into the state's own buffer
        state.q = q
        state.x = x if fixed_cell else x @ D.T
        if self.mode is not None:
            cell = self._cell0 @ D.T
            check_bodies_fit(model, cell, self.atoms.pbc,
                             "the cell relaxation shrank the cell below the bodies (a "
                             "calculator without a repulsion at short range, or a pressure "
                             "too high, collapses the cell); the atoms keep the last cell "
                             "that fitted")
            state.cell = cell
            self.atoms.set_cell(cell, scale_atoms=False)
        r = self._record.r = self._link.place(state, self._record.r)
        self._key = self._x.tobytes()
        self._placed = (self.atoms.positions.copy(), r, q, D)

    def get_positions(self):
        """The generalized coordinates, shape (n, 3) (Å; the cell rows dimensionless × c).

        A body turned by more than :data:`ANCHOR_ANGLE` from its reference is
        re-anchored here (its reference becomes its orientation, its rows 0;
        :attr:`reanchored` counts them), when the optimizer reads the
        coordinates at the start of a step, never between the trial points of
        a line search.  An optimizer that remembers earlier steps must forget
        them then (:func:`relax` makes ASE's do so; see the module docstring).
        """
        self._reanchor()
        return self._x.copy()

    def set_positions(self, new, **kwargs):
        """Move the bodies (and cell) to the coordinates ``new``, shape (n, 3)."""
        new = np.asarray(new, dtype=float).reshape(self._x.shape)
        check_finite(new, "generalized coordinate", "Å", "set by the optimizer")
        fixed = self._x.copy()
        self._x = new.copy()
        for rows, mask in ((self._slices[0], self._fixed_bodies),
                           (self._slices[1], self._fixed_bodies),
                           (self._slices[2], self._fixed_free)):
            block = self._x[rows]
            block[mask] = fixed[rows][mask]
        self._place()

    def copy(self):
        """Refused: ASE's cell filters (``FrechetCellFilter``, ``UnitCellFilter``) copy the
        atoms they wrap, and a filter holds coordinates no copy could keep."""
        raise TypeError(_NOT_IN_A_CELL_FILTER)

    @property
    def arrays(self):
        """Refused, as :meth:`copy` (ASE's cell filters take the wrapped atoms' arrays)."""
        raise TypeError(_NOT_IN_A_CELL_FILTER)

    def _reanchor(self):
        if not self.model.n_bodies:
            return
        if _numba.largest_angle(self._x[self._slices[1]], self.lengths,
                                 self.model.linear) > ANCHOR_ANGLE:
            far = np.linalg.norm(self._phi(), axis=1) > ANCHOR_ANGLE
            q = self._current()[2]
            self._q_ref[far] = q[far]
            block = self._x[self._slices[1]]
            block[far] = 0.0
            self.reanchored += int(far.sum())
            self._key = self._x.tobytes()
            self._results.clear()  # the coordinates of earlier results meant other references

    positions = property(get_positions, set_positions)

    def restore(self, x):
        """Move back to coordinates ``x`` visited before, keeping their energy and forces.

        For a probe (a preconditioner's estimate): ``set_positions(x + v)``,
        ``get_forces()``, ``restore(x)`` costs one force call, not two.
        """
        self._x = np.asarray(x, dtype=float).reshape(self._x.shape).copy()
        self._place()

    def get_state(self):
        """What continues this view exactly (:func:`relax`'s ``state_file``): a dict of arrays.

        The coordinates, the bodies' reference orientations and the reference
        cell of the rows (the chart the optimizer's memory is written in), and
        the energy and generalized forces at the coordinates when known.
        """
        state = {"x": self._x.copy(), "q_ref": self._q_ref.copy(), "cell0": self._cell0.copy(),
                 "reanchored": np.array(self.reanchored), "n_atoms": np.array(len(self.atoms)),
                 **{f"model.{name}": getattr(self.model, name) for name in BodyModel.STORED}}
        for name, value in self._cached().items():
            state[f"known.{name}"] = np.array(value)
        return state

    def set_state(self, state):
        """Continue from :meth:`get_state` of a view of the same bodies; moves the atoms.

        Raises
        ------
        ValueError
            A state of other rows or bodies (nothing changes then).
        """
        x, q_ref = np.asarray(state["x"], dtype=float), np.asarray(state["q_ref"], dtype=float)
        if x.shape != self._x.shape or q_ref.shape != self._q_ref.shape:
            raise ValueError(f"RigidFilter.set_state: a state of {len(x)} rows and "
                             f"{len(q_ref)} bodies, this view has {len(self._x)} and "
                             f"{len(self._q_ref)}")
        # The body frames the orientations refer to (measured again from other positions,
        # a principal axis may come out flipped).
        self.model.update_from(BodyModel(n_atoms=int(state["n_atoms"]), **{
            name: np.asarray(state[f"model.{name}"]) for name in BodyModel.STORED}))
        self.lengths = _body_lengths(self.model)
        self._q_ref = q_ref.copy()
        self._cell0 = np.asarray(state["cell0"], dtype=float).copy()
        self.reanchored = int(state["reanchored"])
        self._x = x.copy()
        self._place()
        self._results.clear()
        self._remember(**{k[6:]: (v.copy() if v.ndim else float(v)) for k, v in state.items()
                          if k.startswith("known.")})

    def rigid_rows(self):
        """Which rows are what, for a preconditioner (:class:`rigidmd.relax.precon.RigidPrecon`).

        Returns
        -------
        dict
            ``centres`` (m, 3): the bodies' centres of mass then the free
            atoms (Å, lab frame, current cell); ``translation_rows`` (m,):
            their rows; ``rotation_rows`` (n_bodies,) and ``rotation_centre``
            (n_bodies,): the rotation rows and the index of their body's
            centre in ``centres``; ``cell_rows`` (0 or 3,); ``n_rows``.
        """
        _, _, _, D = self._current()
        centres = self._x[self._rows["translation_rows"]]
        return {"centres": centres if self.mode is None else centres @ D.T, **self._rows}

    def fixed_rows(self):
        """Rows that ``FixAtoms`` holds, as a boolean mask of shape (n,)."""
        mask = np.zeros(len(self._x), dtype=bool)
        mask[self._slices[0]] = self._fixed_bodies
        mask[self._slices[1]] = self._fixed_bodies
        mask[self._slices[2]] = self._fixed_free
        return mask

    def _current(self):
        """The placement of the current coordinates, placing them first if needed.

        Atoms moved from outside since the filter placed them (or since it was made) are
        refused: the filter holds the bodies' coordinates and would put the atoms back in
        silence (a body moved by 5 Å was moved back, with the energy of the old places).
        """
        last = self._start_positions if self._placed is None else self._placed[0]
        positions = self.atoms.positions
        if last.shape != positions.shape or not np.array_equal(last, positions):
            if last.shape != positions.shape:
                where = f"{len(positions)} atoms where it had {len(last)}"
            else:
                moved = np.linalg.norm(positions - last, axis=1)
                where = f"atom {int(np.argmax(moved))} by {moved.max():.3g} Å"
            raise ValueError(f"RigidFilter: the atoms were moved since the filter placed them "
                             f"({where}); it holds the bodies' coordinates and would put them "
                             "back: make a new RigidFilter for the moved atoms")
        if self._placed is None:
            self._place()
        return self._placed

    # ------------------------------------------------------------ energy and gradient
    def _cached(self):
        """What is known at the current coordinates (dict: ``energy``, ``free_energy``,
        ``forces``), placing them first if needed."""
        self._current()
        return self._results.get(self._key, {})

    def _remember(self, **known):
        key = self._key
        if key not in self._results and len(self._results) >= 2:
            self._results.pop(next(iter(self._results)))
        self._results.setdefault(key, {}).update(known)

    def get_potential_energy(self, force_consistent=False, **kwargs):
        """Potential energy (eV), plus :math:`pV` when the cell relaxes (the enthalpy).

        ``force_consistent``: the free energy where the calculator has one
        (ASE's optimizers ask for it), else the energy.
        """
        name = "free_energy" if force_consistent else "energy"
        cached = self._cached().get(name)
        if cached is not None:
            return cached
        try:
            energy = self.atoms.get_potential_energy(force_consistent=force_consistent)
        except PropertyNotImplementedError:
            if not force_consistent:
                raise
            energy = self.atoms.get_potential_energy()
        if self.mode is not None:
            energy += self.scalar_pressure * self.atoms.get_volume()
        self._remember(**{name: float(energy)})
        return float(energy)

    def get_forces(self, **kwargs):
        """Generalized forces, minus the gradient of the energy, shape (n, 3) (eV/Å)."""
        cached = self._cached().get("forces")
        if cached is not None:
            return cached.copy()
        out, norms = self._generalized_forces()
        self._remember(forces=out.copy(), norms=norms, **self._energies())
        return out

    def force_norms(self):
        r"""Each row's generalized force in the chart anchored here, shape (n,) (eV/Å).

        What a new ``RigidFilter`` of the current structure reads as each row's
        norm: :math:`|F_b|` (lab frame) for a body's centre, :math:`|\tau_b|/\ell_b`
        for its rotation (the torque's component about a linear body's axis
        left out), :math:`|f|` for a free atom, and a row of the cell gradient at
        :math:`D = 1`; 0 for what ``FixAtoms`` holds.  The rows of :meth:`get_forces`
        differ from these by the chart: a rotation row is :math:`J_r^\mathsf{T}\tau_b
        /\ell_b`, down to 0.76 of it below 2.5 rad.  No force call where the
        forces are known.
        """
        norms = self._cached().get("norms")
        if norms is None:
            self.get_forces()
            norms = self._cached().get("norms")
        if norms is None:  # forces of a state written before the norms were kept
            out, norms = self._generalized_forces()
            self._remember(forces=out, norms=norms)
        return norms.copy()

    def converged(self, fmax):
        """Whether every row of :meth:`force_norms` is below ``fmax`` (eV/Å): the criterion
        of :func:`relax`, and of ASE's optimizers that call their optimizable's test."""
        return bool(len(self._x) == 0 or self.force_norms().max() < fmax)

    def __ase_optimizable__(self):
        """ASE's view of a filter, whose ``converged(gradient, fmax)`` is :meth:`converged`
        at the current coordinates (the gradient ASE passes is the one there)."""
        return _RigidOptimizable(self)

    def _energies(self):
        """The energies the force call computed with the forces (no further call), as
        :meth:`get_potential_energy` gives them: ``energy`` and ``free_energy``."""
        if not self._evaluator.energy_known:  # (checked finite by the force evaluator)
            return {}  # the calculator gave none with the forces: asked for when needed
        energy = self._record.energy
        free = float(self.atoms.calc.results.get("free_energy", energy))
        pv = self.scalar_pressure * self.atoms.get_volume() if self.mode is not None else 0.0
        return {"energy": energy + pv, "free_energy": free + pv}

    def _generalized_forces(self):
        _, r, q, D = self._current()  # the atoms are placed: r is the record's
        model, record = self.model, self._record
        # The dynamics' force call (ForceEvaluator), then its reduction to the bodies fused
        # with the rotation rows' gradient (rigidmd.relax._numba.body_gradient).
        forces = self._evaluator.calculator_forces(self._state)
        nb = model.n_bodies
        F, tau, g = np.empty((nb, 3)), np.empty((nb, 3)), np.empty((nb, 3))
        _numba.body_gradient(forces, r, model.order, model.bounds, q, self._x[self._slices[1]],
                              self.lengths, model.linear, self._fixed_bodies, F, tau, g)
        record.F, record.tau, record.f = F, tau, forces[model.free]
        out = np.empty_like(self._x)
        fixed_cell = self.mode is None  # D is the identity: no product
        out[self._slices[0]] = F if fixed_cell else F @ D
        out[self._slices[1]] = g
        out[self._slices[2]] = record.f if fixed_cell else record.f @ D
        out[self._slices[0]][self._fixed_bodies] = 0.0
        out[self._slices[2]][self._fixed_free] = 0.0
        # The rows' norms in the chart anchored here (phi = 0, D = 1): the convergence test.
        norms = np.empty(len(out))
        body_torque = rotate_inverse(q, tau)
        body_torque[model.linear, 0] = 0.0  # about a linear body's axis: no coordinate
        norms[self._slices[0]] = np.where(self._fixed_bodies, 0.0, np.linalg.norm(F, axis=1))
        norms[self._slices[1]] = np.where(self._fixed_bodies, 0.0, np.linalg.norm(
            body_torque, axis=1) / np.where(self.lengths > 0, self.lengths, 1.0))
        norms[self._slices[2]] = np.where(self._fixed_free, 0.0,
                                          np.linalg.norm(record.f, axis=1))
        if self.mode is not None:
            # The barostats' molecular virial (symmetric) and its antisymmetric part, half
            # the bodies' total torque: the full virial of a deformation at fixed orientations.
            W = record.virial - obs.torque_virial(tau)
            out[self._slices[3]] = -relaxcell.cell_gradient(
                W, record.volume, D, self.scalar_pressure, self.mode, self.cell_factor)
            norms[self._slices[3]] = np.linalg.norm(relaxcell.cell_gradient(
                W, record.volume, np.eye(3), self.scalar_pressure, self.mode,
                self.cell_factor), axis=1)
        return out, norms

    # ------------------------------------------------------------ what ASE asks of a filter
    def __len__(self):
        return len(self._x)

    def get_global_number_of_atoms(self):
        return len(self._x)


class _RigidOptimizable(OptimizableFilter):
    """ASE's optimizable of a :class:`RigidFilter`: ASE's filter one, with the view's
    convergence test (:meth:`RigidFilter.converged`)."""

    def converged(self, gradient, fmax):
        view = getattr(self, "filterobj", None)
        if view is None:  # ASE 3.23: OptimizableAtoms
            view = self.atoms
        return view.converged(fmax)


def _check_cell(atoms):
    """Refuse a cell that is not finite, or whose periodic vectors are not independent (a
    zero vector, two parallel, three in a plane): one line, not NumPy's or SciPy's."""
    cell, pbc = atoms.cell.array, np.asarray(atoms.pbc, dtype=bool)
    if not np.isfinite(cell).all():
        raise ValueError(f"RigidFilter: the cell {cell.tolist()} has a non-finite entry; give "
                         "a finite cell")
    if not pbc.any():
        return
    # Singular values of the periodic vectors: one near 0 relative to the largest is a
    # degenerate cell (1e-9: far below any cell a structure has, far above round-off).
    s = np.linalg.svd(cell[pbc], compute_uv=False)
    if s.min() <= 1e-9 * max(s.max(), 1.0):
        raise ValueError(f"RigidFilter: the cell vectors {np.flatnonzero(pbc).tolist()} are "
                         f"periodic (atoms.pbc {pbc.tolist()}) but not independent (cell "
                         f"{np.round(cell, 6).tolist()}): a zero vector, or vectors in one line "
                         "or plane; give a cell with a length in every periodic direction, or "
                         "set atoms.pbc False there")


def _body_lengths(model):
    """Root-mean-square distance of each body's atoms from its centre (Å), shape (n_bodies,)."""
    if not model.n_bodies:
        return np.zeros(0)
    d = model.body_coordinates
    return np.sqrt(np.add.reduceat(np.sum(d * d, axis=1), model.starts) / np.diff(model.bounds))


def _honoured_constraints(atoms, model):
    """Bodies and free atoms that ``FixAtoms`` holds; refuse constraints the bodies cannot honour.

    Returns
    -------
    fixed_bodies : numpy.ndarray of bool, shape (n_bodies,)
    fixed_free : numpy.ndarray of bool, shape (n_free,)
    """
    from ase.constraints import FixAtoms, FixBondLengths

    fixed = np.zeros(len(atoms), dtype=bool)
    body_of = np.full(len(atoms), -1)
    body_of[model.order] = model.atom_body
    for c in atoms.constraints:
        if isinstance(c, RigidBodyDOF):
            continue
        if isinstance(c, FixAtoms):
            fixed[c.get_indices()] = True
            continue
        if isinstance(c, FixBondLengths):
            pairs = np.asarray(c.pairs)
            across = (body_of[pairs[:, 0]] < 0) | (body_of[pairs[:, 0]] != body_of[pairs[:, 1]])
            if np.any(across):
                i, j = pairs[np.flatnonzero(across)[0]]
                raise ValueError(f"RigidFilter: FixBondLengths joins atoms {int(i)} and "
                                 f"{int(j)}, which are not in one rigid body; the bodies "
                                 "cannot honour it")
            continue  # every fixed length lies inside a rigid body: kept by the bodies
        raise ValueError(f"RigidFilter: cannot honour the constraint {type(c).__name__} "
                         "(only FixAtoms on whole bodies or free atoms and FixBondLengths "
                         "within bodies); remove it")
    fixed_bodies = np.zeros(model.n_bodies, dtype=bool)
    if fixed.any() and model.n_bodies:
        per_body = np.add.reduceat(fixed[model.order].astype(int), model.starts)
        counts = np.diff(model.bounds)
        partial = np.flatnonzero((per_body > 0) & (per_body < counts))
        if partial.size:
            b = int(partial[0])
            raise ValueError(f"RigidFilter: FixAtoms holds some but not all atoms of body {b} "
                             f"(atoms {describe_atoms(model.atoms_of(b))}); fix a body whole")
        fixed_bodies = per_body == counts
    return fixed_bodies, fixed[model.free]


#: The optimizers :func:`relax` takes by name: rigidmd's default
#: (:class:`rigidmd.relax.lbfgs.RigidLBFGS`), ASE's preconditioned ones (given a
#: :class:`rigidmd.relax.precon.RigidPrecon`) and all of :mod:`ase.optimize` that take Atoms.
OPTIMIZERS = ("RigidLBFGS", "PreconLBFGS", "PreconFIRE", "BFGS", "LBFGS", "FIRE",
              "BFGSLineSearch", "GPMin", "MDMin")

#: The optimizers that take a preconditioner (``precon``); :func:`relax` gives them a RigidPrecon.
PRECONDITIONED = ("RigidLBFGS", "PreconLBFGS", "PreconFIRE")


@dataclass
class Relaxation:
    """What :func:`relax` did.

    Attributes
    ----------
    converged : bool
        Whether every generalized force fell below ``fmax`` within ``steps``.
    steps : int
        Optimizer steps taken.
    energy : float
        Final potential energy (eV), without :math:`pV`.
    fmax : float
        Largest generalized force left (eV/Å): the largest of
        :meth:`RigidFilter.force_norms`, the convergence test's, which a new
        ``RigidFilter`` of the relaxed structure reads as its rows' largest norm.
    """

    converged: bool
    steps: int
    energy: float
    fmax: float


def optimizer_class(name):
    """The ASE optimizer class named ``name`` (one of :data:`OPTIMIZERS`), or a class as is."""
    if not isinstance(name, str):
        return name
    if name not in OPTIMIZERS:
        raise ValueError(f"optimizer={name!r}: expected one of {', '.join(OPTIMIZERS)}")
    if name == "RigidLBFGS":
        from rigidmd.relax.lbfgs import RigidLBFGS

        return RigidLBFGS
    if name in ("PreconLBFGS", "PreconFIRE"):
        import ase.optimize.precon

        return getattr(ase.optimize.precon, name)
    import ase.optimize

    return getattr(ase.optimize, name)


def relax(atoms, bodies=None, *, fmax=0.05, steps=1000, optimizer="RigidLBFGS", cell=False,
          scalar_pressure=0.0, trajectory=None, logfile=None, observers=(),
          append_trajectory=False, state_file=None, resume=False, first_step=None,
          state_label=None, **kwargs) -> Relaxation:
    """Relax the rigid bodies of ``atoms`` (and the cell) in place with an ASE optimizer.

    Parameters
    ----------
    atoms : ase.Atoms
        With a calculator; moved to the relaxed structure (or as far as it got).
    bodies : optional
        Body specification (:meth:`rigidmd.RigidBodies.resolve`).
    fmax : float, default 0.05
        Largest generalized force at convergence (eV/Å): every row of
        :meth:`RigidFilter.force_norms` below it (every body's force and
        torque over its length, ``|τ_b|/ℓ_b``), with every optimizer.
    steps : int, default 1000
        Optimizer steps allowed.
    optimizer : str or ase.optimize.Optimizer subclass, default "RigidLBFGS"
        One of :data:`OPTIMIZERS` or a class.  The default,
        :class:`rigidmd.relax.lbfgs.RigidLBFGS`, needs no tuning: limited-memory
        BFGS preconditioned by :class:`rigidmd.relax.precon.RigidPrecon`
        (O(n) per step, independent of the number of BLAS threads).
        ``PreconLBFGS`` and ``PreconFIRE`` (ASE's) get a ``RigidPrecon``
        unless ``precon`` is given.  An ASE optimizer's memory of earlier
        steps is cleared when a body is re-anchored (its rows jump;
        :data:`ANCHOR_ANGLE`), before the step that reads the new rows
        (``reset()`` where it has one, else ``initialize()``; a class of your
        own gets the same); RigidLBFGS clears its own.  Whatever the
        optimizer, convergence is the view's test (:meth:`RigidFilter.converged`).
    cell, scalar_pressure :
        As for :class:`RigidFilter` (pressure in eV/Å³).
    trajectory, logfile : str or file, optional
        Passed to the optimizer (ASE's trajectory of the atoms, its log).
    observers : sequence of callables, optional
        Each called after every step as ``observer(step, energy, fmax)``
        (step of this call, energy in eV with :math:`pV`, largest generalized
        force in eV/Å, of :meth:`RigidFilter.force_norms`; no extra force
        call); an exception it raises stops the relaxation after the step's
        trajectory frame.
    append_trajectory : bool, default False
        Append to ``trajectory`` (continuing a relaxation) instead of replacing it.
    state_file : str or pathlib.Path, optional
        Where the relaxation's state is written when it stops before
        converging, after a whole step (Ctrl-C, an observer raised, or
        ``steps`` were taken): the view's chart and the optimizer's memory
        (:mod:`rigidmd.relax.optimizerstate`); removed when the relaxation converges.
        Only for an optimizer that gives its memory
        (:func:`rigidmd.relax.optimizerstate.keeps_memory`; ASE's keep theirs).
    resume : bool, default False
        Continue from ``state_file``, written at ``atoms``' positions by this
        optimizer: the steps are those the uninterrupted relaxation would have
        taken (ValueError when it does not match the atoms).
    first_step : int, optional
        Steps an earlier part of this relaxation took: given (0 included: a
        part stopped at its step 0), this call continues it; the log numbers
        its steps from there, with no second header and no second line for
        the starting point, which the earlier part logged last (nor a second
        call of the observers there).  None: a new relaxation, from step 0.
    state_label : str, optional
        Text recorded in the state file, which ``resume=True`` requires to be
        the same (ValueError otherwise): what else the continuation must
        share, such as a digest of the calculator.
    **kwargs
        Further optimizer arguments (``maxstep``, ...).  With ASE's BFGS,
        ``alpha`` (initial Hessian, eV/Å² times the identity in the rows of
        :class:`RigidFilter`; ASE's default 70) sets most of the cost
        (``benchmarks/relax.txt``); the default optimizer needs none.

    Returns
    -------
    Relaxation

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C (SIGINT with Python's own handler, in the main thread): after
        the step in progress, its trajectory frame and the ``state_file``, as
        ``rigidmd relax`` stops; a second Ctrl-C at once.
    RelaxationFailed
        The optimizer or the calculator raised in a step (a line search that
        found no descent, ...); the atoms are back at the structure of the
        last whole step, which the message names.
    rigidmd.core.forces.NonFiniteForceError
        The calculator returned NaN or infinite forces; the atoms as above.
    """
    if isinstance(fmax, bool) or not isinstance(fmax, Real) or not (np.isfinite(fmax)
                                                                   and fmax > 0):
        raise ValueError(f"relax: fmax={fmax!r} must be a positive number (eV/Å)")
    if isinstance(steps, bool) or not isinstance(steps, Real) or int(steps) != steps \
            or steps < 0:
        raise ValueError(f"relax: steps={steps!r} must be a whole number >= 0")
    continued = first_step is not None
    first_step = 0 if first_step is None else first_step
    if isinstance(first_step, bool) or not isinstance(first_step, Real) \
            or int(first_step) != first_step or first_step < 0:
        raise ValueError(f"relax: first_step={first_step!r} must be a whole number >= 0")
    cls = optimizer_class(optimizer)
    from rigidmd.relax.lbfgs import RigidLBFGS

    view = RigidFilter(atoms, bodies, cell=cell, scalar_pressure=scalar_pressure)
    if cls.__name__ in PRECONDITIONED and "precon" not in kwargs:
        from rigidmd.relax.precon import RigidPrecon

        kwargs["precon"] = RigidPrecon()
    saved = relaxstate.resumed_state(state_file, atoms, cls, state_label) if resume else None
    if not relaxstate.keeps_memory(cls):
        state_file = None  # nothing a continuation could take the same steps from
    with cls(view, trajectory=trajectory, logfile=logfile, append_trajectory=append_trajectory,
             **kwargs) as opt:
        opt.nsteps = int(first_step)  # ASE's log numbers steps by it (header and start at 0)
        if continued and not first_step:
            _skip_the_start(opt)  # continued from step 0: logged and observed already
        if saved is not None:
            view.set_state(relaxstate.split(saved, "view"))
            if hasattr(opt, "set_state"):
                opt.set_state(relaxstate.split(saved, "opt"))
        # The view's test, also for optimizers that test the rows' norms themselves
        # (PreconLBFGS, PreconFIRE): every torque below fmax, whatever the chart.
        opt.gradient_converged = lambda gradient: view.converged(opt.fmax)
        if not issubclass(cls, RigidLBFGS):  # (RigidLBFGS clears its memory itself)
            _forget_on_reanchoring(opt, view)
        whole = WholeStep(atoms, opt)  # first: the structure of each whole step
        opt.attach(whole, interval=1)
        reports = [_Report(observer, opt, view, int(first_step)) for observer in observers]
        for report in reports:
            opt.attach(report, interval=1)
        interrupt = Interrupt()
        opt.attach(interrupt, interval=1)  # last: after the step's frame and observers
        try:
            with interrupt:
                converged = bool(opt.run(fmax=fmax, steps=int(steps)))
        except Exception as err:
            if isinstance(err, Interrupted) or any(report.raised for report in reports):
                if state_file is not None:  # after a whole step
                    relaxstate.write_state(state_file, view, opt, state_label)
                if isinstance(err, Interrupted):
                    kept = (f"its state is in {state_file}: relax(..., resume=True) continues"
                            if state_file is not None else "give a state_file to continue")
                    raise KeyboardInterrupt(f"relax: interrupted (Ctrl-C) after step "
                                            f"{whole.step}; {kept}") from None
                raise
            whole.restore()  # not at the failed trial point: at the last whole step
            if isinstance(err, OSError) or getattr(err, "setup", False):
                raise  # a failed write (named by the caller), an input's mistake
            raise failed(err, cls.__name__, whole.step) from err
        nsteps = opt.get_number_of_steps() - int(first_step)
        if state_file is not None:
            if converged:
                Path(state_file).unlink(missing_ok=True)
            else:
                relaxstate.write_state(state_file, view, opt, state_label)
    left = float(view.force_norms().max()) if len(view) else 0.0
    return Relaxation(converged, int(nsteps), float(atoms.get_potential_energy()), left)


def _forget_on_reanchoring(opt, view):
    """Before each step of ``opt``, re-anchor the bodies of ``view`` turned beyond
    :data:`ANCHOR_ANGLE` and, when one was, clear what ``opt`` remembers of earlier steps
    (:func:`_forget`): their rows jumped, and a memory of steps across the jump (ASE's
    BFGSLineSearch: "LineSearch failed!") is not the surface's curvature."""
    step = opt.step

    def step_in_one_chart(*args, **kwargs):
        before = view.reanchored
        view.get_positions()  # re-anchors, as the step's own reading would
        if view.reanchored != before:
            _forget(opt)
        return step(*args, **kwargs)

    opt.step = step_in_one_chart


def _forget(opt):
    """Clear an ASE optimizer's memory of earlier steps, as it starts: BFGSLineSearch's
    ``reset()``, else ``initialize()`` (BFGS's Hessian, FIRE's and MDMin's velocities,
    PreconLBFGS's pairs, ...), with ASE's LBFGS's pairs (kept in ``state`` since ASE 3.29)
    and GPMin's training points, which ``initialize`` leaves."""
    reset = getattr(opt, "reset", None)
    if callable(reset):
        reset()
    else:
        opt.initialize()
    pairs = getattr(opt, "state", None)
    if all(hasattr(pairs, name) for name in ("s", "y", "rho", "iteration")):
        pairs.s, pairs.y, pairs.rho, pairs.iteration = [], [], [], 0
    if hasattr(opt, "x_list") and hasattr(opt, "y_list"):
        opt.x_list, opt.y_list = [], []


def _skip_the_start(opt):
    """Make ``opt`` neither log nor call its observers at its starting point (step 0), as ASE
    does for a start at step k > 0: a part stopped at step 0 wrote them."""
    log, observe = opt.log, opt.call_observers

    def skipped(call):
        def at_step(*args, **kwargs):
            if opt.nsteps:
                return call(*args, **kwargs)
            return None

        return at_step

    opt.log, opt.call_observers = skipped(log), skipped(observe)


class _Report:
    """``observer(step, energy, fmax)`` of the optimizer's current point (cached: no call;
    ``fmax`` the largest of :meth:`RigidFilter.force_norms`)."""

    def __init__(self, observer, opt, view, first_step=0):
        self.observer, self.opt, self.view = observer, opt, view
        self.first_step = first_step
        self.raised = False  # the observer raised: the step and its frame are whole

    def __call__(self):
        fmax = float(self.view.force_norms().max()) if len(self.view) else 0.0
        try:
            self.observer(self.opt.nsteps - self.first_step, self.view.get_potential_energy(), fmax)
        except BaseException:
            self.raised = True
            raise
