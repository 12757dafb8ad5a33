"""The property tests draw the same examples on every run unless a fuzzing run asks for
fresh ones (``FUZZ_RANDOM=1``): a commit passes or fails CI the same way every time."""

import pytest
from hypothesis_or_skip import FUZZ_RANDOM, given, settings, st


def draws():
    seen = []

    @settings(max_examples=20, deadline=None)
    @given(st.integers(), st.text(max_size=5))
    def record(number, text):
        seen.append((number, text))

    record()
    return seen


@pytest.mark.skipif(FUZZ_RANDOM, reason="a fuzzing run (FUZZ_RANDOM=1) draws fresh examples")
def test_two_runs_of_a_property_test_draw_the_same_examples():
    first, second = draws(), draws()
    assert len(first) >= 10  # the draw is not empty (it stops early only on duplicates)
    assert first == second
