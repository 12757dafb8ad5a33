r"""The backend of a dynamics: the NumPy reference or the compiled kernels, chosen once.

A dynamics (or a body link) resolves its ``backend=`` argument once, at
construction (:func:`resolve_backend`), to one of two objects: :data:`NUMPY`,
the reference (NumPy array operations, :mod:`rigidmd.core.operators` and
:mod:`rigidmd.core.observables`), or :data:`NUMBA`, the compiled loops (numba).
The body link carries it (``link.backend``), and the record, the force
evaluator, the stepper and the coupling parts reach it through the link.  Every
operation that has a compiled form is a method of the backend with the same
signature on both, so a call site reads ``backend.kinetic_tensor(state, model)``
and holds no branch: this module is the only place that tells the two apart
(``tests/core/test_backend.py`` walks every other module's syntax tree to keep it so).

Naming rule.  Each package's compiled kernels live in ``<package>/_numba.py``
(:mod:`rigidmd.core._numba`, :mod:`rigidmd.couplings._numba`,
:mod:`rigidmd.relax._numba`, :mod:`rigidmd.lammps._numba`), and a kernel is
named as the NumPy reference it replaces; a package above the core keeps those
references in ``<package>/_numpy.py`` (:mod:`rigidmd.couplings._numpy`,
:mod:`rigidmd.lammps._numpy`), same names, same arguments.  An operation of
the backend has that name too: :data:`NUMPY` runs the reference, :data:`NUMBA`
the kernel.  Such a pair is registered with the decorator :func:`reference_of`
on the reference (or :func:`register`, for a pair of methods whose two sides
cannot take the same arguments).  The core's own operations are methods of
:class:`Backend` (calling :mod:`rigidmd.core.operators` and
:mod:`rigidmd.core.observables`) and :class:`CompiledBackend` (calling
:mod:`rigidmd.core._numba`), which adapt the arguments.  :func:`operations`
lists every operation; ``tests/core/test_backend.py`` runs each on random inputs on
both backends and compares.  (The relaxation's loops, :mod:`rigidmd.relax._numba`,
have no reference: they are the one implementation, the same without numba.)

A package above :mod:`rigidmd.core` (the couplings) registers its own pairs
when it is imported, so that this module imports nothing above it.

Without numba the compiled backend is unavailable: ``backend=None`` resolves
to :data:`NUMPY` and ``backend="numba"`` is refused, as before.
"""

from collections.abc import Callable

import numpy as np
from ase.stress import voigt_6_to_full_3x3_stress

from rigidmd.core import _numba
from rigidmd.core import observables as obs
from rigidmd.core import operators as ops

__all__ = ["Backend", "CompiledBackend", "NUMPY", "NUMBA", "resolve_backend", "register",
           "reference_of", "operations"]

#: The operations registered by packages above the core: name -> (reference, kernel).
_REGISTERED: dict[str, tuple[Callable, Callable]] = {}

#: The operations the core defines as methods (both backends).
_CORE = ("place", "write_momenta", "largest_angular_speed", "kinetic_tensor",
         "rotational_energy", "congruence", "net_force", "molecular_virial",
         "cell_clearly_fits", "scheme_kernel", "step_function", "equal_or_close")


