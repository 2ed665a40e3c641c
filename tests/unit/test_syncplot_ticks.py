"""The sync-report plot's ticks: round, evenly spaced, covering the range (issue 43: the y ticks
were 1.1/2.2/3.4/4.5, the x axis labelled only at its ends)."""

import math

import pytest

from fxis_shm.viewers.syncplot import nice_ticks


@pytest.mark.parametrize("top", [4.5, 1.0, 0.37, 10.2, 125.0, 0.0012, 3600.0, 7.0])
def test_ticks_are_round_even_and_cover_the_range(top):
    ticks = nice_ticks(top)
    steps = {round(b - a, 12) for a, b in zip(ticks, ticks[1:])}
    assert ticks[0] == 0 and ticks[-1] >= top and len(steps) == 1 and 3 <= len(ticks) <= 7, ticks
    (step,) = steps
    mantissa = step / 10 ** math.floor(math.log10(step))
    assert round(mantissa, 9) in (1, 2, 5), step
    assert ticks[-1] - step < top  # no tick beyond the one that covers it


def test_the_ticks_of_the_issue():
    assert nice_ticks(4.5) == [0, 1, 2, 3, 4, 5]
