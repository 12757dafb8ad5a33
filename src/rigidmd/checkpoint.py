"""Checkpoints: everything a bit-exact continuation of a rigid dynamics needs, in one file.

:func:`save_checkpoint` (also ``dyn.save_checkpoint(path)``) writes, atomically
(a temporary file in the same directory, flushed, synced to disk, then renamed
over the target), a NumPy ``.npz`` archive holding

* the atoms: numbers, masses, tags, charges, cell, periodicity, positions, momenta,
  their other numeric per-atom arrays (``mol-id``, ...) and JSON-able ``info``;
* the bodies: each atom's body and the body model (atom order, masses,
  principal moments, body-frame coordinates: the reference frames), so a
  continuation does not measure them again;
* the state: centres of mass, velocities, quaternions, NO_SQUISH momenta
  (the axial momentum of linear bodies included), free atoms, cell;
* the forces, torques and virial of the last force call, and the scheme's
  scratch values (exaDEM's accelerations);
* step count, simulated time, time step, integrator scheme and backend;
* every coupling part: its kind, parameters and variables (chains, barostat,
  random-number generator states, which parts share a generator);
* anything the caller adds (the command line records the length of each output).

:func:`load_checkpoint` rebuilds the dynamics with a calculator you give and
continues exactly: with a deterministic calculator the positions after ``n``
more steps are bit-identical to those of the run that was never stopped.
(Calculators whose summation order depends on history, such as a LAMMPS
neighbour list built at another step, agree to roundoff instead.)
"""

import json
import os
import tempfile
from pathlib import Path

import numpy as np
from ase import Atoms

__all__ = ["save_checkpoint", "load_checkpoint", "read_checkpoint", "atomic_write",
           "CheckpointError", "FORMAT"]

#: Identifies the file format (with a version number).
FORMAT = "rigidmd-checkpoint-1"

_MODEL_FIELDS = ("order", "starts", "atom_body", "atom_masses", "mass", "moments",
                 "body_coordinates", "free", "free_masses")
_STATE_FIELDS = ("X", "V", "q", "p", "x", "v", "cell")
_ATOMS_ARRAYS = ("numbers", "positions", "momenta", "masses", "tags", "initial_charges")


class CheckpointError(ValueError):
    """A checkpoint file that cannot be read or does not fit what it is loaded with."""