class Backend:
    """The NumPy reference backend (and the base of the compiled one).

    Attributes
    ----------
    name : str
        ``"numpy"`` or ``"numba"``: what :attr:`rigidmd.RigidDynamics.backend`
        reports and a checkpoint stores.
    """

    name = "numpy"

    def __repr__(self) -> str:
        return f"<rigidmd backend {self.name!r}>"

    def __reduce__(self):
        return resolve_backend, (self.name,)

    # ------------------------------------------------------------ body link
    def place(self, state, model, r, positions) -> np.ndarray:
        """Place the body atoms of ``state`` into ``positions`` (in ``model.order``); returns
        the lab displacements ``r`` (filled in place when given, on the compiled backend)."""
        r, positions[model.order] = ops.place_atoms(state, model)
        return r

    def write_momenta(self, state, model, r, momenta) -> None:
        """Write the rigid momenta of the body atoms (placed with ``r``) into ``momenta``."""
        momenta[model.order] = model.atom_masses[:, None] * ops.atom_velocities(state, r, model)

    def largest_angular_speed(self, state, model) -> tuple[int, float]:
        """The body turning fastest and its :math:`|\\omega|` (rad / ASE time)."""
        return obs.largest_angular_speed(state, model)

    # ------------------------------------------------------------ record
    def kinetic_tensor(self, state, model) -> np.ndarray:
        """Translational kinetic tensor (eV, 3x3) of the bodies and point particles."""
        return obs.kinetic_tensor(state, model)

    def rotational_energy(self, state, model) -> float:
        """Rotational kinetic energy of the bodies (eV)."""
        return obs.rotational_kinetic_energy(state, model)

    @staticmethod
    def congruence(F: np.ndarray, K: np.ndarray) -> np.ndarray:
        """:math:`F K F^\\mathsf{T}` of 3x3 matrices (the kernel itself on the compiled
        backend: no call in between, twice per MTK step)."""
        return F @ K @ F.T

    def net_force(self, F: np.ndarray, f: np.ndarray) -> tuple[float, float]:
        """``(|sum of the forces|, sum of their magnitudes)`` of bodies and point particles."""
        net = float(np.linalg.norm(F.sum(axis=0) + f.sum(axis=0)))
        return net, float(np.abs(F).sum() + np.abs(f).sum())

    # ------------------------------------------------------------ force evaluator
    def molecular_virial(self, stress, volume, r, forces, model) -> np.ndarray:
        """The molecular virial (eV, 3x3) from a stress (3x3 or Voigt, eV/Å³); see
        :func:`rigidmd.core.observables.molecular_virial`."""
        if stress.shape == (6,):
            stress = voigt_6_to_full_3x3_stress(stress)
        return obs.molecular_virial(stress, volume, r, forces, model)

    def cell_clearly_fits(self, model, cell, pbc) -> bool:
        """Whether the bodies fit ``cell`` with a margin, so that the full check
        (:func:`rigidmd.core.bodies.check_bodies_fit`) can be skipped.  The reference
        always runs the full check: False."""
        return False

    # ------------------------------------------------------------ calculator checks
    def equal_or_close(self, a: np.ndarray, b: np.ndarray, tol: float) -> bool:
        """Whether float arrays ``a`` and ``b`` (same shape) are equal or close everywhere
        (``numpy.allclose(a, b, rtol=tol, atol=tol)``; see
        :func:`rigidmd.core.checks.changed_properties`)."""
        return bool(np.array_equal(a, b) or np.allclose(a, b, tol, tol))

    # ------------------------------------------------------------ schemes
    def scheme_kernel(self, scheme) -> Callable | None:
        """The fused kernel that runs ``scheme`` on this backend, or None (its operators)."""
        return None

    def step_function(self, scheme) -> Callable:
        """``f(ctx, dt)`` advancing ``ctx`` by one step of ``scheme``."""
        return scheme.run


