r"""Time steps as lists of named operators, and the built-in integrators.

As in exaDEM, a time step is a list of operators, each with parameters; every
operator that advances time takes ``dt_scale``, a factor on the time step.  A
scheme can be written as a Python list or as YAML::

    - translational_kick: {dt_scale: 0.5}
    - drift
    - rotational_kick: {dt_scale: 0.5}
    - no_squish_rotate
    - compute_force
    - translational_kick: {dt_scale: 0.5}
    - rotational_kick: {dt_scale: 0.5}

(the built-in ``no_squish``).  The built-in integrators are such lists, so
each piece of math (in :mod:`rigidmd.core.operators`) exists once:

============================  ======================================================  ======
name                          what it is                                              order
============================  ======================================================  ======
``no_squish`` (default)       NO_SQUISH, LAMMPS ``fix rigid/nve``; symplectic         2
``richardson``                Richardson iteration, LAMMPS ``fix rigid``              2
``rozmanov_kusalik``          iterated quaternion velocity Verlet (RMPCDMD)           2
``pcdm``                      Zhao & van Wachem predictor–corrector, 2 forces/step    2
``exadem``                    exaDEM operator scheme (DEM; heats molecules)           1
``baoab``                     NO_SQUISH cut at its middle: B A (middle) A B; with     2
                              ``RigidLangevinBAOAB``'s O step there, BAOAB
============================  ======================================================  ======

Operators
---------
Translation (bodies' centres of mass and free atoms):
``translational_kick`` (:math:`V \mathrel{+}= hF/M`), ``drift`` (:math:`X \mathrel{+}= hV`),
and exaDEM's ``push_f_v_r`` (:math:`X \mathrel{+}= hV + \tfrac{h^2}{2}a`),
``push_f_v`` (:math:`V \mathrel{+}= \tfrac h2 a`), ``force_to_accel`` (:math:`a = F/M`).
Rotation: ``rotational_kick`` (:math:`L \mathrel{+}= h\tau`), ``no_squish_rotate``,
``richardson_rotate``, ``rozmanov_kusalik_rotate`` (with ``tol``, ``max_iter``),
``pcdm_predict`` / ``pcdm_correct``, and exaDEM's ``push_to_quaternion``,
``push_to_angular_acceleration``, ``push_to_angular_velocity``.  Forces:
``compute_force`` (place atoms, call the calculator, reduce to body forces and
torques), ``reset_force_moment``.  Couplings: ``middle`` (the coupling parts that act
in the middle of the step, e.g. the O step of
:class:`~rigidmd.couplings.baoab.LangevinBAOABThermostat`, for a time :math:`h`; nothing
without such a part).  Groups: ``combined_compute_prolog`` and
``combined_compute_epilog`` (exaDEM's merged operators).  Here
:math:`h = \mathrm{dt\_scale}\cdot\Delta t`.
"""

from dataclasses import dataclass

import numpy as np

from rigidmd.core import stepcontext as sc

__all__ = ["Scheme", "OPERATORS", "BUILTIN_SCHEMES", "resolve_scheme", "load_yaml",
           "scheme_with_middle", "SchemeParameterError", "SchemeParameterTypeError"]


class SchemeParameterError(ValueError):
    """A parameter of one scheme entry refused: ``"scheme entry I (OPERATOR): PARAMETER
    REASON"``, with :attr:`operator`, :attr:`parameter` and :attr:`reason` kept, so that a
    caller can name the option in its own words (the configuration's
    ``integrator_options.tol``)."""

    def __init__(self, entry: int, operator: str, parameter: str, reason: str):
        super().__init__(f"scheme entry {entry} ({operator}): {parameter} {reason}")
        self.operator, self.parameter, self.reason = operator, parameter, reason


class SchemeParameterTypeError(SchemeParameterError, TypeError):
    """A scheme parameter that is not a number (a TypeError as well)."""


@dataclass(frozen=True)
class Operator:
    """A named operator: its function, its parameters with defaults, what it does."""

    function: object
    params: dict
    timed: bool = True       # takes dt_scale
    moves: bool = False      # changes positions or orientations
    forces: bool = False     # calls the calculator
    group: tuple = ()        # a merged operator: the names it runs, in order


def _op(function, moves=False, timed=True, **params):
    return Operator(function, params, timed=timed, moves=moves)


