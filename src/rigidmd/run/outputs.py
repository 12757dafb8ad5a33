"""Output files of a run: one run per directory, lengths at a checkpoint, trimming on resume.

* :class:`OutputLock`: a lock file holding the process id and host; a second
  run into the same directory is refused while the first lives, and a lock
  left by a process that died (``kill -9``, a node failure) is taken over.
* :func:`output_lengths` records how long each output file is when a
  checkpoint is written; :func:`trim_outputs` cuts every file back to those
  lengths before a resumed run appends, which also removes a truncated last
  frame or line.
* ASE ``.traj`` files (ULM) are append-only apart from two header fields, the
  number of frames and the position of the frame table: trimming restores
  both and truncates, which gives back the file as it was at the checkpoint.
"""

import errno
import json
import os
import socket
from pathlib import Path

import numpy as np

from rigidmd.config.sections import LOCK_NAME

__all__ = ["OutputLock", "OutputError", "output_lengths", "trim_outputs", "LOCK_NAME",
           "check_apart_from_inputs", "ulm_header"]


class OutputError(RuntimeError):
    """An output directory or file that cannot be used as asked (the message says which)."""


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - another user's live process
        return True
    return True


class OutputLock:
    """Exclusive use of an output directory by one run.

    Parameters
    ----------
    directory : pathlib.Path
    field : str, default "outputs.directory"
        What the messages name (a command's option, e.g. ``--outdir``).

    Attributes
    ----------
    stale : dict or None
        The lock a dead process left behind, when it was taken over.
    """

    def __init__(self, directory, field="outputs.directory"):
        self.path = Path(directory) / LOCK_NAME
        self.field = field
        self.stale = None
        self._held = False

    def acquire(self):
        """Take the lock, or raise :class:`OutputError` naming the run that holds it."""
        record = {"pid": os.getpid(), "host": socket.gethostname()}
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder is not None and holder.get("host") != socket.gethostname():
                    raise OutputError(
                        f"{self.field}: {self.path.parent} is locked by process "
                        f"{holder.get('pid')} on host {holder.get('host')!r}, which this "
                        f"machine ({socket.gethostname()!r}) cannot check; wait for that run, "
                        f"or, if it is no longer running on {holder.get('host')}, remove "
                        f"{self.path} and try again") from None
                if holder is not None and self._lives(holder):
                    raise OutputError(
                        f"{self.field}: {self.path.parent} is in use by process "
                        f"{holder.get('pid')} on {holder.get('host')} (lock {self.path}); "
                        "wait for it, or choose another directory") from None
                self.stale = holder
                self.path.unlink(missing_ok=True)
                continue
            with os.fdopen(fd, "w") as fh:
                json.dump(record, fh)
            self._held = True
            return self
        raise OutputError(f"{self.field}: cannot take the lock {self.path}")

    def _holder(self):
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None  # unreadable or half-written: treated as stale

    @staticmethod
    def _lives(holder):
        if holder.get("host") != socket.gethostname():
            return True  # another machine's process: cannot check, assume alive
        pid = holder.get("pid")
        return isinstance(pid, int) and pid != os.getpid() and _alive(pid)

    def release(self):
        if self._held:
            self.path.unlink(missing_ok=True)
            self._held = False

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()


def ulm_header(path) -> tuple[int, int]:
    """The two header fields of an ASE ULM (``.traj``) file that appending changes.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    tuple of int
        ``(nitems, pos0)``: the number of items (frames) and the position of
        the frame table.

    Raises
    ------
    OutputError
        The file is not a ULM file.
    """
    with open(path, "rb") as fh:
        head = fh.read(48)
    if len(head) < 48 or not head.startswith(b"- of Ulm"):
        raise OutputError(f"{path}: not an ASE trajectory (ULM) file")
    _, nitems, pos0 = np.frombuffer(head[24:48], dtype="<i8")
    return int(nitems), int(pos0)


def output_lengths(files):
    """Sizes of the output files now, for a checkpoint.

    Parameters
    ----------
    files : dict
        Output name -> path (``"trajectory"`` is an ASE ``.traj``; other
        files are appended byte streams).

    Returns
    -------
    dict
        Name -> ``{"size": bytes}`` (plus ``"nitems"`` and ``"pos0"`` for a
        ``.traj``); a file that does not exist yet has size 0: every output of
        the run is named, so that a resumed run tells an output it wrote from one
        it was not asked for then (:func:`trim_outputs`).
    """
    lengths = {}
    for name, path in files.items():
        path = Path(path)
        if not path.exists():
            lengths[name] = {"size": 0}
            continue
        entry = {"size": path.stat().st_size}
        if name == "trajectory" and entry["size"] > 0:
            entry["nitems"], entry["pos0"] = ulm_header(path)
        lengths[name] = entry
    return lengths