class CompiledBackend(Backend):
    """The compiled backend: the numba kernels of each package's ``_numba`` module."""

    name = "numba"

    def place(self, state, model, r, positions):
        if r is None:
            r = np.empty((len(model.order), 3))
        _numba.place(state.X, state.q, model.body_coordinates, model.bounds, model.order, r,
                     positions)
        return r

    def write_momenta(self, state, model, r, momenta):
        _numba.momenta(state.V, state.q, state.p, model.inv_moments, model.bounds, model.order,
                       model.atom_masses, r, momenta)

    def largest_angular_speed(self, state, model):
        b, speed = _numba.largest_angular_speed(state.q, state.p, model.inv_moments)
        return int(b), float(speed)

    def kinetic_tensor(self, state, model):
        return _numba.kinetic_tensor(state.V, state.v, model.mass, model.free_masses)

    def rotational_energy(self, state, model):
        return _numba.rotational_energy(state.q, state.p, model.inv_moments)

    congruence = staticmethod(_numba.congruence)

    def net_force(self, F, f):
        net, size = _numba.net_force(F, f)
        return float(net), float(size)

    def molecular_virial(self, stress, volume, r, forces, model):
        if stress.shape == (6,):
            return _numba.molecular_virial_voigt(stress, volume, r, forces, model.order)
        return -volume * stress - _numba.intramolecular_virial(r, forces, model.order)

    def cell_clearly_fits(self, model, cell, pbc):
        # The rule's arithmetic with a margin; the full check near the edge.
        return bool(4.0 * model.radius < (1.0 - 1e-12) * _numba.smallest_width(cell, pbc))

    def equal_or_close(self, a, b, tol):
        # One compiled pass, stopping at the first change (the positions at every
        # call: 28 us for the NumPy test of all arrays inside a 216-water step).
        return bool(_numba.equal_or_close(a.reshape(-1), b.reshape(-1), tol))

    def scheme_kernel(self, scheme):
        return scheme.kernel

    def step_function(self, scheme):
        kernel = scheme.kernel
        return scheme.run if kernel is None else kernel


#: The NumPy reference backend.
NUMPY = Backend()
#: The compiled backend (usable only when numba is installed: :data:`AVAILABLE`).
NUMBA = CompiledBackend()
#: Whether the compiled backend can run (numba imports).
AVAILABLE = _numba.AVAILABLE


def resolve_backend(backend: "str | Backend | None" = None) -> Backend:
    """The backend a dynamics runs on, decided once: :data:`NUMBA` or :data:`NUMPY`.

    ``None`` picks numba when it is installed; an unknown name, or numba
    asked for but missing, is a ValueError.  A backend object is returned as is.
    """
    if isinstance(backend, Backend):
        backend = backend.name
    if backend is None:
        return NUMBA if AVAILABLE else NUMPY
    if backend not in ("numba", "numpy"):
        raise ValueError(f"backend must be 'numba' or 'numpy', got {backend!r}")
    if backend == "numba" and not AVAILABLE:
        raise ValueError("backend='numba' but numba is not installed")
    return NUMBA if backend == "numba" else NUMPY


def register(name: str, reference: Callable, kernel: Callable) -> None:
    """Make ``name`` an operation of both backends: ``reference`` on :data:`NUMPY`,
    ``kernel`` on :data:`NUMBA` (both called with the same arguments, no ``self``).

    For a package above the core (its import registers its pairs).  Registering a
    name twice with other functions is an error.
    """
    known = _REGISTERED.get(name)
    if known is not None and known != (reference, kernel):
        raise ValueError(f"backend operation {name!r} is registered already")
    if name in _CORE:
        raise ValueError(f"backend operation {name!r} is one of the core's")
    _REGISTERED[name] = (reference, kernel)
    setattr(Backend, name, staticmethod(reference))
    setattr(CompiledBackend, name, staticmethod(kernel))


def reference_of(kernel: Callable) -> Callable:
    """Decorator: the function below is the NumPy reference of ``kernel``, which has its
    name (the naming rule) and takes the same arguments; both become an operation of
    the backends under that name (:func:`register`)."""
    def decorate(reference: Callable) -> Callable:
        name = reference.__name__
        if getattr(kernel, "__name__", name) != name:
            raise ValueError(f"the kernel of {name!r} is named {kernel.__name__!r}")
        register(name, reference, kernel)
        return reference
    return decorate


def operations() -> tuple[str, ...]:
    """The names of every operation of the backends: the core's and those registered."""
    return _CORE + tuple(sorted(_REGISTERED))