OPERATORS = {
    "translational_kick": _op(sc.apply_translational_kick, dt_scale=0.5),
    "drift": _op(sc.apply_drift, moves=True, dt_scale=1.0),
    "rotational_kick": _op(sc.apply_rotational_kick, dt_scale=0.5),
    "no_squish_rotate": _op(sc.apply_no_squish_rotate, moves=True, dt_scale=1.0),
    "richardson_rotate": _op(sc.apply_richardson_rotate, moves=True, dt_scale=1.0),
    "rozmanov_kusalik_rotate": _op(sc.apply_rozmanov_kusalik_rotate, moves=True, dt_scale=1.0,
                                   tol=1e-13, max_iter=100),
    "pcdm_predict": _op(sc.apply_pcdm_predict, moves=True, dt_scale=1.0),
    "pcdm_correct": _op(sc.apply_pcdm_correct, moves=True, dt_scale=1.0),
    "middle": _op(sc.apply_middle, dt_scale=1.0),
    "compute_force": Operator(sc.apply_compute_force, {}, timed=False, forces=True),
    "reset_force_moment": Operator(sc.apply_reset_force_moment, {}, timed=False),
    "force_to_accel": Operator(sc.apply_force_to_accel, {}, timed=False),
    "push_f_v_r": _op(sc.apply_push_f_v_r, moves=True, dt_scale=1.0),
    "push_f_v": _op(sc.apply_push_f_v, dt_scale=1.0),
    "push_to_quaternion": _op(sc.apply_push_to_quaternion, moves=True, dt_scale=1.0),
    "push_to_angular_acceleration": Operator(sc.apply_push_to_angular_acceleration, {},
                                             timed=False),
    "push_to_angular_velocity": _op(sc.apply_push_to_angular_velocity, dt_scale=1.0),
    "combined_compute_prolog": Operator(None, {"dt_scale": 1.0}, moves=True, group=(
        "push_f_v_r", "push_f_v", "push_to_quaternion")),
    "combined_compute_epilog": Operator(None, {"dt_scale": 1.0}, group=(
        "push_to_angular_acceleration", "push_to_angular_velocity", "push_f_v")),
}

_NO_SQUISH = [("translational_kick", {"dt_scale": 0.5}), ("drift", {"dt_scale": 1.0}),
              ("rotational_kick", {"dt_scale": 0.5}), ("no_squish_rotate", {"dt_scale": 1.0}),
              ("compute_force", {}),
              ("translational_kick", {"dt_scale": 0.5}), ("rotational_kick", {"dt_scale": 0.5})]

BUILTIN_SCHEMES = {
    "no_squish": _NO_SQUISH,
    "richardson": [(name if name != "no_squish_rotate" else "richardson_rotate", params)
                   for name, params in _NO_SQUISH],
    # The iteration includes its own half kick of L (its predictor needs L at the start).
    "rozmanov_kusalik": [("translational_kick", {"dt_scale": 0.5}), ("drift", {"dt_scale": 1.0}),
                         ("rozmanov_kusalik_rotate", {"dt_scale": 1.0}), ("compute_force", {}),
                         ("translational_kick", {"dt_scale": 0.5}),
                         ("rotational_kick", {"dt_scale": 0.5})],
    # The midpoint torque is evaluated with the centres of mass at the
    # velocity-Verlet midpoint X + (dt/2) V(t + dt/2) and the orientations at
    # PCDM's predicted q'(dt/2); the force at the end of the step gives the
    # translation's second kick and the next step's start torque.
    "pcdm": [("translational_kick", {"dt_scale": 0.5}), ("drift", {"dt_scale": 0.5}),
             ("pcdm_predict", {"dt_scale": 1.0}), ("compute_force", {}),
             ("pcdm_correct", {"dt_scale": 1.0}), ("drift", {"dt_scale": 0.5}),
             ("compute_force", {}), ("translational_kick", {"dt_scale": 0.5})],
    # BAOAB (Leimkuhler & Matthews 2013): B(dt/2) A(dt/2) O(dt) A(dt/2) B(dt/2), the O
    # step being the coupling parts' middle; A is NO_SQUISH's drift and free rotor.
    "baoab": [("translational_kick", {"dt_scale": 0.5}), ("rotational_kick", {"dt_scale": 0.5}),
              ("drift", {"dt_scale": 0.5}), ("no_squish_rotate", {"dt_scale": 0.5}),
              ("middle", {"dt_scale": 1.0}),
              ("drift", {"dt_scale": 0.5}), ("no_squish_rotate", {"dt_scale": 0.5}),
              ("compute_force", {}),
              ("translational_kick", {"dt_scale": 0.5}), ("rotational_kick", {"dt_scale": 0.5})],
    "exadem": [("combined_compute_prolog", {"dt_scale": 1.0}), ("reset_force_moment", {}),
               ("compute_force", {}), ("force_to_accel", {}),
               ("combined_compute_epilog", {"dt_scale": 1.0})],
}


