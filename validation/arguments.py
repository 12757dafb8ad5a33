"""Argument types shared by the validation scripts' command lines: each refuses, in
argparse's one line naming the option, a value that would run nothing or run wrong (a run
of 0 ps marked complete, --jobs 0 waiting for ever, --repeats 0 writing empty tables over the
committed ones)."""

import argparse

__all__ = ["positive", "at_least_zero", "whole"]


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
