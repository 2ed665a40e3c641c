"""Nearest-time search over a circular timestamp vector (fxis_shm.core.timesearch)."""

from __future__ import annotations

import bisect

import pytest
from hypothesis import given, settings, strategies as st

from fxis_shm.core.timesearch import Timeline

from .timeline_helpers import brute_nearest, ring

STEP = 100  # spacing of the frames in the hand-made rings


def fill_levels(n: int):
    """(n, start, count) for every fill level of an n-slot ring, unwrapped and wrapped."""
    return [(n, start, count) for start in (0, 1, n - 1) for count in range(1, n + 1)]


@pytest.mark.parametrize("n, start, count", fill_levels(5) + fill_levels(20))
def test_nearest_at_every_fill_level(n, start, count):
    times = [1000 + STEP * k for k in range(count)]
    tl = ring(times, n, start)
    for k, t in enumerate(times):
        assert tl.nearest(t) == k, "exact hit"
        assert tl.nearest(t - STEP // 4) == k, "a little before"
        assert tl.nearest(t + STEP // 4) == k, "a little after"
    for k in range(count - 1):
        assert tl.nearest(times[k] + STEP // 2) == k + 1, "exactly halfway: the newer frame"
    assert tl.nearest(times[0] - 10 * STEP) == 0, "before the oldest"
    assert tl.nearest(times[-1] + 10 * STEP) == count - 1, "after the newest"


def test_logical_indices_map_onto_wrapped_physical_slots():
    # 7 slots; the oldest frame (100) sits at physical index 3
    tl = Timeline([500, 600, 700, 100, 200, 300, 400], start=3, count=7)
    assert [tl.at(i) for i in range(7)] == [100, 200, 300, 400, 500, 600, 700]
    assert [tl.physical(i) for i in range(7)] == [3, 4, 5, 6, 0, 1, 2]
    assert tl.nearest(620) == 5  # 600, stored at physical 1
    assert tl.physical(tl.nearest(620)) == 1
    assert tl.nearest(420) == 3  # 400, the last slot before the wrap
    assert tl.nearest(480) == 4  # 500, the first slot after the wrap


def test_slots_outside_the_valid_range_are_never_read():
    # count < n: physical slots 1 and 2 hold junk that would break any search reading them
    tl = Timeline([300, -5, 10**12, 100, 200], start=3, count=3)
    assert [tl.nearest(t) for t in (0, 160, 260, 10**13)] == [0, 1, 2, 2]
    assert list(tl.within(0, 10**13)) == [0, 1, 2]


@pytest.mark.parametrize("start", [0, 2, 4])
@pytest.mark.parametrize(
    "times, t_star, expected",
    [
        ([100, 200, 200, 200, 300], 200, 3),  # exact hit on a run of equal times: newest
        ([100, 200, 200, 200, 300], 190, 3),
        ([100, 200, 200, 200, 300], 240, 3),
        ([100, 200, 200, 200, 300], 250, 4),  # halfway between 200 and 300
        ([100, 200, 200, 200, 300], 150, 3),  # halfway between 100 and the 200s: newest 200
        ([100, 100, 200], 0, 1),  # before the oldest, which is duplicated
        ([100, 200, 200], 10**6, 2),  # after the newest, which is duplicated
        ([100, 200, 200], 160, 2),
        ([7, 7, 7, 7, 7], 7, 4),
        ([7, 7, 7, 7, 7], -100, 4),
        ([100, 200], 150, 1),  # exactly halfway: the later frame
        ([100, 101], 100, 0),  # an exact hit beats a neighbour one ns away
    ],
)
def test_ties_go_to_the_newest_frame(times, t_star, expected, start):
    n = len(times) + 1
    assert ring(times, n, start).nearest(t_star) == expected


@pytest.mark.parametrize("t_star", [-(10**18), 0, 999, 1000, 1001, 10**18])
def test_a_single_frame_is_always_the_nearest(t_star):
    assert ring([1000], n=4, start=2).nearest(t_star) == 0


@pytest.mark.parametrize("tl", [Timeline([], 0, 0), Timeline([1, 2, 3], start=1, count=0)])
def test_nearest_on_an_empty_timeline_raises(tl):
    assert len(tl) == 0
    with pytest.raises(ValueError):
        tl.nearest(0)


@pytest.mark.parametrize(
    "times, start, count",
    [([1, 2, 3], 0, 4), ([1, 2, 3], 3, 1), ([1, 2, 3], -1, 1), ([1, 2, 3], 0, -1)],
)
def test_inconsistent_start_or_count_is_rejected(times, start, count):
    with pytest.raises(ValueError):
        Timeline(times, start, count)


TIMES = [100, 200, 200, 300, 400]


@pytest.mark.parametrize(
    "lo, hi, expected",
    [
        (200, 300, [200, 200, 300]),  # both ends inclusive, duplicates included
        (150, 350, [200, 200, 300]),
        (0, 99, []),  # before the oldest
        (401, 500, []),  # after the newest
        (0, 10**6, TIMES),
        (250, 260, []),  # a gap between frames
        (400, 400, [400]),
        (300, 200, []),  # empty range
    ],
)
def test_within_returns_the_frames_in_a_closed_interval(lo, hi, expected):
    tl = ring(TIMES, n=8, start=6)  # wrapped
    assert [tl.at(i) for i in tl.within(lo, hi)] == expected


@pytest.mark.parametrize("t", [50, 100, 150, 200, 250, 400, 450])
def test_bisect_matches_the_standard_library(t):
    tl = ring(TIMES, n=6, start=3)
    assert tl.bisect_left(t) == bisect.bisect_left(TIMES, t)
    assert tl.bisect_right(t) == bisect.bisect_right(TIMES, t)


@st.composite
def stored_rings(draw):
    """(logical times, Timeline): a random sorted sequence in a random ring at a random start.
    Times come from a narrow range so that duplicates and exact halfway points are common."""
    times = sorted(draw(st.lists(st.integers(0, 60), min_size=1, max_size=25)))
    n = len(times) + draw(st.integers(0, 6))
    start = draw(st.integers(0, n - 1))
    return times, ring(times, n, start)


@settings(max_examples=200, derandomize=True, deadline=None)
@given(stored=stored_rings(), t_star=st.integers(-10, 70))
def test_nearest_agrees_with_brute_force(stored, t_star):
    times, tl = stored
    assert tl.nearest(t_star) == brute_nearest(times, t_star)


@settings(max_examples=200, derandomize=True, deadline=None)
@given(stored=stored_rings(), lo=st.integers(-10, 70), width=st.integers(0, 30))
def test_within_and_bisect_agree_with_brute_force(stored, lo, width):
    times, tl = stored
    hi = lo + width
    assert list(tl.within(lo, hi)) == [i for i, t in enumerate(times) if lo <= t <= hi]
    assert tl.bisect_left(lo) == bisect.bisect_left(times, lo)
    assert tl.bisect_right(lo) == bisect.bisect_right(times, lo)