class Scheme:
    """A validated list of operators making one time step.

    :meth:`run` applies the operators in order (the readable NumPy path) or,
    for a scheme with a compiled :attr:`kernel`, the fused equivalent.

    Parameters
    ----------
    steps : list
        Each entry a name (``"drift"``), a one-key mapping
        (``{"drift": {"dt_scale": 0.5}}``) or a ``(name, params)`` pair.
        Omitted parameters take the operator's defaults.
    name : str, optional

    Raises
    ------
    ValueError
        An unknown operator or parameter (the message lists the known ones),
        a non-positive ``dt_scale``, a scheme that never calls
        ``compute_force``, or one that moves atoms after its last force call
        (the forces it leaves would not belong to the final positions).
    TypeError
        An entry or parameter of the wrong type.
    """

    def __init__(self, steps, name="custom"):
        if isinstance(steps, (str, bytes)) or not hasattr(steps, "__iter__"):
            raise TypeError(f"a scheme is a list of operators, got {type(steps).__name__}")
        self.name = name
        self.steps = [_parse_entry(i, entry) for i, entry in enumerate(steps)]
        expanded = self.expanded()
        force_calls = [i for i, (op, _) in enumerate(expanded) if op.forces]
        if not force_calls:
            raise ValueError(f"scheme {name!r} never evaluates forces: add 'compute_force'")
        moving = [n for n, (op, _) in zip(self._expanded_names(), expanded, strict=True)
                  if op.moves]
        last = force_calls[-1]
        after = [n for n, (op, _) in list(zip(self._expanded_names(), expanded,
                                               strict=True))[last + 1:] if op.moves]
        if after:
            raise ValueError(
                f"scheme {name!r} moves atoms ({after[0]}) after its last compute_force: "
                "the forces would not belong to the final positions"
            )
        self.moves = bool(moving)

    def _expanded_names(self):
        names = []
        for name, _ in self.steps:
            group = OPERATORS[name].group
            names += list(group) if group else [name]
        return names

    def expanded(self):
        """The steps with merged operators replaced by their members: ``[(Operator, params)]``."""
        out = []
        for name, params in self.steps:
            op = OPERATORS[name]
            if op.group:
                for member in op.group:
                    sub = OPERATORS[member]
                    out.append((sub, {k: v for k, v in params.items() if k in sub.params}))
            else:
                out.append((op, params))
        return out

    @property
    def force_calls_per_step(self):
        """How many times a step calls the calculator."""
        return sum(op.forces for op, _ in self.expanded())

    @property
    def kernel(self):
        """The compiled, fused implementation of this scheme, or None.

        The built-in ``no_squish`` and ``baoab`` (and any scheme equal to one, e.g.
        from YAML) have one: :func:`rigidmd.core.stepcontext.fused_no_squish` and
        :func:`rigidmd.core.stepcontext.fused_baoab`, which a dynamics on the numba
        backend runs.
        """
        try:
            return self._kernel
        except AttributeError:
            self._kernel = None
            for name, kernel in (("no_squish", sc.fused_no_squish),
                                 ("baoab", sc.fused_baoab)):
                if self.steps == [_parse_entry(i, e)
                                  for i, e in enumerate(BUILTIN_SCHEMES[name])]:
                    self._kernel = kernel
            return self._kernel

    @property
    def has_middle(self) -> bool:
        """Whether the scheme runs the ``middle`` operator (where parts may act mid-step)."""
        return any(name == "middle" for name, _ in self.steps)

    def run(self, ctx, dt):
        """Advance ``ctx`` by one step of ``dt`` (ASE time units), operator by operator.

        The compiled backend runs the fused :attr:`kernel` instead, where the
        scheme has one (:meth:`rigidmd.core.backend.Backend.step_function`).

        Parameters
        ----------
        ctx : StepContext
        dt : float
            The time step, read from the dynamics at every step.
        """
        for function, dt_scale, extra in self._compiled:
            if dt_scale is None:
                function(ctx)
            else:
                function(ctx, dt_scale * dt, **extra)

    @property
    def _compiled(self):
        """``[(function, dt_scale or None, other parameters)]``, built once."""
        try:
            return self._calls
        except AttributeError:
            self._calls = [
                (op.function, params["dt_scale"] if op.timed else None,
                 {k: v for k, v in params.items() if k != "dt_scale"})
                for op, params in self.expanded()]
            return self._calls

    def todict(self):
        """A JSON- and YAML-friendly description: ``[{name: params}, ...]``."""
        return [{name: dict(params)} if params else name for name, params in self.steps]

    def __eq__(self, other):
        return isinstance(other, Scheme) and self.steps == other.steps

    def __repr__(self):
        return f"Scheme({self.name!r}, {[name for name, _ in self.steps]})"


