r"""Rigid-body molecular dynamics as an ASE integrator.

:class:`RigidVerlet` advances rigid bodies with quaternion velocity Verlet
(NO_SQUISH, as LAMMPS ``fix rigid/nve``) and atoms that belong to no body as
point particles, in the same step, with forces from any ASE calculator.
"""

import warnings

import numpy as np
from ase import Atoms
from ase.md.md import MolecularDynamics

from rigidmd import _numba
from rigidmd import operators as ops
from rigidmd import quaternion as quat
from rigidmd.bodies import RigidBodies, unwrap_bodies
from rigidmd.schemes import BUILTIN_SCHEMES, Scheme, SchemeContext, resolve_scheme
from rigidmd.state import RigidState

__all__ = ["RigidVerlet", "RigidBodyDOF", "NonFiniteForceError"]

#: Largest rigid-fit residual (Å) accepted silently when re-reading positions.
FIT_TOLERANCE = 1e-6


class NonFiniteForceError(ValueError):
    """The calculator returned a force that is NaN or infinite."""


class RigidBodyDOF:
    """Marks rigid bodies for ASE's degree-of-freedom count.

    :class:`RigidVerlet` puts one of these in ``atoms.constraints`` so that
    :meth:`ase.Atoms.get_temperature` and :class:`ase.md.MDLogger` count 6
    degrees of freedom per body (5 per linear body) and 3 per point particle.
    It never changes positions, momenta or forces.  It has no ``todict``, so
    trajectory writers skip it and ``.traj`` files stay readable by plain
    :func:`ase.io.read`.

    Parameters
    ----------
    removed_dof : int
        ``3 * len(atoms)`` minus the rigid degrees of freedom.
    """

    def __init__(self, removed_dof):
        self.removed_dof = int(removed_dof)

    def get_removed_dof(self, atoms):
        return self.removed_dof

    def adjust_positions(self, atoms, new):
        pass

    def adjust_momenta(self, atoms, momenta):
        pass

    def adjust_forces(self, atoms, forces):
        pass

    def index_shuffle(self, atoms, ind):
        # A subset of atoms is no longer the same set of bodies: drop it.
        raise NotImplementedError

    def __repr__(self):
        return f"RigidBodyDOF(removed_dof={self.removed_dof})"


