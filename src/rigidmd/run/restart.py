"""Rebuild a rigid dynamics from a checkpoint file and continue exactly.

:mod:`rigidmd.core.checkpoint` reads and writes the file;
:class:`~rigidmd.core.dynamics.RigidDynamics` exports and restores its state;
:func:`load_checkpoint` joins the two.
"""

from rigidmd.core.checkpoint import Checkpoint, read_checkpoint
from rigidmd.core.dynamics import RigidDynamics
from rigidmd.core.schemes import Scheme

__all__ = ["load_checkpoint"]


def load_checkpoint(path, calculator, **kwargs) -> RigidDynamics:
    """Rebuild a rigid dynamics from a checkpoint, ready to continue exactly.

    Parameters
    ----------
    path : str, os.PathLike or rigidmd.core.checkpoint.Checkpoint
    calculator : ase.calculators.calculator.Calculator
        Attached to the rebuilt atoms (the checkpoint holds no calculator; one with
        ``set_checkpoint_state`` gets what its ``get_checkpoint_state`` gave).
    **kwargs
        ``trajectory``, ``logfile``, ``loginterval``, ``append_trajectory``, ...
        as for :class:`RigidDynamics`.

    Returns
    -------
    RigidDynamics
        At the checkpoint's step and time; ``dyn.atoms`` are new Atoms.  The
        class is :class:`RigidDynamics` with the stored coupling parts
        (``dyn.couplings``); as on the classes that build them
        (:class:`~rigidmd.RigidMCBarostat`, :class:`~rigidmd.RigidNPT`, the
        thermostat classes), the thermostat part is ``dyn.thermostat`` and the
        barostat part ``dyn.barostat`` when the run had one.
    """
    checkpoint = path if isinstance(path, Checkpoint) else read_checkpoint(path)
    saved = checkpoint.dynamics_state()
    atoms = checkpoint.atoms()
    atoms.calc = calculator
    calculator_state = checkpoint.meta.get("calculator_state")
    if calculator_state is not None and hasattr(calculator, "set_checkpoint_state"):
        calculator.set_checkpoint_state(calculator_state)
    scheme = Scheme(saved["scheme"], name=saved["scheme_name"])
    dyn = RigidDynamics(atoms, saved["dt"], bodies=saved["body_ids"], integrator=scheme,
                        backend=saved["backend"], couplings=checkpoint.couplings(),
                        **kwargs)
    dyn.set_state(saved)
    for part in dyn.couplings:
        if part.section in ("thermostat", "barostat"):
            setattr(dyn, part.section, part)
    return dyn