def _parse_entry(i, entry):
    if isinstance(entry, str):
        name, params = entry, {}
    elif isinstance(entry, dict) and len(entry) == 1:
        ((name, params),) = entry.items()
        params = {} if params is None else params
    elif isinstance(entry, (tuple, list)) and len(entry) == 2 and isinstance(entry[0], str):
        name, params = entry
    else:
        raise TypeError(
            f"scheme entry {i}: expected a name, {{name: {{params}}}} or (name, params), "
            f"got {entry!r}"
        )
    if name not in OPERATORS:
        raise ValueError(
            f"scheme entry {i}: unknown operator {name!r}; known: {', '.join(OPERATORS)}"
        )
    if not isinstance(params, dict):
        raise TypeError(f"scheme entry {i} ({name}): parameters must be a mapping, got {params!r}")
    op = OPERATORS[name]
    unknown = set(params) - set(op.params)
    if unknown:
        allowed = ", ".join(op.params) or "none"
        raise ValueError(
            f"scheme entry {i} ({name}): unknown parameter {sorted(unknown)[0]!r}; "
            f"it takes: {allowed}"
        )
    merged = dict(op.params) | dict(params)
    for key, value in merged.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SchemeParameterTypeError(i, name, key, f"must be a number, got {value!r}")
    if "dt_scale" in merged and not (np.isfinite(merged["dt_scale"])
                                     and merged["dt_scale"] > 0):
        raise SchemeParameterError(i, name, "dt_scale",
                                   f"must be positive, got {merged['dt_scale']!r}")
    if "tol" in merged and not merged["tol"] > 0:
        raise SchemeParameterError(i, name, "tol", "must be positive")
    if "max_iter" in merged:
        if int(merged["max_iter"]) != merged["max_iter"] or merged["max_iter"] < 1:
            raise SchemeParameterError(i, name, "max_iter", "must be a positive integer")
        merged["max_iter"] = int(merged["max_iter"])
    return name, merged


def load_yaml(path):
    """Read a scheme from a YAML file: a list of operators, or ``{scheme: [...]}``."""
    import yaml

    with open(path) as fh:
        data = yaml.safe_load(fh)
    if isinstance(data, dict) and set(data) == {"scheme"}:
        data = data["scheme"]
    if not isinstance(data, list):
        raise ValueError(f"{path}: expected a list of operators (or 'scheme:' and a list)")
    return Scheme(data, name=str(path))


def resolve_scheme(spec, **params):
    """Turn an integrator specification into a :class:`Scheme`.

    Parameters
    ----------
    spec : str, Scheme or list
        A built-in name (``"no_squish"``, ``"richardson"``,
        ``"rozmanov_kusalik"``, ``"pcdm"``, ``"exadem"``), a path to a YAML
        file (``.yaml`` / ``.yml``), a :class:`Scheme`, or a list of operators.
    **params
        Parameters for a built-in scheme's operators, e.g. ``tol`` and
        ``max_iter`` for ``rozmanov_kusalik``; each goes to every operator
        of the scheme that takes it.
    """
    if isinstance(spec, Scheme):
        scheme = spec
    elif isinstance(spec, str) and spec in BUILTIN_SCHEMES:
        steps = []
        used = set()
        for name, defaults in BUILTIN_SCHEMES[spec]:
            own = {k: v for k, v in params.items() if k in OPERATORS[name].params}
            used |= set(own)
            steps.append((name, defaults | own))
        unused = set(params) - used
        if unused:
            raise ValueError(f"integrator {spec!r} takes no parameter {sorted(unused)[0]!r}")
        return Scheme(steps, name=spec)
    elif isinstance(spec, str) and spec.endswith((".yaml", ".yml")):
        scheme = load_yaml(spec)
    elif isinstance(spec, str):
        raise ValueError(
            f"unknown integrator {spec!r}; built-in: {', '.join(BUILTIN_SCHEMES)}, "
            "or a .yaml file, or a list of operators"
        )
    else:
        scheme = Scheme(spec)
    if params:
        raise ValueError("integrator parameters go with a built-in name; "
                         "put them in the scheme's entries instead")
    return scheme



def scheme_with_middle(scheme: Scheme, integrator, kinds) -> Scheme:
    """The scheme a dynamics runs when coupling parts (of ``kinds``) act in its middle.

    Without such parts, or with a scheme that has a ``middle`` operator,
    ``scheme`` itself; for the default integrator ``"no_squish"``, ``baoab``
    (NO_SQUISH cut in two where the parts act); for any other, a ValueError in one
    line naming the part and the integrator.
    """
    if not kinds or scheme.has_middle:
        return scheme
    if isinstance(integrator, str) and integrator == "no_squish":
        return resolve_scheme("baoab")
    raise ValueError(f"thermostat {kinds[0]} acts in the middle of the step: the integrator "
                     f"needs a 'middle' operator (integrator='baoab'); {scheme.name!r} has none")
