"""Hypothesis's ``given``, ``settings``, ``strategies`` and ``HealthCheck``, or stand-ins.

Hypothesis comes with the test extra (``pip install -e ".[test]"``).  Without it a
property test (one under ``@given``) is collected and skipped with the reason, and the
other tests of its module run: ``from hypothesis_or_skip import given, settings, st``.

The test suite draws the same examples on every run (hypothesis's ``derandomize``), so a
commit passes or fails the same way on every machine: a random draw in CI once failed a
commit for a fault in code the commit had not touched.  Searching for new faults is a
separate, deliberate run with fresh random examples, as many times more as asked::

    FUZZ_RANDOM=1 FUZZ_SCALE=20 python -m pytest -n auto tests

A fault it finds goes into a test of its own (each module keeps a list of the cases its
fuzzing found), so the fixed draw keeps it.
"""

import os

import pytest

REASON = 'needs hypothesis (pip install hypothesis; the test extra ".[test]" has it)'

FUZZ_RANDOM = os.environ.get("FUZZ_RANDOM", "") not in ("", "0")
FUZZ_SCALE = float(os.environ.get("FUZZ_SCALE", "1"))

try:
    import hypothesis
    from hypothesis import HealthCheck, given
    from hypothesis import strategies as st
except ImportError:
    class _Anything:
        """Stands for any strategy or health check: every attribute and call is itself."""

        def __getattr__(self, name):
            return self

        def __call__(self, *args, **kwargs):
            return self

    st = HealthCheck = _Anything()

    def settings(*args, **kwargs):
        """Hypothesis's settings decorator: nothing to set without hypothesis."""
        return lambda test: test

    def given(*args, **kwargs):
        """A test without arguments, in place of the property test, that skips."""
        def skipped_property_test(test):
            def skipped():
                pytest.skip(REASON)

            for name in ("__name__", "__qualname__", "__doc__", "__module__"):
                setattr(skipped, name, getattr(test, name))
            if hasattr(test, "pytestmark"):
                skipped.pytestmark = test.pytestmark
            return skipped
        return skipped_property_test

else:
    hypothesis.settings.register_profile(
        "rigidmd", derandomize=not FUZZ_RANDOM, print_blob=True,
        database=hypothesis.database.DirectoryBasedExampleDatabase(".hypothesis/examples")
        if FUZZ_RANDOM else None)
    hypothesis.settings.load_profile("rigidmd")

    def settings(*args, max_examples=None, **kwargs):
        """Hypothesis's settings, the number of examples times ``FUZZ_SCALE``."""
        if max_examples is not None:
            kwargs["max_examples"] = max(1, round(max_examples * FUZZ_SCALE))
        return hypothesis.settings(*args, **kwargs)

__all__ = ["HealthCheck", "given", "settings", "st", "REASON", "FUZZ_RANDOM", "FUZZ_SCALE"]
