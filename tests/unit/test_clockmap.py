"""The clock estimator against synthetic exchanges whose true offset and drift are known."""

import random

import pytest

from fxis_shm.core.clockmap import ESTIMATED, ClockEstimate, ClockEstimator, Exchange

S = 1_000_000_000
US = 1_000


def exchange(t: int, offset: int, drift_ppm: float, there_us: float, back_us: float, serve_us: float = 30) -> Exchange:
    """An exchange starting at caller time ``t`` against a service clock of ``offset`` + drift,
    with one-way delays ``there_us`` and ``back_us``."""

    def service(tc):
        return tc + offset + round(drift_ppm * 1e-6 * tc)

    received = t + int(there_us * US)
    replied = received + int(serve_us * US)
    return Exchange(t, service(received), service(replied), replied + int(back_us * US))


def feed(
    est: ClockEstimator,
    rng: random.Random,
    seconds: int,
    offset: int,
    drift_ppm: float = 0.0,
    start: int = 10 * S,
    per_burst: int = 8,
    queueing_us: float = 2000,
    outlier_rate: float = 0.3,
):
    """One burst a second; each exchange has a base delay of 60 us each way plus, often, queueing
    on one side only (asymmetric): the kind of delays a loaded link adds."""
    for k in range(seconds):
        burst = []
        for j in range(per_burst):
            there = 60 + (rng.expovariate(1 / queueing_us) if rng.random() < outlier_rate else rng.uniform(0, 10))
            back = 60 + (rng.expovariate(1 / queueing_us) if rng.random() < outlier_rate else rng.uniform(0, 10))
            burst.append(exchange(start + k * S + j * 400 * US, offset, drift_ppm, there, back))
        est.add_burst(burst)
    return start + seconds * S


def test_one_exchange_gives_offset_and_half_the_round_trip():
    e = exchange(5 * S, 1000 * S, 0, there_us=100, back_us=100)
    assert e.offset == 1000 * S and e.round_trip == 200 * US
    est = ClockEstimator()
    est.add_burst([e])
    got = est.estimate()
    assert got.offset_ns == 1000 * S and got.uncertainty_ns == 100 * US and got.method == ESTIMATED


def test_asymmetric_queueing_and_outliers_do_not_move_the_offset():
    est = ClockEstimator()
    end = feed(est, random.Random(1), 30, offset=-123_456_789_000)
    got = est.estimate()
    assert abs(got.to_service(end) - (end - 123_456_789_000)) < 10 * US
    assert got.uncertainty_ns < 80 * US  # rests on the short exchanges, not the queued ones


def test_a_burst_of_only_queued_exchanges_is_left_out():
    est = ClockEstimator()
    feed(est, random.Random(2), 5, offset=0, outlier_rate=0)
    est.add_burst([exchange(20 * S, 0, 0, there_us=5000, back_us=60)])  # 2.5 ms off, all of it queueing
    assert abs(est.estimate().offset_ns) < 10 * US


@pytest.mark.parametrize("drift_ppm", [-50.0, 20.0, 100.0])
def test_drift_is_fitted_and_extrapolated(drift_ppm):
    est = ClockEstimator()
    end = feed(est, random.Random(3), 100, offset=7 * S, drift_ppm=drift_ppm)
    got = est.estimate()
    assert got.drift_ppm == pytest.approx(drift_ppm, abs=0.5)
    later = end + 2 * S  # between refreshes the line carries on
    truth = later + 7 * S + round(drift_ppm * 1e-6 * later)
    assert abs(got.to_service(later) - truth) < 10 * US


def test_no_drift_is_claimed_from_a_short_span():
    est = ClockEstimator()
    feed(est, random.Random(4), 3, offset=0)
    assert est.estimate().drift_ppm == 0.0


def test_offsets_near_the_int64_range_keep_every_nanosecond():
    wall_minus_monotonic = 1_764_000_000 * S + 123_456_789  # realtime against monotonic
    est = ClockEstimator()
    end = feed(est, random.Random(5), 40, offset=wall_minus_monotonic, drift_ppm=1.0)
    got = est.estimate()
    assert abs(got.to_service(end) - (end + wall_minus_monotonic + round(1e-6 * end))) < 10 * US


def test_old_bursts_leave_the_window():
    est = ClockEstimator(window_ns=10 * S)
    feed(est, random.Random(6), 30, offset=0)
    assert len(est) <= 11


def test_to_caller_inverts_to_service():
    got = ClockEstimate(5 * S, drift_ppm=30.0, at_ns=100 * S)
    for t in (0, 100 * S, 10_000 * S):
        assert abs(got.to_caller(got.to_service(t)) - t) <= 1


def test_nothing_to_estimate_from():
    est = ClockEstimator()
    assert est.estimate() is None
    est.add_burst([Exchange(10, 0, 100, 20)])  # replied long after it was back: broken stamps
    assert est.estimate() is None
