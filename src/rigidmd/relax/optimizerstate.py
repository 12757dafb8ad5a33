"""The state of a relaxation that stopped early, for a continuation that takes the same steps.

:func:`rigidmd.relax.filter.relax` writes it (``state_file``) when a
relaxation stops before converging, after a whole step: an observer raised
(a stop signal of ``rigidmd relax``), Ctrl-C stopped it or the step limit was
reached.  It holds the view's chart (:meth:`rigidmd.relax.filter.RigidFilter.get_state`: the
coordinates, the bodies' reference orientations, the energy and forces
already computed there) and the optimizer's memory where the optimizer has
one to give (:meth:`rigidmd.relax.lbfgs.RigidLBFGS.get_state`: its curvature
pairs, last point and the preconditioner's scales and matrix), with the
atoms' positions it belongs to.  A continuation from it takes the steps the
uninterrupted relaxation would have taken, bit for bit where the calculator
gives the same forces for the same positions, with no force call more.

The file is NumPy's ``.npz`` (float64 kept exactly), written as checkpoints are
(:func:`rigidmd.core.checkpoint.atomic_write`), so that a file of that name is always whole.
"""

from pathlib import Path

import numpy as np

from rigidmd.core.checkpoint import atomic_write

__all__ = ["keeps_memory", "write_state", "read_state", "state_matches", "resumed_state"]


def keeps_memory(optimizer) -> bool:
    """Whether ``optimizer`` (an ASE optimizer class) gives and takes its memory
    (``get_state``/``set_state``, as :class:`rigidmd.relax.lbfgs.RigidLBFGS`): only then
    does a continuation take the uninterrupted relaxation's steps.  ASE's own optimizers
    (FIRE, BFGS, LBFGS, ...) keep theirs to themselves: a continuation starts them afresh.
    """
    return callable(getattr(optimizer, "get_state", None)) and \
        callable(getattr(optimizer, "set_state", None))


def write_state(path, view, opt, label=None):
    """Write the state of ``view`` (a RigidFilter) and ``opt`` (its optimizer) to ``path``,
    with ``label`` (text: what else the continuation must share, e.g. the calculator)."""
    path = Path(path)
    arrays = {f"view.{k}": v for k, v in view.get_state().items()}
    if hasattr(opt, "get_state"):
        arrays.update({f"opt.{k}": v for k, v in opt.get_state().items()})
    arrays["optimizer"] = np.array(type(opt).__name__)
    arrays["positions"] = view.atoms.positions.copy()
    arrays["cell"] = view.atoms.cell.array.copy()
    if label is not None:
        arrays["label"] = np.array(str(label))
    atomic_write(path, lambda fh: np.savez(fh, **arrays))


def read_state(path):
    """The arrays of a state file (dict), or None when there is no file at ``path``.

    Raises
    ------
    ValueError
        A file that is not a whole state (named, with what went wrong).
    """
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as err:  # numpy raises several kinds on a damaged file  # noqa: BLE001
        raise ValueError(f"{path}: not a relaxation state ({type(err).__name__}: "
                         f"{' '.join(str(err).split())})") from None
    missing = {"optimizer", "positions", "cell", "view.x", "view.q_ref", "view.n_atoms"} - \
        set(arrays)
    if missing:
        raise ValueError(f"{path}: not a relaxation state (no {sorted(missing)[0]})")
    _check_contents(arrays, path)
    return arrays


def _check_contents(arrays, path):
    """Refuse a state whose numbers are not finite, whose reference orientations are not unit
    quaternions or whose parts do not fit together, as checkpoints are checked
    (:func:`rigidmd.core.checkpoint.check_checkpoint`): a damaged file is never used."""
    from rigidmd.core.checkpoint import QUATERNION_NORM_TOLERANCE

    where = f"{path}: a damaged relaxation state"
    for name, values in arrays.items():
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            raise ValueError(f"{where} ({name} holds a non-finite number)")
    positions, cell, q_ref = arrays["positions"], arrays["cell"], arrays["view.q_ref"]
    if positions.ndim != 2 or positions.shape[1:] != (3,) or \
            len(positions) != int(arrays["view.n_atoms"]) or cell.shape != (3, 3):
        raise ValueError(f"{where} (positions {positions.shape}, cell {cell.shape} for "
                         f"{int(arrays['view.n_atoms'])} atoms)")
    if q_ref.ndim != 2 or q_ref.shape[1:] != (4,):
        raise ValueError(f"{where} (view.q_ref has shape {q_ref.shape}, not (bodies, 4))")
    norms = np.linalg.norm(q_ref, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_NORM_TOLERANCE)
    if bad.size:
        raise ValueError(f"{where} (body {int(bad[0])} has a reference orientation of norm "
                         f"{norms[bad[0]]:.9g}, not 1)")


def state_matches(state, atoms, optimizer, label=None):
    """Whether ``state`` was taken at ``atoms``' positions and cell, by ``optimizer`` (a
    class or its name), with ``label`` (as :func:`write_state` recorded it; None: unchecked).

    Returns
    -------
    str or None
        None when it matches, else what differs (for a message).
    """
    optimizer = optimizer if isinstance(optimizer, str) else optimizer.__name__
    if label is not None and str(state.get("label", "")) != str(label):
        return (f"it was written with {state.get('label', 'no label')}, this relaxation has "
                f"{label}")
    if str(state["optimizer"]) != optimizer:
        return f"it was written by {state['optimizer']}, this relaxation uses {optimizer}"
    if state["positions"].shape != atoms.positions.shape:
        return (f"it holds {len(state['positions'])} atoms, the structure "
                f"{len(atoms)}")
    if not (np.array_equal(state["positions"], atoms.positions)
            and np.array_equal(state["cell"], atoms.cell.array)):
        return "its positions are not the last frame's (a later step was written after it)"
    return None


def split(state, prefix):
    """The entries of ``state`` under ``prefix.``, without it."""
    return {k[len(prefix) + 1:]: v for k, v in state.items() if k.startswith(prefix + ".")}


def resumed_state(state_file, atoms, optimizer, label=None):
    """The state ``relax(resume=True)`` continues from, checked against the atoms and the
    ``optimizer`` class.

    Raises
    ------
    ValueError
        No ``state_file``, an optimizer without a memory to continue
        (:func:`keeps_memory`), no file at that path, or one that does not match.
    """
    if state_file is None:
        raise ValueError("relax: resume=True needs the state_file to continue from")
    if not keeps_memory(optimizer):
        raise ValueError(f"relax: resume=True continues an optimizer's memory, and "
                         f"{optimizer.__name__} keeps none that can be saved (continue from "
                         "the last frame without resume)")
    saved = read_state(state_file)
    if saved is None:
        raise ValueError(f"relax: resume=True but {state_file} does not exist (a relaxation "
                         "writes it when Ctrl-C, an observer or its steps stop it, and removes "
                         "it once converged); relax the atoms as they are without resume")
    differs = state_matches(saved, atoms, optimizer, label)
    if differs:
        raise ValueError(f"relax: cannot continue from {state_file}: {differs}")
    return saved