def atomic_write(path, write):
    """Write a file atomically: ``write(fh)`` into a temporary file, fsync, rename.

    A reader sees the old file or the new one, never a partial one, also
    after a crash or a full disk (the temporary file is removed then).
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    try:
        directory = os.open(path.parent, os.O_RDONLY)
    except OSError:  # pragma: no cover - some file systems do not open directories
        return
    try:
        os.fsync(directory)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(directory)


def _jsonable(value):
    """Arrays to tagged lists (exact: JSON keeps every float digit), recursively."""
    if isinstance(value, np.ndarray):
        return {"__array__": value.tolist(), "dtype": str(value.dtype)}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def _from_json(value):
    if isinstance(value, dict):
        if "__array__" in value:
            return np.array(value["__array__"], dtype=value["dtype"])
        return {k: _from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    return value


def _is_json(value):
    try:
        json.dumps(value)
    except (TypeError, ValueError):
        return False
    return True


def _rng_kind(rng):
    if isinstance(rng, np.random.Generator):
        return {"type": "generator", "bit_generator": type(rng.bit_generator).__name__}
    return {"type": "legacy"}


def save_checkpoint(dyn, path, extra=None):
    """Write a checkpoint of ``dyn`` to ``path`` (atomically).

    Parameters
    ----------
    dyn : rigidmd.dynamics.RigidDynamics
    path : str or os.PathLike
    extra : dict, optional
        JSON-serialisable data stored alongside (e.g. output file lengths).
    """
    atoms, model, state, ctx = dyn.atoms, dyn.model, dyn.state, dyn._ctx
    arrays = {
        "numbers": atoms.numbers, "masses": atoms.get_masses(), "tags": atoms.get_tags(),
        "charges": atoms.get_initial_charges(), "cell": atoms.cell.array,
        "pbc": atoms.pbc, "positions": atoms.positions, "momenta": atoms.get_momenta(),
        "body_ids": dyn.bodies.body_ids, "F": ctx.F, "tau": ctx.tau, "f": ctx.f,
    }
    arrays.update({f"model_{name}": getattr(model, name) for name in _MODEL_FIELDS})
    arrays.update({f"state_{name}": getattr(state, name) for name in _STATE_FIELDS})
    if dyn._virial is not None:
        arrays["virial"] = dyn._virial
    # Other per-atom arrays (a LAMMPS data file's mol-id and type, ...), for calculators.
    for name, values in atoms.arrays.items():
        if name not in _ATOMS_ARRAYS and values.dtype.kind in "biuf":
            arrays[f"atoms_{name}"] = values
    rngs = []
    parts = []
    for part in dyn.couplings:
        rng = getattr(part, "rng", None)
        owner = next((i for i, other in enumerate(dyn.couplings)
                      if getattr(other, "rng", None) is rng), None) if rng is not None else None
        parts.append({"class": type(part).__name__, "parameters": part.todict(),
                      "state": part.get_state(), "rng_owner": owner,
                      "rng": None if rng is None else _rng_kind(rng)})
        rngs.append(rng)
    meta = {
        "format": FORMAT,
        "class": type(dyn).__name__,
        "nsteps": int(dyn.nsteps), "time": float(dyn.get_time()), "dt": float(dyn.dt),
        "scheme": dyn.scheme.todict(), "scheme_name": dyn.scheme.name,
        "backend": dyn.backend, "bodies_rule": dyn.bodies.rule,
        "model_n_atoms": int(model.n_atoms),
        "couplings": parts,
        "scratch": {k: v for k, v in ctx.scratch.items() if isinstance(v, np.ndarray)},
        "info": {k: v for k, v in atoms.info.items() if _is_json(v)},
        "extra": extra or {},
        # What the calculator needs to continue with the same energies (LAMMPS's k-space
        # parameters), when it offers it.
        "calculator_state": (atoms.calc.get_checkpoint_state()
                             if hasattr(atoms.calc, "get_checkpoint_state") else None),
    }
    arrays["meta"] = np.array(json.dumps(_jsonable(meta)))
    atomic_write(path, lambda fh: np.savez(fh, **arrays))


class Checkpoint:
    """A checkpoint read from a file: ``meta`` (dict) and ``arrays`` (dict of arrays)."""

    def __init__(self, meta, arrays):
        self.meta, self.arrays = meta, arrays

    @property
    def nsteps(self):
        return self.meta["nsteps"]

    @property
    def extra(self):
        return self.meta["extra"]

    def atoms(self):
        """The Atoms at the checkpoint (positions, momenta, cell, tags, charges; no calculator)."""
        a = self.arrays
        atoms = Atoms(numbers=a["numbers"], positions=a["positions"], cell=a["cell"],
                      pbc=a["pbc"], tags=a["tags"], charges=a["charges"])
        atoms.set_masses(a["masses"])
        atoms.set_momenta(a["momenta"], apply_constraint=False)
        for key, values in a.items():
            if key.startswith("atoms_"):
                atoms.arrays[key[len("atoms_"):]] = values.copy()
        atoms.info.update(self.meta.get("info", {}))
        return atoms


def read_checkpoint(path):
    """Read a checkpoint file; a :class:`CheckpointError` names what is wrong."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint: no such file {str(path)!r}") from None
    except (OSError, ValueError) as err:
        raise CheckpointError(f"checkpoint: {str(path)!r} is not a readable checkpoint "
                              f"({err})") from None
    if "meta" not in arrays:
        raise CheckpointError(f"checkpoint: {str(path)!r} holds no rigidmd metadata")
    meta = _from_json(json.loads(str(arrays.pop("meta"))))
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint: {str(path)!r} has format {meta.get('format')!r}, "
                              f"this rigidmd reads {FORMAT!r}")
    return Checkpoint(meta, arrays)


