r"""The arrays a time step changes, packed in one buffer, and their version counters.

:class:`RigidState` is the one owner of the simulated system's changing part:
the bodies' centres, velocities, orientations and momenta, the point
particles and the cell.  Every change of its arrays moves a version counter,
:attr:`RigidState.versions`: one for the positions and orientations
(``X, q, x``), one for the momenta (``V, p, v``), one for the cell.  What is
derived from the state (the per-step record's volume, kinetic tensor and
rotational energy, :mod:`rigidmd.core.record`) is kept with the versions it
was computed at and computed again when they moved: nobody invalidates a
cache by hand.

How a change moves the counters:

* assigning a field (``state.V = V``, and so also ``state.V += dV``, which
  Python runs as an assignment) copies into the field's view and moves its
  counter;
* :meth:`RigidState.copy_into` (a rollback, a Monte Carlo move accepted) moves
  every counter of the target;
* code that writes into the arrays in place, without an assignment
  (``state.V[...] = ...``, a compiled kernel writing :attr:`RigidState.data`,
  :func:`rigidmd.core.operators.free_rotor`), calls :meth:`RigidState.touched`
  for what it wrote, before anything reads a derived quantity: the kernel
  drivers of :mod:`rigidmd.core.stepcontext`, the free rotor, and a coupling
  part that writes velocities in place (the Langevin thermostats);
* a known scaling of the velocities written in place (a thermostat's, a
  barostat's friction) goes through
  :meth:`rigidmd.core.record.StepRecord.scaled`, which moves the momenta
  counter and carries the record's sums to the new version, scaled, instead of
  summing again.

A counter only grows, so a version is never reused; moving one without a
change costs a recomputation, never a wrong value.  The body model (masses,
moments, reference frames) does not change during a run:
:meth:`rigidmd.core.dynamics.RigidDynamics.set_state` replaces it in place and
assigns every field of the state, so every counter moves with it.
"""

import numpy as np

__all__ = ["RigidState", "STATE_FIELDS"]

#: The state's arrays, in order (their order in :attr:`RigidState.data`).
STATE_FIELDS = ("X", "V", "q", "p", "x", "v", "cell")
#: Columns of each field: per body (X, V, q, p), per free atom (x, v), the cell.
_WIDTHS = {"X": 3, "V": 3, "q": 4, "p": 4, "x": 3, "v": 3}
#: Each field's counter in :attr:`RigidState.versions`: positions 0, momenta 1, cell 2.
_KIND = {"X": 0, "q": 0, "x": 0, "V": 1, "p": 1, "v": 1, "cell": 2}


class RigidState:
    r"""Dynamical state of the rigid bodies, the free atoms and the cell.

    All seven arrays are C-contiguous views into one buffer, :attr:`data`,
    so that a copy of the whole state (the rollback's backup, at every step)
    is one ``numpy.copyto``.  Assigning to a field copies into its view: the
    arrays never change identity, and an array of another shape is refused.

    Parameters
    ----------
    X, V, q, p, x, v, cell : array_like
        Copied into the buffer; shapes as below.

    Attributes
    ----------
    X : numpy.ndarray, shape (n_bodies, 3)
        Centres of mass (Å), unwrapped.
    V : numpy.ndarray, shape (n_bodies, 3)
        Centre-of-mass velocities (Å per ASE time unit).
    q : numpy.ndarray, shape (n_bodies, 4)
        Orientations ``(w, x, y, z)``; :math:`R(q)` maps body to lab frame.
    p : numpy.ndarray, shape (n_bodies, 4)
        NO_SQUISH conjugate quaternion momenta
        :math:`p = 2\, q \otimes (0, L_b)` (amu Å² per ASE time unit), with
        :math:`L_b` the body-frame angular momentum.
    x : numpy.ndarray, shape (n_free, 3)
        Positions of the atoms that are point particles (Å).
    v : numpy.ndarray, shape (n_free, 3)
        Their velocities (Å per ASE time unit).
    cell : numpy.ndarray, shape (3, 3)
        Cell vectors as rows (Å), as :attr:`ase.Atoms.cell`; only a barostat
        changes it.
    data : numpy.ndarray, shape (14 n_bodies + 6 n_free + 9,)
        The buffer: ``X, V, q, p, x, v, cell`` one after the other, each
        flattened in C order.
    versions : list of int
        ``[positions, momenta, cell]``: counters that grow at every change of
        ``X, q, x``, of ``V, p, v`` and of ``cell`` (see the module's text).
    """

    # Plain slots: reading a field is as cheap as an attribute (the step reads them often).
    __slots__ = ("data", "versions", *STATE_FIELDS)

    def __init__(self, X, V, q, p, x, v, cell):
        arrays = {name: np.asarray(value, dtype=float) for name, value in
                  zip(STATE_FIELDS, (X, V, q, p, x, v, cell), strict=True)}
        n_bodies, n_free = len(arrays["X"]), len(arrays["x"])
        shapes = {name: ((n_bodies if name in "XVqp" else n_free), width)
                  for name, width in _WIDTHS.items()}
        shapes["cell"] = (3, 3)
        for name, shape in shapes.items():
            if arrays[name].shape != shape:
                raise ValueError(f"RigidState.{name} must have shape {shape}, got "
                                 f"{arrays[name].shape}")
        data = np.empty(sum(int(np.prod(s)) for s in shapes.values()))
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "versions", [0, 0, 0])
        start = 0
        for name in STATE_FIELDS:
            size = int(np.prod(shapes[name]))
            view = data[start:start + size].reshape(shapes[name])
            view[...] = arrays[name]
            object.__setattr__(self, name, view)
            start += size

    def __setattr__(self, name, value):
        """``state.X = array`` copies into the view (same shape only); ``data`` is fixed."""
        if name not in STATE_FIELDS:
            raise AttributeError(f"RigidState.{name} cannot be assigned")
        view = getattr(self, name)
        value = np.asarray(value, dtype=float)
        if value.shape != view.shape:
            raise ValueError(f"RigidState.{name} has shape {view.shape}; cannot assign an array "
                             f"of shape {value.shape}")
        view[...] = value
        self.versions[_KIND[name]] += 1

    def touched(self, positions: bool = False, momenta: bool = False,
                cell: bool = False) -> None:
        """Arrays were written in place: move the counters of what was written.

        ``positions``: ``X, q, x``; ``momenta``: ``V, p, v``; ``cell``: ``cell``.
        """
        versions = self.versions
        if positions:
            versions[0] += 1
        if momenta:
            versions[1] += 1
        if cell:
            versions[2] += 1

    def __repr__(self) -> str:
        return (f"RigidState(n_bodies={len(self.X)}, n_free={len(self.x)}, "
                f"cell={self.cell.tolist()})")

    def copy(self) -> "RigidState":
        """A deep copy (its own buffer)."""
        return RigidState(self.X, self.V, self.q, self.p, self.x, self.v, self.cell)

    def copy_into(self, other: "RigidState") -> None:
        """Overwrite ``other``'s arrays in place with this state's values (one copy); every
        counter of ``other`` moves."""
        np.copyto(other.data, self.data)
        versions = other.versions
        versions[0] += 1
        versions[1] += 1
        versions[2] += 1
