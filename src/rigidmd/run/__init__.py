"""Running: the command line, the runner, checkpoints and restarts, outputs, logs, plots.

Nothing is re-exported here: :func:`rigidmd.load_checkpoint` is the public name; import a
module of this package by its full path (``from rigidmd.run.restart import load_checkpoint``).
"""
