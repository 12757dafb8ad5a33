"""Rebuild a rigid dynamics from a checkpoint file and continue exactly.

:mod:`rigidmd.core.checkpoint` reads and writes the file;
:class:`~rigidmd.core.dynamics.RigidDynamics` exports and restores its state;
:func:`load_checkpoint` joins the two, as an instance of the class that was saved
(:data:`CLASSES`).
"""

import warnings

import rigidmd.md as md
from rigidmd.core.checkpoint import Checkpoint, CheckpointError, read_checkpoint
from rigidmd.core.dynamics import RigidDynamics
from rigidmd.core.schemes import Scheme

__all__ = ["load_checkpoint", "saved_class", "CLASSES"]

#: The classes a checkpoint comes back as, by name: ``RigidDynamics`` and the classes of
#: :mod:`rigidmd.md`.  A class is found by its name, never imported from a module a file
#: names (a checkpoint makes rigidmd run no code of its choosing).
CLASSES = {cls.__name__: cls for cls in (RigidDynamics, *(getattr(md, name)
                                                           for name in md.__all__))}


def saved_class(classes: list[str]) -> tuple[type, str | None]:
    """The class to rebuild for a checkpoint's ``classes`` (the saved class and its bases,
    most derived first), and the saved class's name when it is not that one.

    The first name in :data:`CLASSES` wins: a user's subclass of ``RigidBussi`` comes
    back as a ``RigidBussi``, one of ``RigidDynamics`` as a ``RigidDynamics``; a
    checkpoint that names no class (written before the class was stored) as a
    ``RigidDynamics``.
    """
    classes = list(classes)
    for name in classes:
        if name in CLASSES:
            return CLASSES[name], (None if name == classes[0] else classes[0])
    return RigidDynamics, (classes[0] if classes else None)


#: Keywords of the dynamics a checkpoint's continuation takes from the checkpoint.
_DECIDED_BY_THE_CHECKPOINT = frozenset({"timestep", "integrator", "integrator_options",
                                        "bodies", "backend", "couplings"})


def load_checkpoint(path, calculator, dynamics_class: type | None = None,
                    **kwargs) -> RigidDynamics:
    """Rebuild a rigid dynamics from a checkpoint, of the class saved, ready to continue exactly.

    Parameters
    ----------
    path : str, os.PathLike or rigidmd.core.checkpoint.Checkpoint
    calculator : ase.calculators.calculator.Calculator
        Attached to the rebuilt atoms (the checkpoint holds no calculator; one with
        ``set_checkpoint_state`` gets what its ``get_checkpoint_state`` gave).
    dynamics_class : type, optional
        The class to rebuild, a subclass of :class:`RigidDynamics` (the user's own:
        built by its :meth:`~RigidDynamics.from_parts` around the stored parts,
        its ``__init__`` not run).  By default the class saved, found by name
        among rigidmd's (:data:`CLASSES`).
    **kwargs
        ``trajectory``, ``logfile``, ``loginterval``, ``append_trajectory``, ...
        as for :class:`RigidDynamics`.

    Returns
    -------
    RigidDynamics
        At the checkpoint's step and time; ``dyn.atoms`` are new Atoms.  An
        instance of the class that was saved (:class:`~rigidmd.RigidBussi`,
        :class:`~rigidmd.RigidNPT`, ..., :class:`RigidDynamics`), built around
        the stored coupling parts (:meth:`RigidDynamics.from_parts`), so its
        methods and properties work (``thermostat_work``, ``set_friction``,
        ``todict()``'s ``md-type``).  A class of the user's own, which rigidmd
        does not import, comes back as its nearest base that rigidmd has
        (``RigidBussi`` for a subclass of it, else :class:`RigidDynamics`), with
        a warning naming it; ``dynamics_class=`` gives it back as that class.  A checkpoint
        written before the class was stored comes back as :class:`RigidDynamics`.
        On a :class:`RigidDynamics` the thermostat part is ``dyn.thermostat`` and
        the barostat part ``dyn.barostat`` when the run had one, as on the classes.

    Raises
    ------
    rigidmd.core.checkpoint.CheckpointError
        The file cannot be read, or its parts are not those of the class it names.
    TypeError
        A keyword the checkpoint decides (``timestep``, ``integrator``, ``bodies``,
        ``backend``, ``couplings``): the continuation is the run saved.
    """
    decided = sorted(set(kwargs) & _DECIDED_BY_THE_CHECKPOINT)
    if decided:
        raise TypeError(f"load_checkpoint: {decided[0]} is the checkpoint's (the continuation "
                        "is the run saved); change it after loading where a setter allows "
                        "(set_timestep, set_temperature), or start a new run")
    checkpoint = path if isinstance(path, Checkpoint) else read_checkpoint(path)
    saved = checkpoint.dynamics_state()
    if dynamics_class is not None:
        if not (isinstance(dynamics_class, type) and issubclass(dynamics_class, RigidDynamics)):
            raise TypeError("dynamics_class must be a subclass of RigidDynamics, got "
                            f"{dynamics_class!r}")
        cls = dynamics_class
    else:
        cls, other = saved_class(saved["classes"])
        if other is not None:
            warnings.warn(f"checkpoint: the dynamics was a {other}, a class rigidmd does not "
                          f"rebuild; loaded as {cls.__name__} with its parts (pass "
                          f"dynamics_class={other} to continue as it)", stacklevel=2)
    parts = checkpoint.couplings()
    try:
        cls.check_parts(parts)  # before the calculator gets its state
    except ValueError as err:
        raise CheckpointError(f"checkpoint: {err}") from None
    atoms = checkpoint.atoms()
    atoms.calc = calculator
    calculator_state = checkpoint.meta.get("calculator_state")
    if calculator_state is not None and hasattr(calculator, "set_checkpoint_state"):
        calculator.set_checkpoint_state(calculator_state)
    scheme = Scheme(saved["scheme"], name=saved["scheme_name"])
    dyn = cls.from_parts(atoms, saved["dt"], parts, bodies=saved["body_ids"],
                         integrator=scheme, backend=saved["backend"], **kwargs)
    dyn.set_state(saved)
    for part in dyn.couplings:  # as the classes hold them, on a class that does not
        if part.section in ("thermostat", "barostat") and not hasattr(dyn, part.section):
            setattr(dyn, part.section, part)
    return dyn
