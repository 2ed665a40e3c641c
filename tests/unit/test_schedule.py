"""The arithmetic of triggering for a moment (fxis_shm.core.schedule): numbers in, decisions out."""

import pytest

from fxis_shm.core import schedule
from fxis_shm.core.schedule import MS
from fxis_shm.core.snapshot import CAPTURE_FREE, CAPTURE_LATE, CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED
from fxis_shm.errors import Code

NOW = 5_000 * MS


def test_the_trigger_fires_the_learned_latency_before_the_moment():
    assert schedule.fire_time(NOW + 100 * MS, 3 * MS) == NOW + 97 * MS
    assert schedule.fire_time(NOW + 100 * MS, -1) == NOW + 100 * MS  # a latency is never negative


@pytest.mark.parametrize(
    ("lead_ms", "latency_ms", "says"),
    [
        (-10, 0, "10.0 ms in the past"),
        (4, 0, "nearest T this camera can be triggered for is 5.0 ms ahead"),
        (7, 3, "nearest T this camera can be triggered for is 8.0 ms ahead (5 ms to schedule + 3.0 ms"),
        (10_001, 0, "at most 10 s ahead"),
    ],
)
def test_a_moment_that_cannot_be_kept_is_refused_saying_why(lead_ms, latency_ms, says):
    refusal = schedule.check_target(NOW + lead_ms * MS, NOW, latency_ms * MS)
    assert refusal is not None and refusal.code == Code.OUT_OF_RANGE and says in refusal.message


@pytest.mark.parametrize(("lead_ms", "latency_ms"), [(5, 0), (8, 3), (100, 3), (10_000, 0)])
def test_a_moment_far_enough_ahead_is_kept(lead_ms, latency_ms):
    assert schedule.check_target(NOW + lead_ms * MS, NOW, latency_ms * MS) is None


def test_the_latency_is_a_mean_of_the_first_samples_then_an_exponential_average():
    latency = 0
    for n, sample in enumerate([4 * MS, 2 * MS], start=1):
        latency = schedule.learn_latency(latency, sample, n)
    assert latency == 3 * MS  # (4 + 2) / 2: a plain mean so far
    for n in range(3, 200):
        latency = schedule.learn_latency(latency, 10 * MS, n)
    assert abs(latency - 10 * MS) < 10_000  # follows a changed latency


def test_a_frame_answers_the_trigger_whose_expected_capture_is_nearest():
    fired = [NOW, NOW + 1 * MS, NOW + 50 * MS]
    # latency 3 ms: the frame at +3 ms is the first trigger's, not the second's (fired later, before it)
    assert schedule.answered_trigger(fired, NOW + 3 * MS, 3 * MS) == 0
    assert schedule.answered_trigger(fired, NOW + 4 * MS, 3 * MS) == 1
    assert schedule.answered_trigger(fired, NOW + 53 * MS, 3 * MS) == 2  # the first two got no frame
    assert schedule.answered_trigger(fired, NOW - 10 * MS, 3 * MS) is None  # before every trigger
    assert schedule.answered_trigger([], NOW, 0) is None


def test_a_frame_slightly_before_its_trigger_still_answers_it():
    """A camera's device time mapped onto the host's clock may land just before the trigger."""
    assert schedule.answered_trigger([NOW], NOW - 1 * MS, 0) == 0
    assert schedule.answered_trigger([NOW], NOW - 3 * MS, 0) is None


def test_the_grid_points_are_exact_far_from_the_grids_origin():
    """A realtime grid counts from 1970: a float period would put its points nanoseconds off."""
    now = 1_764_000_000_123_456_789
    point = schedule.next_grid_point(now, 20.0, 7 * MS)
    assert point >= now and point - now <= 50 * MS and (point - 7 * MS) % (50 * MS) == 0
    assert schedule.next_grid_point(point, 20.0, 7 * MS) == point  # a grid point is its own next
    assert schedule.next_grid_point(point, 20.0, 7 * MS, lead_ns=1) == point + 50 * MS
    third = schedule.next_grid_point(now, 30.0, 0)  # 33.333... ms: rounded up to whole ns
    assert 0 <= third * 30 % 10**9 < 30


def test_a_tai_grid_is_counted_in_tai_and_lands_in_the_services_clock():
    """TAI runs 37 s ahead of UTC (since 2017): the tai grid's points are its own, not realtime's
    shifted, when the period does not divide 37 s; each is a point of k/hz + phase in TAI."""
    monotonic_now, realtime_offset = 5_000 * 10**9, 1_764_000_000 * 10**9 - 5_000 * 10**9
    tai_offset = realtime_offset + 37 * 10**9
    period = schedule.grid_period(7.5)  # 133.333... ms
    tai = schedule.grid_target(monotonic_now, tai_offset, 7.5, 3 * MS, lead_ns=MS)
    realtime = schedule.grid_target(monotonic_now, realtime_offset, 7.5, 3 * MS, lead_ns=MS)
    assert monotonic_now + MS <= tai < monotonic_now + MS + period
    assert (tai + tai_offset - 3 * MS) * 15 % (2 * 10**9) < 15  # on the tai grid, to the ns it was rounded to
    assert abs(abs(tai - realtime) - period / 2) <= 1  # 37 s is 277.5 periods of 1/7.5 s


def test_a_lockstep_clock_is_one_the_hosts_of_a_cell_share():
    assert [schedule.check_grid_clock(c) for c in ("realtime", "tai")] == ["realtime", "tai"]
    with pytest.raises(ValueError, match="realtime or tai"):
        schedule.check_grid_clock("monotonic")


@pytest.mark.parametrize(
    ("text", "expected"),
    [("20", (20.0, 0)), ("20,5", (20.0, 5 * MS)), (" 12.5 , -2.5 ", (12.5, -2_500_000))],
)
def test_a_lockstep_option_reads_as_rate_and_phase(text, expected):
    assert schedule.parse_lockstep(text) == expected


@pytest.mark.parametrize(
    ("text", "says"), [("0", "above 0"), ("5000", "at most 1000 Hz"), ("x", "are numbers"), ("1,2,3", "HZ or")]
)
def test_a_bad_lockstep_option_says_what_is_wrong(text, says):
    with pytest.raises(ValueError, match=says):
        schedule.parse_lockstep(text)


def test_percentiles_by_nearest_rank():
    assert schedule.percentile([], 50) is None
    assert schedule.percentile([5, 1, 3], 50) == 3
    assert schedule.percentile(list(range(101)), 99) == 99
    assert schedule.percentile([7], 99) == 7


def test_a_frame_for_t_further_from_t_than_the_tolerance_is_late_and_only_such_a_frame():
    tolerance = 2 * MS
    for residual in (0, 2 * MS, -2 * MS, 500_000):
        assert schedule.captured_as(CAPTURE_SCHEDULED, NOW + residual, NOW, tolerance) == CAPTURE_SCHEDULED
    for residual in (2 * MS + 1, -2 * MS - 1, 336 * MS):  # 336 ms: the frames, once marked scheduled
        assert schedule.captured_as(CAPTURE_SCHEDULED, NOW + residual, NOW, tolerance) == CAPTURE_LATE
    # a free frame has no T; a lockstep frame keeps saying lockstep (its residual is in status)
    assert schedule.captured_as(CAPTURE_FREE, NOW + 336 * MS, 0, tolerance) == CAPTURE_FREE
    assert schedule.captured_as(CAPTURE_LOCKSTEP, NOW + 336 * MS, NOW, tolerance) == CAPTURE_LOCKSTEP
