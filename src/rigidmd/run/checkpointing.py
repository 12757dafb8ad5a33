"""The checkpoints of one run: what each records, and how ``--resume`` checks the one it reads.

* :meth:`RunCheckpoints.write` flushes the outputs, records each appended
  file's length, the configuration's digest (:func:`fingerprint`) and the
  steps asked for, and writes the checkpoint (atomically); :attr:`step` is the
  step of the last one on disk.
* :meth:`RunCheckpoints.read_for_resume` reads the checkpoint of the run to
  continue and compares the configuration with it field by field: a changed
  field is named, and a missing or unreadable checkpoint says how to go on.
"""

from rigidmd.config import ConfigError
from rigidmd.run.fingerprint import differing_fields, earlier_release_differences, fingerprint
from rigidmd.run.outputs import output_lengths

__all__ = ["RunCheckpoints"]


class RunCheckpoints:
    """Write the checkpoints of one run, and read the one a resumed run continues.

    Parameters
    ----------
    config : rigidmd.config.RunConfig
    files : rigidmd.run.directory.RunFiles
        The run's output files.
    stream : file
        Where messages go.

    Attributes
    ----------
    step : int or None
        Step of the last checkpoint on disk, once known.
    """

    def __init__(self, config, files, stream):
        self.config, self.files, self.stream = config, files, stream
        self.step = None
        self._fingerprint = None

    @property
    def fingerprint(self):
        """:func:`fingerprint` of the configuration, taken once (files are read once)."""
        if self._fingerprint is None:
            self._fingerprint = fingerprint(self.config)
        return self._fingerprint

    # ------------------------------------------------------------ writing
    def write(self, dyn, writer=None, relaxation=None):
        """Flush ``writer`` (an MDAnalysis writer, or None) and checkpoint ``dyn``.

        ``relaxation``: the run stopped in its ``relax:`` section, whose trajectory
        (this file name) ``--resume`` continues before the MD (``dyn`` is the start).
        """
        if writer is not None:
            writer.flush()
        extra = {"outputs": output_lengths(self.files.appended()),
                 "fingerprint": self.fingerprint, "steps": self.config.run.steps}
        if relaxation is not None:
            extra["relaxation"] = relaxation
        dyn.save_checkpoint(self.files.outputs.checkpoint, extra=extra)
        self.step = dyn.nsteps

    def write_after_undone_step(self, dyn, writer):
        """Checkpoint after a step an engine failed in: the stepper undid that step, and
        the steps before it, outputs included, are whole (``--resume`` starts there)."""
        try:
            self.write(dyn, writer)
        except OSError:
            pass  # the last checkpoint stays, and the message names it

    # ------------------------------------------------------------ reading
    def is_earlier_demo(self):
        """The checkpoint in the directory is a demo's (same fingerprint, any steps)."""
        from rigidmd.core.checkpoint import CheckpointError, read_checkpoint

        try:
            checkpoint = read_checkpoint(self.files.outputs.checkpoint)
        except CheckpointError:
            return False
        return checkpoint.extra.get("fingerprint") == self.fingerprint

    def read_for_resume(self):
        """The checkpoint to continue from, checked against the configuration.

        Returns
        -------
        rigidmd.core.checkpoint.Checkpoint

        Raises
        ------
        rigidmd.config.ConfigError
            No checkpoint, an unreadable one, or one whose run differs from
            the configuration (the fields are named).
        """
        from rigidmd.core.checkpoint import CheckpointError, read_checkpoint

        out = self.files.outputs
        if not out.checkpoint.exists():
            others = [p.name for p in self.files.all() if p.exists()]
            if others:
                raise ConfigError(
                    f"--resume: there is no checkpoint {out.checkpoint} beside "
                    f"{', '.join(others)}, so that run cannot be continued; start it again "
                    "with --overwrite")
            raise ConfigError(f"--resume: there is no run to continue in {out.directory} (no "
                              f"{out.checkpoint.name}); start one without --resume")
        try:
            checkpoint = read_checkpoint(out.checkpoint)
        except CheckpointError as err:
            raise ConfigError(f"--resume: {err}; the run cannot be continued from it: "
                              f"{self.files.fresh_start_advice()}") from None
        differing = differing_fields(checkpoint.extra.get("fingerprint"), self.fingerprint)
        if differing is None:
            differing = earlier_release_differences(self.config, checkpoint)
            if not differing:
                print("the checkpoint was written by an earlier rigidmd, which recorded the "
                      "configuration as one digest: its atoms, timestep, integrator and "
                      "thermostat/barostat were compared with the configuration and agree; "
                      "the calculator and outputs.interval cannot be compared (keep them as "
                      "they were)", file=self.stream)
        if differing:
            raise ConfigError(
                f"--resume: {', '.join(differing)} differ{'s' if len(differing) == 1 else ''} "
                "from the checkpoint's run (only steps may change between a run and its "
                "continuation); restore it, or start anew with --overwrite")
        return checkpoint
