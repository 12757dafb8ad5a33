"""Hypothesis's ``given``, ``settings``, ``strategies`` and ``HealthCheck``, or stand-ins.

Hypothesis comes with the test extra (``pip install -e ".[test]"``).  Without it a
property test (one under ``@given``) is collected and skipped with the reason, and the
other tests of its module run: ``from hypothesis_or_skip import given, settings, st``.
"""

import pytest

REASON = 'needs hypothesis (pip install hypothesis; the test extra ".[test]" has it)'

try:
    from hypothesis import HealthCheck, given, settings
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

__all__ = ["HealthCheck", "given", "settings", "st", "REASON"]
