"""The output directory of one run: its files, its lock, what is in the way, what it opened.

* :meth:`RunFiles.open` creates the directory and takes its lock
  (:class:`~rigidmd.run.outputs.OutputLock`); :meth:`RunFiles.abandon` undoes
  what a run that failed before its first checkpoint did there, so that the
  corrected configuration starts without ``--overwrite``.
* :meth:`RunFiles.prepare` refuses a new run into a directory that holds an
  earlier run's outputs, removes them when the run replaces them, and removes
  the temporary files of a checkpoint write that was killed.
* :class:`NamedOutput` makes the write errors of an output observer name its
  file.
"""

import os
from pathlib import Path

from rigidmd.config import ConfigError
from rigidmd.run.outputs import OutputError, OutputLock, describe_os_error

__all__ = ["RunFiles", "NamedOutput"]


class NamedOutput:
    """An output observer whose write errors name its file (ASE's carry no file name)."""

    modifies_atoms = False

    def __init__(self, function, path):
        self.function, self.path = function, path

    def __call__(self, *args, **kwargs):
        try:
            return self.function(*args, **kwargs)
        except OSError as err:
            if err.filename is None:
                raise type(err)(err.errno, err.strerror or str(err), str(self.path)) from None
            raise


def _missing_directories(directory):
    """The directories ``directory.mkdir(parents=True)`` would create, deepest first (the
    path taken as written, ``..`` resolved by name)."""
    path = Path(os.path.normpath(directory.absolute()))
    missing = []
    while not path.exists() and path != path.parent:
        missing.append(path)
        path = path.parent
    return missing


