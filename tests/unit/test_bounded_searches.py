"""The core's loops end within their bounds: a search over a ring reads O(log n) slots (the
paper's Algorithm 1), and the prediction of coming frames steps once per frame period. Each
test counts the steps and fails at once past the bound, so a fault that stops a loop from
moving fails here instead of hanging (the 9 mutants `make mutation` saw time out, issue 47)."""

from __future__ import annotations

import math

import pytest

from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import CameraState, with_predictions

from .timeline_helpers import CountedReads, ring


def wrapped(times: list[int], n: int, start: int) -> Timeline:
    """``times`` in a ring of ``n`` slots from ``start``, wrapped (the searches' own loop),
    reads counted up to 2 log2(n) + 4 (two bisections, and the nearest frame's neighbours)."""
    slots = ring(times, n, start).times
    return Timeline(CountedReads(slots, 2 * math.ceil(math.log2(n)) + 4), start, len(times))


TIMES = [10, 20, 20, 30, 40, 50, 60, 70]  # 8 frames in a ring of 11 slots, wrapped at slot 3


@pytest.mark.parametrize(
    "t, left, right",
    [(5, 0, 0), (10, 0, 1), (20, 1, 3), (25, 3, 3), (70, 7, 8), (71, 8, 8)],
)
def test_a_bisection_of_a_wrapped_ring_finds_its_index_in_a_logarithmic_number_of_reads(t, left, right):
    assert wrapped(TIMES, 11, 5).bisect_left(t) == left
    assert wrapped(TIMES, 11, 5).bisect_right(t) == right


@pytest.mark.parametrize("t_star, nearest", [(0, 0), (15, 2), (24, 2), (26, 3), (64, 6), (100, 7)])
def test_the_nearest_frame_of_a_wrapped_ring_in_a_logarithmic_number_of_reads(t_star, nearest):
    assert wrapped(TIMES, 11, 5).nearest(t_star) == nearest


class CountedBound(int):
    """A time bound that counts how often a loop compares against it, failing past ``limit``."""

    def __new__(cls, value: int, limit: int):
        bound = super().__new__(cls, value)
        bound.compared, bound.limit = 0, limit
        return bound

    def __ge__(self, other):  # `t <= bound` asks the bound (an int subclass) first
        self.compared += 1
        assert self.compared <= self.limit, f"compared {self.compared} times: the loop does not step towards {self}"
        return int(self) >= other


def test_predictions_step_one_period_at_a_time_up_to_the_bound():
    camera = CameraState(newest=100, period_ns=10, delay_ns=1, newest_stored=101)
    up_to = CountedBound(135, limit=4)  # 110, 120, 130 and the 140 that ends the loop
    extended, predicted = with_predictions(Timeline([90, 100], 0, 2), camera, now=121, up_to=up_to)
    assert predicted == [120, 130]  # 110 is overdue from 121 on (110 + period + delay): taken as dropped
    assert [extended.at(i) for i in range(len(extended))] == [90, 100, 120, 130]


def test_a_camera_of_unknown_period_predicts_nothing_without_looping():
    camera = CameraState(newest=100, period_ns=0, delay_ns=1, newest_stored=101)
    up_to = CountedBound(135, limit=0)  # not a single step: a period of 0 would never reach it
    timeline = Timeline([90, 100], 0, 2)
    assert with_predictions(timeline, camera, now=0, up_to=up_to) == (timeline, [])