def _new_rng(kind):
    if kind["type"] == "generator":
        return np.random.Generator(getattr(np.random, kind["bit_generator"])())
    return np.random.RandomState()


def _parts(meta):
    """New coupling parts with the stored parameters; parts that shared a generator share one."""
    from rigidmd.coupling import COUPLINGS

    parts, rngs = [], []
    for entry in meta["couplings"]:
        parameters = dict(entry["parameters"])
        kind = parameters.pop("kind")
        if kind not in COUPLINGS:
            raise CheckpointError(f"checkpoint: unknown coupling kind {kind!r}")
        if entry["rng"] is not None:
            owner = entry["rng_owner"]
            rng = rngs[owner] if owner is not None and owner < len(rngs) and \
                rngs[owner] is not None else _new_rng(entry["rng"])
            parameters["rng"] = rng
        else:
            rng = None
        parts.append(COUPLINGS[kind](**parameters))
        rngs.append(rng)
    return parts


def load_checkpoint(path, calculator, **kwargs):
    """Rebuild a rigid dynamics from a checkpoint, ready to continue exactly.

    Parameters
    ----------
    path : str or os.PathLike
    calculator : ase.calculators.calculator.Calculator
        Attached to the rebuilt atoms (the checkpoint holds no calculator; one with
        ``set_checkpoint_state`` gets what its ``get_checkpoint_state`` gave).
    **kwargs
        ``trajectory``, ``logfile``, ``loginterval``, ``append_trajectory``, ...
        as for :class:`~rigidmd.dynamics.RigidDynamics`.

    Returns
    -------
    rigidmd.dynamics.RigidDynamics
        At the checkpoint's step and time; ``dyn.atoms`` are new Atoms.  The
        class is :class:`~rigidmd.dynamics.RigidDynamics` with the stored
        coupling parts (``dyn.couplings``).
    """
    from rigidmd.dynamics import RigidDynamics
    from rigidmd.model import BodyModel
    from rigidmd.schemes import Scheme

    checkpoint = path if isinstance(path, Checkpoint) else read_checkpoint(path)
    meta, arrays = checkpoint.meta, checkpoint.arrays
    atoms = checkpoint.atoms()
    atoms.calc = calculator
    if meta.get("calculator_state") is not None and hasattr(calculator, "set_checkpoint_state"):
        calculator.set_checkpoint_state(meta["calculator_state"])
    scheme = Scheme(meta["scheme"], name=meta["scheme_name"])
    dyn = RigidDynamics(atoms, meta["dt"], bodies=arrays["body_ids"], integrator=scheme,
                        backend=meta["backend"], couplings=_parts(meta), **kwargs)
    # The stored model and state replace what the constructor measured.
    dyn.model = BodyModel(n_atoms=meta["model_n_atoms"],
                          **{name: arrays[f"model_{name}"] for name in _MODEL_FIELDS})
    dyn._ctx.model = dyn.model
    for name in _STATE_FIELDS:
        np.copyto(getattr(dyn.state, name), arrays[f"state_{name}"])
    dyn._ctx.F, dyn._ctx.tau, dyn._ctx.f = arrays["F"], arrays["tau"], arrays["f"]
    dyn._ctx.scratch = dict(meta["scratch"])
    for part, entry in zip(dyn.couplings, meta["couplings"], strict=True):
        part.set_state(entry["state"])
    if "virial" in arrays:
        dyn._virial = arrays["virial"]
    dyn.nsteps = meta["nsteps"]
    dyn._time = meta["time"]
    dyn.bodies.rule = meta["bodies_rule"]
    atoms.set_cell(dyn.state.cell)
    dyn._write_atoms()
    dyn._forces_current = True
    return dyn