class RunFiles:
    """The output files of one run in its directory.

    Parameters
    ----------
    outputs : rigidmd.config.OutputsSection
        The configuration's ``outputs:`` section (paths already resolved).
    mode : {"new", "resume", "overwrite", "demo"}
        As for :class:`rigidmd.run.runner.Run`.
    stream : file
        Where messages go.
    relax : rigidmd.config.relaxsection.RelaxSection, optional
        The run's ``relax:`` section: its trajectory and log are the run's
        outputs too (a new run does not replace an earlier relaxation unless
        ``--overwrite``).

    Attributes
    ----------
    created : list of pathlib.Path
        The output files this run creates (none was there before it).
    made_directories : list of pathlib.Path
        The directories :meth:`open` created (``outputs.directory`` and those of its
        parents that did not exist), deepest first.
    """

    def __init__(self, outputs, mode, stream, relax=None):
        self.outputs, self.mode, self.stream = outputs, mode, stream
        self.relaxation = [] if relax is None else [outputs.directory / relax.trajectory,
                                                   outputs.directory / relax.log]
        self.created = []
        self.made_directories = []

    def appended(self):
        """The files a run appends to (trimmed on resume): ``{name: path}``."""
        out = self.outputs
        return {name: path for name, path in (("trajectory", out.trajectory), ("log", out.log),
                                              ("mdanalysis", out.mdanalysis)) if path}

    def all(self):
        """Every file the run writes (the checkpoint included)."""
        files = list(self.appended().values())
        if self.outputs.mdanalysis is not None:
            files.append(self.outputs.mdanalysis.with_suffix(".psf"))
        files += [p for p in (self.outputs.plot, self.outputs.checkpoint) if p]
        return self.relaxation + files

    def named(self):
        """Every file the run writes (the lock file included), by its field: ``{field: path}``."""
        from rigidmd.run.outputs import LOCK_NAME
        from rigidmd.run.relaxstructure import state_path

        out = self.outputs
        named = {f"outputs.{name}": path for name, path in out.files.items()}
        if out.mdanalysis is not None:
            named["outputs.mdanalysis topology"] = out.mdanalysis.with_suffix(".psf")
        named["outputs.checkpoint"] = out.checkpoint
        if self.relaxation:
            trajectory, log = self.relaxation
            named.update({"relax.trajectory": trajectory, "relax.log": log,
                          "relax state": state_path(trajectory)})
        named["the lock file"] = out.directory / LOCK_NAME
        return named

    def fresh_start_advice(self):
        """How to go on without the checkpoint: keeping the outputs first, then removing them."""
        trajectory = self.outputs.trajectory
        keep = ""
        if trajectory is not None and trajectory.exists():
            keep = (f"start a new run from its last frame with --restart {trajectory} "
                    "--outdir NEW_DIRECTORY (which keeps these outputs), or ")
        return f"{keep}start it again with --overwrite (which removes them)"

    # ------------------------------------------------------------ the directory
    def open(self):
        """Create the directory (and its missing parents) if needed and take its lock;
        returns the held lock.  On failure, the directories it created are removed."""
        out = self.outputs
        self.made_directories = _missing_directories(out.directory)
        try:
            out.directory.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            self.remove_made_directories()
            raise OutputError(f"outputs.directory: cannot create {out.directory} "
                              f"({describe_os_error(err).split(': ', 1)[-1]})") from None
        lock = OutputLock(out.directory)
        try:
            lock.acquire()
        except OSError as err:
            self.remove_made_directories()
            reason = describe_os_error(err).rsplit(": ", 1)[-1]
            raise OutputError(f"outputs.directory: cannot write in {out.directory} "
                              f"({reason})") from None
        if lock.stale:
            print(f"taking over the lock left by process {lock.stale.get('pid')}, which is gone",
                  file=self.stream)
        return lock

    def abandon(self, lock, started):
        """After a failure: release ``lock``; a run that never ``started`` (wrote no
        checkpoint) also removes the outputs it opened, and the directory it created."""
        removed = [] if started else self.remove_created()
        if removed:
            print(f"the run did not start: removed {', '.join(removed)}, which it had "
                  "opened", file=self.stream)
        lock.release()
        self.remove_made_directories()  # a run that could not start leaves no empty directory

    def remove_made_directories(self):
        """Remove the directories :meth:`open` created, deepest first, while they are empty
        (one that holds outputs, a run's that had started, stays, and so do its parents)."""
        for directory in self.made_directories:
            try:
                directory.rmdir()
            except FileNotFoundError:
                continue  # (mkdir failed before it)
            except OSError:
                return
        self.made_directories = []

    def remove_created(self):
        """Remove the outputs of a new run that failed before its first checkpoint.

        Such a run never started: what it opened (a log header, an empty
        trajectory) would only block the corrected configuration.  Returns the
        names removed.
        """
        removed = []
        for path in self.created:
            if path.exists():
                path.unlink()
                removed.append(path.name)
        return removed

    def prepare(self, earlier_demo, replace=False, keep=()):
        """Make the directory ready for the run's mode, before anything is written.

        Parameters
        ----------
        earlier_demo : callable
            ``earlier_demo()`` says whether the checkpoint in the directory is
            this demo's (asked only for a demo into a directory with outputs).
        replace : bool
            Remove the outputs under ``--resume`` too (a resume from step 0).
        keep : sequence of pathlib.Path
            Outputs that ``replace`` keeps (a stopped relaxation continued: its
            trajectory, log and checkpoint).
        """
        from rigidmd.core.checkpoint import remove_stale_temporaries

        existing = [p for p in self.all() if p.exists() and p not in keep]
        names = ", ".join(p.name for p in existing)
        if self.mode == "new" and existing and self.outputs.checkpoint.exists():
            raise ConfigError(
                f"outputs: {self.outputs.directory} already holds {names} from an earlier run; "
                "continue it with --resume, or replace it with --overwrite")
        if self.mode == "new" and existing:  # (--resume would only refuse)
            raise ConfigError(
                f"outputs: {self.outputs.directory} already holds {names} from an earlier run; "
                "nothing there can be continued (no checkpoint: a relaxation by rigidmd "
                "relax, or a run stopped before its first checkpoint); replace it with "
                "--overwrite, or give another directory")
        if self.mode == "demo" and existing and not earlier_demo():
            raise ConfigError(
                f"outputs: {self.outputs.directory} holds {names}, which are not an earlier "
                "demo's; give the demo another --outdir")
        # No other run writes here (the lock is ours): a temporary file is a killed write's.
        stale = remove_stale_temporaries(self.outputs.checkpoint)
        if stale:
            print(f"removed {', '.join(stale)}, left by a checkpoint write that was killed",
                  file=self.stream)
        if (self.mode == "resume" and not replace) or not existing:
            return
        verb = "replacing the earlier demo's" if self.mode == "demo" else "removing"
        print(f"{verb} {names} in {self.outputs.directory}", file=self.stream)
        for path in existing:
            path.unlink()

    def note_created(self):
        """Record the files the run is about to create (call when none of its is there)."""
        self.created = [p for p in self.all() if not p.exists()]

    def name_outputs(self, dyn):
        """Wrap the trajectory and log observers so that their write errors name the file.

        Called before the run attaches its own observers: the dynamics has only
        these two (ASE's trajectory writer, an ``MDLogger``) then.
        """
        from ase.md.logger import MDLogger

        named = []
        for function, interval, args, kwargs in dyn.observers:
            owner = getattr(function, "__self__", function)
            path = self.outputs.log if isinstance(owner, MDLogger) else self.outputs.trajectory
            named.append((NamedOutput(function, path), interval, args, kwargs))
        dyn.observers[:] = named