def trim_outputs(files, lengths, advice="start it again with --overwrite"):
    """Cut each output file back to its recorded length (before a resumed run appends).

    A file shorter than recorded (lost after the checkpoint) is an error:
    the run cannot continue it, and ``advice`` says what to do instead.  So
    is a file the checkpoint does not name (the output was not asked for when
    it was written): its frames stop where that output was left out, and
    appending would hide the gap (deleting it lost the frames before it).
    Returns the names of the files trimmed.
    """
    trimmed = []
    for name, path in files.items():
        path = Path(path)
        recorded = lengths.get(name)
        if recorded is None:
            if path.exists() and path.stat().st_size > 0:
                raise OutputError(
                    f"outputs.{name}: {path} was not written up to the checkpoint "
                    f"(outputs.{name} was not given when it was taken), so it lacks the "
                    f"frames since; move it away to start it afresh from here, or leave "
                    f"outputs.{name} out")
            continue
        if recorded["size"] == 0:  # asked for, not yet written at the checkpoint
            if path.exists():  # written after it only: start it again
                path.unlink()
                trimmed.append(name)
            continue
        if not path.exists() or path.stat().st_size < recorded["size"]:
            raise OutputError(
                f"outputs.{name}: {path} is shorter than at the checkpoint "
                f"({path.stat().st_size if path.exists() else 0} < {recorded['size']} bytes); "
                f"the run cannot be continued without it: restore it, or {advice}")
        if path.stat().st_size == recorded["size"]:
            if name == "trajectory" and "nitems" in recorded:
                _restore_ulm(path, recorded)
            continue
        with open(path, "r+b") as fh:
            fh.truncate(recorded["size"])
            if name == "trajectory" and "nitems" in recorded:
                _restore_ulm_header(fh, recorded)
            fh.flush()
            os.fsync(fh.fileno())
        if name == "mdanalysis":
            for suffix in ("_offsets.npz", "_offsets.lock"):
                path.with_name(f".{path.name}{suffix}").unlink(missing_ok=True)
        trimmed.append(name)
    return trimmed


def _restore_ulm(path, recorded):
    nitems, pos0 = ulm_header(path)
    if (nitems, pos0) != (recorded["nitems"], recorded["pos0"]):
        with open(path, "r+b") as fh:
            _restore_ulm_header(fh, recorded)


def _restore_ulm_header(fh, recorded):
    fh.seek(32)
    fh.write(np.array([recorded["nitems"], recorded["pos0"]], dtype="<i8").tobytes())


def check_apart_from_inputs(outputs, inputs, allowed=()):
    """Refuse an output on the path of an input, before anything is read or written.

    An output there would replace the input (a log over the configuration, a
    trajectory over the structure) or remove it (``--overwrite``).

    Parameters
    ----------
    outputs, inputs : dict
        Field name -> path (``None`` is skipped): what the run writes, what it reads.
    allowed : collection of (str, str)
        (output field, input field) pairs that may share a path: the input is
        read whole before the output is written.

    Raises
    ------
    OutputError
        Naming the output's field, its path and the input it is.
    """
    read = {}
    for name, path in inputs.items():
        if path is not None:
            read.setdefault(_identity(path), name)
    for name, path in outputs.items():
        if path is None:
            continue
        source = read.get(_identity(path))
        if source is None or (name, source) in allowed:
            continue
        raise OutputError(f"{name}: {path} is also the {source} this run reads, which "
                          f"writing it would destroy; give {name} another file, or copy the "
                          f"{source} elsewhere first")


def _identity(path):
    """What names one file: its device and inode when it exists (a link, another spelling),
    else its resolved path."""
    path = Path(path).resolve()  # "out/../c.yaml" is c.yaml before "out" exists too
    try:
        info = path.stat()
    except OSError:
        return str(path)
    return (info.st_dev, info.st_ino)


def describe_os_error(err, path=None):
    """One line for a failed write: the file and the reason (disk full, permission)."""
    reason = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
              errno.EACCES: "permission denied", errno.EROFS: "the file system is read-only"
              }.get(err.errno, err.strerror or str(err))
    where = path or getattr(err, "filename", None) or "an output file"
    return f"cannot write {where}: {reason}"
