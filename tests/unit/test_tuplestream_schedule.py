"""How far a joint tuple stream (client/tuplestream.py) may fall behind its schedule and still
catch up: never so far that the time it asks next is older than what the cameras hold (a
stream a ring behind failed OUT_OF_RANGE instead of giving up the times it missed)."""

import pytest

from fxis_shm.client.tuplestream import GIVE_UP_NS, catch_up_limit_ns, next_time

MS = 1_000_000


def test_without_a_known_ring_a_stream_catches_up_a_second():
    assert catch_up_limit_ns(80 * MS, 45 * MS, None) == GIVE_UP_NS == 1000 * MS


def test_a_ring_shorter_than_a_second_bounds_it():
    # 20 frames at 50 fps hold 380 ms: asking t* then needs it held for lag + one interval more
    assert catch_up_limit_ns(80 * MS, 45 * MS, 380 * MS) == 255 * MS
    assert catch_up_limit_ns(80 * MS, 45 * MS, 10_000 * MS) == GIVE_UP_NS


def test_never_less_than_one_interval():
    assert catch_up_limit_ns(80 * MS, 45 * MS, 100 * MS) == 80 * MS


@pytest.mark.parametrize("late_ms", [0, 79, 80, 254, 255, 256, 390, 700, 5000])
def test_the_next_time_asked_is_still_held(late_ms):
    """The schedule's rule (TupleStream._schedule): late past the limit gives up whole intervals."""
    interval, lag, held = 80 * MS, 45 * MS, 380 * MS
    late = late_ms * MS
    # now is 0, and the t* one interval on from the last is ``late`` behind (t* + lag)
    t_star = next_time(-lag - late - interval, interval, lag, held, now=0)
    assert -t_star <= held  # what it asks next is no older than the ring's span
    assert (t_star + lag + late) % interval == 0  # still on the schedule's grid