class RigidVerlet(MolecularDynamics):
    r"""NVE rigid-body molecular dynamics (NO_SQUISH quaternion velocity Verlet).

    Molecules are rigid bodies with centre of mass :math:`X`, velocity
    :math:`V`, orientation quaternion :math:`q = (w, x, y, z)` and NO_SQUISH
    conjugate momentum :math:`p = 2\,q \otimes (0, L_b)`; atoms in no body
    are point particles.  One step of ``timestep`` is (Miller et al. 2002;
    LAMMPS ``fix rigid/nve``)

    1. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`, :math:`X \mathrel{+}= \Delta t\,V`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    2. free rotation :math:`R_3(\tfrac{\Delta t}{2}) R_2(\tfrac{\Delta t}{2})
       R_1(\Delta t) R_2(\tfrac{\Delta t}{2}) R_3(\tfrac{\Delta t}{2})`;
    3. atoms placed at :math:`x_i = X + R(q)\,d_i`, one force call;
    4. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    5. atom momenta :math:`m_i (V + \omega \times (x_i - X))`.

    It is symplectic, time reversible and second order, with one force
    evaluation per step.

    At construction the atoms' velocities are projected onto rigid motion
    (as LAMMPS does at setup); the kinetic energy this removes is kept in
    :attr:`removed_kinetic_energy` and a warning reports it when it is more
    than roundoff.  After every step the Atoms hold the rigid positions and
    momenta.  If the Atoms' positions or momenta are changed between runs,
    the next :meth:`run` reads them again, keeping each body's reference
    frame (positions are fitted by the best rigid rotation).

    While the dynamics exists, ``atoms.constraints`` holds a
    :class:`RigidBodyDOF`, so ``atoms.get_temperature()`` and the MD logger
    count rigid degrees of freedom (6 per body, 5 per linear body, 3 per
    point particle; no centre-of-mass correction, as everywhere in ASE,
    whereas LAMMPS subtracts 3).

    Parameters
    ----------
    atoms : ase.Atoms
        The system, with a calculator attached.
    timestep : float
        Time step in ASE time units (``1 * ase.units.fs`` for 1 fs).
    bodies : None, str, RigidBodies, array_like, or list of lists, optional
        Which atoms form which body; see :meth:`RigidBodies.resolve`.
        ``None`` (default) uses covalent connectivity; ``"mol-id"`` the
        ``mol-id`` array of a LAMMPS data file; ``"tags"`` the tags.
    trajectory : str or ase.io.Trajectory, optional
        Write frames here every ``loginterval`` steps.
    logfile : str or file, optional
        MD log (``"-"`` for stdout).
    loginterval : int, default 1
        Interval of the trajectory and log, in steps.
    integrator : str, list or Scheme, default ``"no_squish"``
        The rotational integrator: ``"no_squish"`` (LAMMPS ``fix rigid/nve``),
        ``"richardson"`` (LAMMPS ``fix rigid``), ``"rozmanov_kusalik"``
        (RMPCDMD), ``"pcdm"`` (Zhao & van Wachem, two force calls per step),
        ``"exadem"`` (first order; a DEM scheme, not for molecules); or a
        scheme of operators as a list, a :class:`~rigidmd.schemes.Scheme` or a
        YAML file.  See :mod:`rigidmd.schemes`.
    integrator_options : dict, optional
        Parameters of a built-in integrator's operators, e.g.
        ``{"tol": 1e-13, "max_iter": 100}`` for ``"rozmanov_kusalik"``.
    backend : {None, "numba", "numpy"}, optional
        For ``"no_squish"``: ``"numpy"`` runs the scheme's operators
        (:mod:`rigidmd.operators`, the readable reference path); ``"numba"``
        runs the same arithmetic as two compiled loops over bodies (about 6
        times faster per body).  ``None`` picks numba when it is installed.
        Other integrators always run their operators.
    **kwargs
        Passed to :class:`ase.md.md.MolecularDynamics` (e.g. ``append_trajectory``).

    Raises
    ------
    TypeError
        ``atoms`` is not an :class:`ase.Atoms`.
    ValueError
        A bad body definition, mass, geometry or time step, or other ASE
        constraints on the atoms; raised before anything is changed.

    References
    ----------
    T. F. Miller III, M. Eleftheriou, P. Pattnaik, A. Ndirango, D. Newns and
    G. J. Martyna, J. Chem. Phys. 116, 8649 (2002).
    """

    def __init__(self, atoms, timestep, bodies=None, trajectory=None, logfile=None,
                 loginterval=1, integrator="no_squish", integrator_options=None, backend=None,
                 **kwargs):
        # -- validate everything before touching the atoms or any file --
        if not isinstance(atoms, Atoms):
            raise TypeError(f"atoms must be an ase.Atoms, got {type(atoms).__name__}")
        try:
            dt = float(timestep)
        except (TypeError, ValueError):
            raise TypeError(f"timestep must be a number, got {timestep!r}") from None
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"timestep must be positive and finite, got {timestep!r}")
        others = [c for c in atoms.constraints if not isinstance(c, RigidBodyDOF)]
        if others:
            raise ValueError(
                f"RigidVerlet cannot honour other ASE constraints ({others[0]!r}); "
                "remove them (rigid bodies replace bond constraints)"
            )
        if backend is None:
            backend = "numba" if _numba.AVAILABLE else "numpy"
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', got {backend!r}")
        if backend == "numba" and not _numba.AVAILABLE:
            raise ValueError("backend='numba' but numba is not installed")
        momenta = atoms.get_momenta()
        if not np.all(np.isfinite(momenta)):
            a = int(np.flatnonzero(~np.isfinite(momenta).all(axis=1))[0])
            raise ValueError(f"atom {a} has a non-finite momentum {momenta[a]}")
        scheme = resolve_scheme(integrator, **(integrator_options or {}))
        rigid = RigidBodies.resolve(atoms, bodies)
        geom = rigid.geometry(atoms)

        # -- from here on the atoms and files change --
        super().__init__(atoms, dt, trajectory=trajectory, logfile=logfile,
                         loginterval=loginterval, **kwargs)
        self.backend = backend
        self.scheme = scheme
        self._fused = backend == "numba" and scheme == Scheme(BUILTIN_SCHEMES["no_squish"])
        self.bodies = rigid
        self.geometry = geom
        self._free = rigid.free_indices
        self._free_masses = self.masses[self._free, 0].copy()
        self._bounds = np.append(geom.starts, len(geom.order)).astype(np.int64)
        # Reciprocals for the compiled loops (0 about a zero-moment axis).
        moments = geom.moments
        self._inv_moments = np.where(moments > 0, 1.0 / np.where(moments > 0, moments, 1.0), 0.0)
        self._inv4i = 0.25 * self._inv_moments
        self._inv_mass = 1.0 / geom.mass
        self.degrees_of_freedom = geom.degrees_of_freedom + 3 * len(self._free)
        dof = RigidBodyDOF(3 * len(atoms) - self.degrees_of_freedom)
        atoms.constraints = [dof]
        nb, nf = geom.n_bodies, len(self._free)
        self._state = RigidState(
            X=geom.com.copy(), V=np.zeros((nb, 3)), q=geom.quaternions.copy(),
            p=np.zeros((nb, 4)), x=atoms.positions[self._free].copy(), v=np.zeros((nf, 3)),
        )
        self._backup = self._state.copy()
        self._ctx = SchemeContext(
            state=self._state, geometry=geom, dt=dt, F=np.zeros((nb, 3)), tau=np.zeros((nb, 3)),
            f=np.zeros((nf, 3)), free_masses=self._free_masses, evaluate=self._evaluate_forces)
        self._r = np.zeros((len(geom.order), 3))
        self.removed_kinetic_energy = 0.0
        self._synced = None
        self._read_momenta()
        self._write_atoms()

    # ------------------------------------------------------------ ASE API
    def todict(self):
        d = super().todict()
        name = self.scheme.name if self.scheme.name in BUILTIN_SCHEMES else "custom"
        d.update(integrator=name, scheme=self.scheme.todict(), bodies_rule=self.bodies.rule,
                 n_bodies=self.geometry.n_bodies)
        return d

    def irun(self, steps=50):
        """Run as a generator; see :meth:`ase.md.md.MolecularDynamics.irun`.

        Changes made to the Atoms since the last step are read first.
        """
        self._sync_from_atoms()
        self._evaluate_forces()
        try:
            yield from super().irun(steps)
        finally:
            self._remember_atoms()

    def _refresh_properties(self):
        # Forces at the current positions were evaluated inside step() (or
        # at the start of irun); nothing to refresh.
        pass

    # ------------------------------------------------------------ the step
    def step(self):
        """Advance one step of ``self.dt`` with the integrator's scheme.

        If anything fails (the calculator, an iteration), the state, forces,
        thermostat variables and atoms are put back as they were at the start
        of the step.
        """
        ctx = self._ctx
        self._state.copy_into(self._backup)
        if self._fused:
            # The forces are only overwritten after the force call succeeded.
            saved = (ctx.F, ctx.tau, ctx.f, ctx.scratch)
        else:
            saved = (ctx.F.copy(), ctx.tau.copy(), ctx.f.copy(), dict(ctx.scratch))
        extra = self._save_extra()
        try:
            self._advance()
        except BaseException:
            self._backup.copy_into(self._state)
            ctx.F, ctx.tau, ctx.f, ctx.scratch = saved
            self._restore_extra(extra)
            self._place_atoms()
            raise

    def _advance(self):
        """The step proper; thermostats wrap it."""
        if self._fused:
            self._fused_step()
        else:
            self.scheme.run(self._ctx)
            self._write_momenta()

    def _save_extra(self):
        """Variables beyond the state that a failed step must restore (thermostats)."""
        return None

    def _restore_extra(self, saved):
        pass

    def _fused_step(self):
        """NO_SQUISH as two compiled loops over bodies (the same arithmetic as the scheme)."""
        s, g, ctx, dt = self._state, self.geometry, self._ctx, self.dt
        positions = self.atoms.arrays["positions"]
        _numba.first_half(s.X, s.V, s.q, s.p, ctx.F, ctx.tau, self._inv_mass, self._inv4i, dt,
                          g.body_coordinates, self._bounds, g.order, self._r, positions)
        if len(self._free):
            s.v += (0.5 * dt) * ctx.f / self._free_masses[:, None]
            s.x += dt * s.v
            positions[self._free] = s.x
        forces = self._get_forces()
        momenta = self.atoms.arrays["momenta"]
        _numba.second_half(s.V, s.q, s.p, ctx.F, ctx.tau, self._inv_mass, self._inv_moments, dt,
                           forces, self._bounds, g.order, g.atom_masses, self._r, momenta)
        if len(self._free):
            ctx.f = forces[self._free]
            s.v += (0.5 * dt) * ctx.f / self._free_masses[:, None]
            momenta[self._free] = self._free_masses[:, None] * s.v

    # ------------------------------------------------------------ forces
    def _get_forces(self):
        """Call the calculator on the current positions and check the result."""
        forces = np.asarray(self.atoms.get_forces(md=True), dtype=float)
        if forces.shape != (len(self.atoms), 3):
            raise ValueError(
                f"calculator returned forces of shape {forces.shape}, "
                f"expected {(len(self.atoms), 3)}"
            )
        # One reduction: a NaN or an infinity anywhere makes the sum non-finite.
        if not np.isfinite(forces.sum()):
            bad = np.flatnonzero(~np.isfinite(forces).all(axis=1))
            raise NonFiniteForceError(
                f"calculator returned non-finite forces on atom(s) {bad[:10].tolist()} "
                f"after step {self.nsteps}; the atoms are left at step {self.nsteps}"
            )
        return forces

    def _evaluate_forces(self):
        """Place the atoms from the state, call the calculator, reduce to bodies."""
        self._place_atoms()
        forces = self._get_forces()
        ctx = self._ctx
        ctx.F, ctx.tau = ops.reduce_forces(forces, self._r, self.geometry)
        ctx.f = forces[self._free]

    # ------------------------------------------------------------ atoms <-> state
    def _place_atoms(self):
        """Write rigid positions of the current state to the atoms."""
        s, g = self._state, self.geometry
        positions = self.atoms.arrays["positions"]
        if self.backend == "numba":
            # The same arithmetic as the step's, so a restored state gives
            # bit-identical positions.
            _numba.place(s.X, s.q, g.body_coordinates, self._bounds, g.order, self._r, positions)
        else:
            self._r, positions[g.order] = ops.place_atoms(s, g)
        positions[self._free] = s.x

    def _write_momenta(self):
        """Write rigid momenta of the current state to the atoms (positions placed already)."""
        s, g = self._state, self.geometry
        momenta = self.atoms.arrays["momenta"]
        if self.backend == "numba":
            _numba.momenta(s.V, s.q, s.p, self._inv_moments, self._bounds, g.order,
                           g.atom_masses, self._r, momenta)
        else:
            momenta[g.order] = g.atom_masses[:, None] * ops.atom_velocities(s, self._r, g)
        momenta[self._free] = self._free_masses[:, None] * s.v

    def _write_atoms(self):
        """Write positions and rigid momenta of the current state to the atoms."""
        self._place_atoms()
        self._write_momenta()
        self._remember_atoms()

    def _remember_atoms(self):
        self._synced = (self.atoms.positions.copy(), self.atoms.get_momenta())

    def _read_momenta(self, previous=None):
        """Project the atoms' velocities onto rigid motion of the bodies.

        With ``previous`` (the momenta last written to the atoms, positions
        unchanged since), a body whose atom momenta were all scaled by one
        factor (a velocity flip, a rescaling) has its whole momentum scaled
        instead of projected afresh.  This keeps, bit for bit, the axial
        NO_SQUISH momentum of a linear body, which its atoms' velocities
        cannot express, so that flipping velocities reverses a run exactly.
        """
        s, g, atoms = self._state, self.geometry, self.atoms
        momenta = atoms.get_momenta()
        ke_atoms = 0.5 * np.sum(momenta**2 / self.masses)
        r, _ = ops.place_atoms(s, g)
        V, L_body = ops.rigid_projection(momenta[g.order], r, s.q, g)
        p = ops.conjugate_momentum(s.q, L_body)
        if previous is not None:
            scale, uniform = ops.uniform_rescale(momenta[g.order], previous[g.order], g)
            V = np.where(uniform[:, None], scale[:, None] * s.V, V)
            p = np.where(uniform[:, None], scale[:, None] * s.p, p)
        s.V, s.p = V, p
        s.v = momenta[self._free] / self._free_masses[:, None]
        ke_rigid = self.get_translational_kinetic_energy() + self.get_rotational_kinetic_energy()
        self.removed_kinetic_energy = float(ke_atoms - ke_rigid)
        # Rigid input loses only roundoff (~1e-16 of the kinetic energy).
        if self.removed_kinetic_energy > 1e-10 * ke_atoms + 1e-12:
            warnings.warn(
                f"RigidVerlet: projecting the atoms' velocities onto rigid-body motion "
                f"removed {self.removed_kinetic_energy:.6g} eV of kinetic energy "
                f"({100 * self.removed_kinetic_energy / ke_atoms:.3g}% of {ke_atoms:.6g} eV)",
                stacklevel=3,
            )
        self._backup = s.copy()

    def _read_positions(self):
        """Refit centres of mass and orientations to the atoms' positions."""
        s, g, atoms = self._state, self.geometry, self.atoms
        x = unwrap_bodies(atoms, g.order, g.starts, g.atom_body)
        if g.n_bodies:
            X, q, residual = ops.fit_bodies(x, g)
            worst = int(np.argmax(residual))
            if residual[worst] > FIT_TOLERANCE:
                warnings.warn(
                    f"RigidVerlet: the atoms of body {worst} are {residual[worst]:.3g} Å "
                    "from a rigid image of the body; they were moved onto it",
                    stacklevel=3,
                )
            s.X, s.q = X, q
        s.x = atoms.positions[self._free].copy()

    def _sync_from_atoms(self):
        """Pick up changes the user made to the Atoms since our last write."""
        atoms = self.atoms
        if len(atoms) != len(self.bodies.body_ids):
            raise ValueError(
                f"the atoms changed from {len(self.bodies.body_ids)} to {len(atoms)}; "
                "create a new RigidVerlet"
            )
        if not np.array_equal(atoms.get_masses(), self.masses[:, 0]):
            raise ValueError("the atoms' masses changed; create a new RigidVerlet")
        if not any(isinstance(c, RigidBodyDOF) for c in atoms.constraints):
            atoms.constraints = list(atoms.constraints) + [
                RigidBodyDOF(3 * len(atoms) - self.degrees_of_freedom)]
        positions, momenta = self._synced
        moved = not np.array_equal(atoms.positions, positions)
        kicked = not np.array_equal(atoms.get_momenta(), momenta)
        if moved:
            self._read_positions()
        if moved or kicked:
            self._read_momenta(previous=None if moved else momenta)
            self._write_atoms()
            self._ctx.scratch.clear()

    # ------------------------------------------------------------ per-body state
    @property
    def com_positions(self):
        """Centres of mass of the bodies (Å), unwrapped, shape (n_bodies, 3)."""
        return self._state.X.copy()

    @property
    def com_velocities(self):
        """Centre-of-mass velocities (Å per ASE time unit), shape (n_bodies, 3)."""
        return self._state.V.copy()

    @property
    def quaternions(self):
        """Orientations ``(w, x, y, z)``, body to lab frame, shape (n_bodies, 4)."""
        return self._state.q.copy()

    @property
    def moments_of_inertia(self):
        """Principal moments (amu Å²), ascending, shape (n_bodies, 3)."""
        return self.geometry.moments.copy()

    @property
    def angular_momenta(self):
        """Lab-frame angular momenta about the centres of mass, shape (n_bodies, 3).

        Units amu Å² per ASE time unit.
        """
        s = self._state
        return quat.rotate(s.q, ops.body_angular_momentum(s.q, s.p))

    @property
    def angular_velocities(self):
        """Lab-frame angular velocities (rad / ASE time), shape (n_bodies, 3)."""
        s = self._state
        return ops.angular_velocity(s.q, s.p, self.geometry.moments)

    @property
    def translational_kinetic_energies(self):
        r"""Per-body :math:`\tfrac12 M |V|^2` (eV), shape (n_bodies,)."""
        return 0.5 * self.geometry.mass * np.sum(self._state.V**2, axis=1)

    @property
    def rotational_kinetic_energies(self):
        r"""Per-body rotational energy (eV), shape (n_bodies,).

        :math:`\tfrac12 \sum_k L_{b,k}^2 / I_k` over the axes with :math:`I_k > 0`.
        """
        s, moments = self._state, self.geometry.moments
        L_body = ops.body_angular_momentum(s.q, s.p)
        safe = np.where(moments > 0, moments, 1.0)
        return 0.5 * np.sum(np.where(moments > 0, L_body**2 / safe, 0.0), axis=1)

    def get_angular_momentum(self):
        r"""Total angular momentum about the origin (amu Å² / ASE time), shape (3,).

        :math:`\sum_b (X_b \times M_b V_b + R(q_b) L_{b}) + \sum_{free} x \times m v`,
        with :math:`L_b` from the NO_SQUISH momentum.  For a linear body this
        includes the axial component that NO_SQUISH's splitting builds up (as in
        LAMMPS), which atom velocities cannot show; this total, not the atoms'
        :math:`\sum_i x_i \times p_i`, is what the integrator conserves.
        """
        s, g = self._state, self.geometry
        L = np.cross(s.X, g.mass[:, None] * s.V).sum(axis=0) + self.angular_momenta.sum(axis=0)
        return L + np.cross(s.x, self._free_masses[:, None] * s.v).sum(axis=0)

    def get_translational_kinetic_energy(self):
        """Kinetic energy of the centres of mass plus that of the point particles (eV)."""
        free = 0.5 * np.sum(self._free_masses[:, None] * self._state.v**2)
        return float(self.translational_kinetic_energies.sum() + free)

    def get_rotational_kinetic_energy(self):
        """Rotational kinetic energy of all bodies (eV)."""
        return float(self.rotational_kinetic_energies.sum())
