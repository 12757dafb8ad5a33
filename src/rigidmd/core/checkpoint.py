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
* the forces, torques and virial of the last force call (or that there was
  none yet: a continuation then calls the calculator at its start), and the
  scheme's scratch values (exaDEM's accelerations);
* the dynamics' class (``RigidBussi``, ...) and its bases, by name;
* step count, simulated time, time step, integrator scheme and backend;
* every coupling part: its kind, parameters and variables (chains, barostat,
  random-number generator states, which parts share a generator);
* anything the caller adds (the command line records the length of each output).

It only serialises what the dynamics exports (``dyn.get_state()``);
:func:`rigidmd.load_checkpoint` rebuilds the dynamics, of the class saved, with a
calculator you give (``dyn.set_state(...)``) and continues exactly: with a deterministic
calculator the positions after ``n`` more steps are bit-identical to those
of the run that was never stopped.  (Calculators whose summation order
depends on history, such as a LAMMPS neighbour list built at another step,
agree to roundoff instead.)
"""

import glob
import json
import os
import secrets
from pathlib import Path

import numpy as np
from ase import Atoms

from rigidmd.core.coupling import COUPLINGS, Coupling, new_rng
from rigidmd.core.model import BodyModel
from rigidmd.core.state import STATE_FIELDS

__all__ = ["save_checkpoint", "read_checkpoint", "check_checkpoint", "atomic_write",
           "remove_stale_temporaries", "Checkpoint", "CheckpointError", "FORMAT"]

#: Identifies the file format (with a version number).
FORMAT = "rigidmd-checkpoint-1"

_ATOMS_ARRAYS = ("numbers", "positions", "momenta", "masses", "tags", "initial_charges")


class CheckpointError(ValueError):
    """A checkpoint file that cannot be read or does not fit what it is loaded with."""


def atomic_write(path, write):
    """Write a file atomically: ``write(fh)`` into a temporary file, fsync, rename.

    A reader sees the old file or the new one, never a partial one, also
    after a crash or a full disk (the temporary file is removed then; one
    left by ``kill -9`` is named ``.NAME.*.tmp`` and :func:`remove_stale_temporaries`
    removes it).  The file's mode follows the umask, as ``open()``'s does.
    An ``OSError`` (a full disk, ...) carries ``path`` as its ``filename``.
    """
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
        try:
            fd = os.open(tmp, flags, 0o666)  # the umask applies, as for every other output
            break
        except FileExistsError:  # pragma: no cover - 32 random bits taken already
            continue
        except OSError as err:
            raise _naming(err, path) from None
    else:  # pragma: no cover
        raise FileExistsError(f"cannot create a temporary file beside {path}")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(err, OSError):
            raise _naming(err, path) from None
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


def _naming(err, path):
    """``err`` with ``filename`` set to the file meant (not its temporary name)."""
    if err.filename is None or str(err.filename).endswith(".tmp"):
        err = type(err)(err.errno, err.strerror or str(err), str(path))
    return err


def remove_stale_temporaries(path):
    """Remove the temporary files a killed :func:`atomic_write` of ``path`` left behind.

    Call it only while no other process writes ``path`` (the command line
    holds the output directory's lock).  Returns the names removed.
    """
    path = Path(path)
    removed = []
    for tmp in sorted(path.parent.glob(f".{glob.escape(path.name)}.*.tmp")):
        tmp.unlink(missing_ok=True)
        removed.append(tmp.name)
    return removed


def _jsonable(value):
    """Arrays to tagged lists (exact: JSON keeps every float digit), recursively."""
    if isinstance(value, np.ndarray):  # the shape too: an empty (0, 3) array lists as []
        return {"__array__": value.tolist(), "dtype": str(value.dtype),
                "shape": list(value.shape)}
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
            array = np.array(value["__array__"], dtype=value["dtype"])
            shape = value.get("shape")  # (files of earlier releases have none)
            return array if shape is None or array.size else array.reshape(shape)
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


def save_checkpoint(dyn, path, extra=None):
    """Write a checkpoint of ``dyn`` to ``path`` (atomically).

    Parameters
    ----------
    dyn : rigidmd.core.dynamics.RigidDynamics
    path : str or os.PathLike
    extra : dict, optional
        JSON-serialisable data stored alongside (e.g. output file lengths).
    """
    if extra is not None and (not isinstance(extra, dict) or not _is_json(extra)):
        raise TypeError(f"save_checkpoint: extra must be a dict of JSON data (numbers, "
                        f"strings, lists, dicts), got {extra!r:.80}")
    atoms, saved = dyn.atoms, dyn.get_state()
    record = saved["record"]
    arrays = {
        "numbers": atoms.numbers, "masses": atoms.get_masses(), "tags": atoms.get_tags(),
        "charges": atoms.get_initial_charges(), "cell": atoms.cell.array,
        "pbc": atoms.pbc, "positions": atoms.positions, "momenta": atoms.get_momenta(),
        "body_ids": saved["body_ids"], "F": record["F"], "tau": record["tau"], "f": record["f"],
    }
    arrays.update({f"model_{name}": value for name, value in saved["model"].items()})
    arrays.update({f"state_{name}": value for name, value in saved["state"].items()})
    if record["virial"] is not None:
        arrays["virial"] = record["virial"]
    levels = record.get("levels") or {}  # a force split's fast and slow records
    for level, kept in levels.items():
        arrays.update({f"{level}_{key}": kept[key] for key in ("F", "tau", "f", "r")})
        if kept["virial"] is not None:
            arrays[f"{level}_virial"] = kept["virial"]
    # Other per-atom arrays (a LAMMPS data file's mol-id and type, ...), for calculators.
    for name, values in atoms.arrays.items():
        if name not in _ATOMS_ARRAYS and values.dtype.kind in "biuf":
            arrays[f"atoms_{name}"] = values
    meta = {
        "format": FORMAT,
        "class": type(dyn).__name__,
        # The class's bases down to RigidDynamics: a class rigidmd does not know (the
        # user's own) is loaded as the nearest one it does.
        "classes": saved["classes"],
        "nsteps": saved["nsteps"], "time": saved["time"], "dt": saved["dt"],
        "scheme": saved["scheme"], "scheme_name": saved["scheme_name"],
        "backend": saved["backend"], "bodies_rule": saved["bodies_rule"],
        "model_n_atoms": saved["n_atoms"],
        "couplings": saved["couplings"],
        "scratch": {k: v for k, v in record["scratch"].items() if isinstance(v, np.ndarray)},
        # What the per-step record had computed (the kinetic tensor as the coupling parts
        # updated it): a continuation reads these, not fresh sums that differ in roundoff.
        # Whether the forces are a call's (False before the first: zeros, called at the start).
        "record": {key: record[key] for key in ("volume", "kinetic", "rotational",
                                                 "forces_known")},
        "levels": {level: {"energy": kept["energy"]} for level, kept in levels.items()},
        "split": saved["split"],
        "info": {k: v for k, v in atoms.info.items() if _is_json(v)},
        "extra": extra or {},
        "atoms_arrays": sorted(atoms.arrays),  # which arrays the Atoms had set
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
        # Masses and charges as the saved Atoms had them: an array set only where it was
        # (ASE writes the arrays an Atoms has to every trajectory frame).
        present = self.meta.get("atoms_arrays")
        if present is None or "masses" in present:
            atoms.set_masses(a["masses"])
        if present is not None and "initial_charges" not in present:
            del atoms.arrays["initial_charges"]
        atoms.set_momenta(a["momenta"], apply_constraint=False)
        for key, values in a.items():
            if key.startswith("atoms_"):
                atoms.arrays[key[len("atoms_"):]] = values.copy()
        atoms.info.update(self.meta.get("info", {}))
        return atoms

    def dynamics_state(self) -> dict:
        """What ``RigidDynamics.set_state`` takes, as ``RigidDynamics.get_state`` gave it."""
        meta, a = self.meta, self.arrays
        record = {"F": a["F"], "tau": a["tau"], "f": a["f"], "virial": a.get("virial"),
                  "scratch": dict(meta["scratch"]), **meta.get("record", {})}
        if meta.get("levels"):  # a force split's records, each level's own
            record["levels"] = {
                level: {"F": a[f"{level}_F"], "tau": a[f"{level}_tau"], "f": a[f"{level}_f"],
                        "r": a[f"{level}_r"], "virial": a.get(f"{level}_virial"),
                        "energy": kept["energy"]}
                for level, kept in meta["levels"].items()}
        classes = meta.get("classes") or ([meta["class"]] if meta.get("class") else [])
        return {
            "classes": list(classes),
            "nsteps": meta["nsteps"], "time": meta["time"], "dt": meta["dt"],
            "scheme": meta["scheme"], "scheme_name": meta["scheme_name"],
            "backend": meta["backend"], "bodies_rule": meta["bodies_rule"],
            "body_ids": a["body_ids"], "n_atoms": meta["model_n_atoms"],
            "model": {name: a[f"model_{name}"] for name in BodyModel.STORED},
            "state": {name: a[f"state_{name}"] for name in STATE_FIELDS},
            "record": record, "couplings": meta["couplings"],
            **({"split": meta["split"]} if "split" in meta else {}),  # (older: none stored)
        }

    def couplings(self) -> list[Coupling]:
        """New coupling parts with the stored parameters (a shared generator stays shared)."""
        parts, rngs = [], []
        for entry in self.meta["couplings"]:
            parameters = dict(entry["parameters"])
            kind = parameters.pop("kind")
            if kind not in COUPLINGS:
                raise CheckpointError(f"checkpoint: unknown coupling kind {kind!r}")
            if entry["rng"] is not None:
                owner = entry["rng_owner"]
                rng = rngs[owner] if owner is not None and owner < len(rngs) and \
                    rngs[owner] is not None else new_rng(entry["rng"])
                parameters["rng"] = rng
            else:
                rng = None
            parts.append(COUPLINGS[kind](**parameters))
            rngs.append(rng)
        return parts


#: What every checkpoint holds (a file without one of them is damaged or not ours).
_REQUIRED_ARRAYS = ("numbers", "positions", "momenta", "masses", "tags", "charges", "cell",
                    "pbc", "body_ids", "F", "tau", "f")
_REQUIRED_META = ("nsteps", "time", "dt", "scheme", "scheme_name", "backend", "bodies_rule",
                  "model_n_atoms", "couplings", "scratch", "extra")


def read_checkpoint(path):
    """Read a checkpoint file; a :class:`CheckpointError` names what is wrong.

    An empty, truncated or corrupted file (the archive's checksums fail),
    or one that lacks a part every checkpoint has, is a :class:`CheckpointError`.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint: no such file {str(path)!r}") from None
    except IsADirectoryError:
        raise CheckpointError(f"checkpoint: {str(path)!r} is a directory") from None
    except Exception as err:  # a damaged archive raises BadZipFile, EOFError, KeyError, ...
        reason = " ".join(str(err).split()) or type(err).__name__
        if path.is_file() and path.stat().st_size == 0:
            reason = "the file is empty"
        elif "pickle" in reason:  # NumPy's advice to load it unsafely: never for a checkpoint
            reason = "not a NumPy archive of arrays"
        raise CheckpointError(f"checkpoint: {str(path)!r} is not a readable checkpoint "
                              f"({reason})") from None
    if "meta" not in arrays:
        raise CheckpointError(f"checkpoint: {str(path)!r} holds no rigidmd metadata")
    try:
        meta = _from_json(json.loads(str(arrays.pop("meta"))))
    except (ValueError, TypeError, KeyError) as err:
        raise CheckpointError(f"checkpoint: {str(path)!r} has unreadable metadata "
                              f"({err})") from None
    if not isinstance(meta, dict):
        raise CheckpointError(f"checkpoint: {str(path)!r} has unreadable metadata")
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint: {str(path)!r} has format {meta.get('format')!r}, "
                              f"this rigidmd reads {FORMAT!r}")
    missing = [name for name in _REQUIRED_ARRAYS if name not in arrays]
    missing += [f"model_{name}" for name in BodyModel.STORED if f"model_{name}" not in arrays]
    missing += [f"state_{name}" for name in STATE_FIELDS if f"state_{name}" not in arrays]
    missing += [name for name in _REQUIRED_META if name not in meta]
    if missing:
        raise CheckpointError(f"checkpoint: {str(path)!r} is incomplete (no {missing[0]!r})")
    check_checkpoint(meta, arrays, path)
    return Checkpoint(meta, arrays)


#: How far a stored orientation's norm may be from 1.  A run keeps it to roundoff: each
#: free rotation is an exact rotation, so |q| drifts by ~1e-16 a step (below 1e-10 after
#: 1e8 steps); anything near 1e-6 was written by hand or damaged.
QUATERNION_NORM_TOLERANCE = 1e-6


def _shapes(meta, arrays):
    """The shape each array of a checkpoint must have, from its atoms and its body ids."""
    n_atoms = len(arrays["numbers"])
    ids = np.asarray(arrays["body_ids"]).reshape(-1)
    n_bodies = int(ids.max()) + 1 if ids.size and ids.max() >= 0 else 0
    n_body_atoms = int(np.count_nonzero(ids >= 0))
    n_free = n_atoms - n_body_atoms
    per = {"atoms": n_atoms, "bodies": n_bodies, "body atoms": n_body_atoms,
           "free atoms": n_free}
    expected = {name: ("atoms", 3) for name in ("positions", "momenta")}
    expected.update({name: ("atoms", None) for name in ("masses", "tags", "charges",
                                                        "body_ids")})
    expected.update({"F": ("bodies", 3), "tau": ("bodies", 3), "f": ("free atoms", 3),
                     "model_mass": ("bodies", None), "model_moments": ("bodies", 3),
                     "model_starts": ("bodies", None), "model_order": ("body atoms", None),
                     "model_atom_body": ("body atoms", None),
                     "model_atom_masses": ("body atoms", None),
                     "model_body_coordinates": ("body atoms", 3),
                     "model_free": ("free atoms", None), "model_free_masses": ("free atoms", None),
                     "state_X": ("bodies", 3), "state_V": ("bodies", 3), "state_q": ("bodies", 4),
                     "state_p": ("bodies", 4), "state_x": ("free atoms", 3),
                     "state_v": ("free atoms", 3)})
    for level in meta.get("levels") or {}:  # a force split's records
        expected.update({f"{level}_F": ("bodies", 3), f"{level}_tau": ("bodies", 3),
                         f"{level}_f": ("free atoms", 3), f"{level}_r": ("body atoms", 3)})
    return per, expected


def check_checkpoint(meta, arrays, path="checkpoint"):
    """Refuse a checkpoint whose parts do not fit together, naming the part and the body.

    Every per-atom, per-body and per-free-atom array must have as many rows
    as the atoms and the body ids say (a body short or extra is named, not
    left to a broadcasting error), the metadata's atom count must agree,
    every stored number must be finite, and every orientation a unit
    quaternion (within :data:`QUATERNION_NORM_TOLERANCE`).

    Raises
    ------
    CheckpointError
    """
    where = f"checkpoint: {str(path)!r}"
    per, expected = _shapes(meta, arrays)
    for name, (count, width) in expected.items():
        shape = np.shape(arrays[name])
        rows, columns = (shape[0] if shape else None), (shape[1] if len(shape) > 1 else None)
        if rows != per[count] or (width is not None and columns != width):
            want = f"{per[count]} {count}" + (f" x {width}" if width else "")
            raise CheckpointError(
                f"{where} does not fit together: {name} has shape {shape}, but the body ids "
                f"give {want} (a body or an atom short or extra: the file was changed)")
    if meta["model_n_atoms"] != per["atoms"]:
        raise CheckpointError(f"{where} does not fit together: its metadata says "
                              f"{meta['model_n_atoms']} atoms, its arrays hold {per['atoms']}")
    if np.shape(arrays["cell"]) != (3, 3):
        raise CheckpointError(f"{where}: cell has shape {np.shape(arrays['cell'])}, not (3, 3)")
    for name, values in arrays.items():
        values = np.asarray(values)
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            raise CheckpointError(f"{where}: {name} holds a non-finite number")
    # A body's mass is positive; an atom of one may weigh nothing (TIP4P's M site).
    for name, what, least in (("model_mass", "body mass", 0.0),
                              ("model_atom_masses", "atom mass", None)):
        values = np.asarray(arrays[name], dtype=float)
        bad = values <= 0 if least is not None else values < 0
        if values.size and bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise CheckpointError(f"{where}: {name} holds a {what} of {values[i]:g} amu (entry "
                                  f"{i}); the file was changed")
    moments = np.asarray(arrays["model_moments"], dtype=float)
    if moments.size and (moments < 0).any():
        b = int(np.flatnonzero((moments < 0).any(axis=1))[0])
        raise CheckpointError(f"{where}: body {b} has a negative principal moment; the file "
                              "was changed")
    steps = meta["nsteps"]
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise CheckpointError(f"{where}: nsteps is {steps!r}, not a whole number >= 0")
    for name in ("time", "dt"):
        value = meta[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value \
                or value < 0 or (name == "dt" and value == 0):
            raise CheckpointError(f"{where}: {name} is {value!r}, not a "
                                  f"{'positive' if name == 'dt' else 'non-negative'} number")
    couplings = meta["couplings"]
    if not isinstance(couplings, list):
        raise CheckpointError(f"{where}: couplings is {couplings!r}, not a list of parts")
    for i, entry in enumerate(couplings):
        missing = [key for key in ("class", "parameters", "state", "rng", "rng_owner")
                   if not isinstance(entry, dict) or key not in entry]
        if missing:
            raise CheckpointError(f"{where}: coupling part {i} lacks {missing[0]!r}; the file "
                                  "was changed")
        if not isinstance(entry["parameters"], dict) or "kind" not in entry["parameters"]:
            raise CheckpointError(f"{where}: coupling part {i} has no kind in its parameters")
    norms = np.linalg.norm(arrays["state_q"], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_NORM_TOLERANCE)
    if bad.size:
        b = int(bad[0])
        raise CheckpointError(
            f"{where}: body {b} has an orientation quaternion of norm {norms[b]:.9g}, not 1 "
            f"({bad.size} of {len(norms)} bodies): orientations must be unit quaternions; the "
            "file was changed or damaged")
