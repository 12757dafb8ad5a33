"""What defines a run, field by field, and the command that continues it.

:func:`fingerprint` digests each configuration field that defines the
trajectory; a checkpoint records it and ``--resume`` compares it
(:func:`differing_fields`).  A checkpoint of rigidmd 0.1.0, which recorded
one digest of the whole configuration, is compared through its own contents
instead (:func:`earlier_release_differences`).  :func:`resume_command` is the
exact command a stopped run prints.
"""

import hashlib
import json
import shlex
from dataclasses import asdict
from pathlib import Path

import numpy as np

from rigidmd.couplings.base import COUPLINGS

__all__ = ["fingerprint", "differing_fields", "earlier_release_differences", "resume_command",
           "calculator_digest"]


def resume_command(config_path=None, directory=None, flags=(), command="run"):
    """The ``rigidmd run ... --resume`` command that continues a run, quoted for a shell.

    Parameters
    ----------
    config_path : str, optional
        The configuration file as given on the command line.
    directory : path-like, optional
        The output directory; given as ``--outdir`` with its absolute path, so
        the command acts on this run from any directory.
    flags : sequence of str
        The other command-line flags that defined the run (``--structure``,
        ``--timestep``, ...), repeated as given.
    command : {"run", "relax"}
        The subcommand: ``rigidmd relax ... --resume`` continues a relaxation alike.
    """
    words = ["rigidmd", command] + ([str(config_path)] if config_path else []) + list(flags)
    if directory is not None:
        words += ["--outdir", str(Path(directory).resolve())]
    return shlex.join(words + ["--resume"])


def _digest(value):
    text = json.dumps(value, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _file_digest(path):
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:16]


#: Calculator options that say where the forces run or who may answer, not what they are.
WHERE_OPTIONS = ("peers",)


#: Calculator fields that say where the forces run, not what they are.
WHERE_FIELDS = ("calculator_class", "processes", "threads", "address")


def _calculator_fields(calculator):
    if hasattr(calculator, "fingerprint_fields"):  # a split: each level's fields
        return calculator.fingerprint_fields(_calculator_fields)
    fields = {key: value for key, value in asdict(calculator).items()
              if key not in WHERE_FIELDS}
    if isinstance(fields.get("options"), dict):
        fields["options"] = {k: v for k, v in fields["options"].items()
                             if k not in WHERE_OPTIONS}
    return fields


def calculator_digest(calculator):
    """The digest :func:`fingerprint` gives the ``calculator`` field, of a
    :class:`~rigidmd.config.sections.CalculatorSection` (a relaxation's state records it)."""
    return _digest(_calculator_fields(calculator))


def fingerprint(config):
    """What defines the trajectory, field by field: a digest per configuration field.

    ``steps`` and the output file names are left out, and so is where the
    files lie: a structure file or an integrator ``.yaml`` counts by its
    content, so a moved or copied run directory resumes.

    Returns
    -------
    dict
        Field name (as in the configuration) -> 16 hexadecimal digits.
    """
    structure = config.structure
    source = structure.source
    if isinstance(source, Path):
        source = {"file content": _file_digest(source)}
    integrator = config.run.integrator
    if isinstance(integrator, str) and integrator.endswith((".yaml", ".yml")):
        integrator = {"file content": _file_digest(integrator)}
    fields = {
        "structure": source, "read_options": structure.read_options,
        "bodies": structure.bodies, "calculator": _calculator_fields(config.calculator),
        "integrator": integrator, "integrator_options": config.run.integrator_options,
        "timestep": config.run.timestep, "velocities": _velocities(config.run.velocities),
        "outputs.interval": config.outputs.interval,
    }
    for section in ("thermostat", "barostat"):
        spec = getattr(config.coupling, section)
        fields[section] = None if spec is None else [spec.kind, spec.kwargs, spec.seed]
    relax = getattr(config, "relax", None)
    if relax is not None:  # what it relaxes to; relax.steps may be raised, as steps may
        fields["relax"] = [relax.fmax, relax.optimizer, relax.cell, relax.pressure]
    return {name: _digest(value) for name, value in fields.items()}


def _velocities(velocities):
    """The start velocities as a fingerprint holds them: ``stationary`` only when it is not
    the default (it came later, and a resumed run draws no velocities: a run begun before
    it continues)."""
    if velocities is None or velocities.get("stationary", True) is not True:
        return velocities
    return {k: v for k, v in velocities.items() if k != "stationary"}


#: Fields a fingerprint gained after checkpoints were written without them: a record that
#: lacks one is not refused for it (its run could not have been compared on it).
LATER_FIELDS = ("relax",)


def differing_fields(recorded, current):
    """The configuration fields whose digests differ (all of them for an old record)."""
    if not isinstance(recorded, dict):
        return None
    return [name for name in current if recorded.get(name) != current[name]
            and not (name in LATER_FIELDS and name not in recorded)]


def _plain(value):
    """Numbers, lists and dicts only (NumPy's as Python's), for comparing parameters."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def earlier_release_differences(config, checkpoint):
    """The fields that differ from a checkpoint without a per-field record (0.1.0's).

    Its own contents are compared: the atoms (elements), the timestep, the
    integrator's name and every coupling part's kind and parameters.
    """
    meta = checkpoint.meta
    differing = []
    atoms = config.structure.build_atoms()
    if not np.array_equal(atoms.numbers, checkpoint.arrays["numbers"]):
        differing.append("structure")
    if not np.isclose(meta["dt"], config.run.timestep, rtol=1e-12, atol=0):
        differing.append("timestep")
    integrator = config.run.integrator
    if isinstance(integrator, str) and not integrator.endswith((".yaml", ".yml")) and \
            integrator != meta["scheme_name"]:
        differing.append("integrator")
    stored = {COUPLINGS[entry["parameters"]["kind"]].section: _plain(entry["parameters"])
              for entry in meta["couplings"] if entry["parameters"]["kind"] in COUPLINGS}
    current = {part.section: _plain(part.todict()) for part in config.coupling.parts()}
    for section, parameters in current.items():
        # fixcm left to its default: the run continues with the value it stored
        if parameters.get("fixcm", False) is None:
            del parameters["fixcm"]
            stored.get(section, {}).pop("fixcm", None)
    differing += [section for section in ("thermostat", "barostat")
                  if stored.get(section) != current.get(section)]
    return differing
