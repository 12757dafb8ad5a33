"""Argument types shared by the validation scripts' command lines: each refuses, in
argparse's one line naming the option, a value that would run nothing or run wrong (a run
of 0 ps marked complete, --jobs 0 waiting for ever, --repeats 0 writing empty tables over the
committed ones)."""

import argparse
import json
from pathlib import Path

__all__ = ["positive", "at_least_zero", "whole", "existing_file", "read_json",
           "read_results"]


def positive(text):
    """An argparse type: a positive finite number."""
    value = float(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def at_least_zero(text):
    """An argparse type: a finite number >= 0."""
    value = float(text)
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
    return value


def whole(least):
    """An argparse type: a whole number >= ``least``."""
    def parse_whole(text):
        value = int(text)
        if value < least:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {least}, got {text}")
        return value
    parse_whole.__name__ = f"whole number >= {least}"
    return parse_whole


def existing_file(text):
    """An argparse type: the path of a file that is there (a missing one is refused in
    argparse's line, not as a traceback when it is read)."""
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"no such file {text!r}")
    return path


def read_json(path):
    """The JSON in ``path``, or SystemExit in one line naming the file (missing, unreadable
    or not JSON)."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise SystemExit(f"{path}: not a readable JSON file ({err})") from None


def read_results(path, keys, script, prefix=""):
    """The results JSON in ``path`` of ``script`` (a dict holding every one of ``keys``),
    or SystemExit in one line naming the file and what it lacks (another script's file
    failed with a KeyError's traceback)."""
    result = read_json(path)
    missing = [k for k in keys if k not in result] if isinstance(result, dict) else list(keys)
    if missing:
        raise SystemExit(f"{prefix}{path} is not a results file of {script} "
                         f"(no {', '.join(missing)})")
    return result
