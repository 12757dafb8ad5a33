"""The ``rigidmd`` console script's entry point.

It lives outside the :mod:`rigidmd` package so that a Ctrl-C while the package and
its dependencies (ASE, NumPy, SciPy, numba) are still being imported ends in one
line and exit status 130, not a traceback: nothing has run or been written then.
"""

import sys


def main() -> int:
    """Import the command line, then run it (:func:`rigidmd.run.cli.main`)."""
    try:
        from rigidmd.run.cli import main as command_line
    except KeyboardInterrupt:
        print("rigidmd: interrupted while starting; nothing was run or written",
              file=sys.stderr)
        return 130
    from rigidmd.run.signals import run_command

    return run_command(command_line)
