"""Camera timestamps onto CLOCK_MONOTONIC (fxis_shm.core.clocks)."""

import random

import pytest

from fxis_shm.core.clocks import DeviceClockFit, wall_to_monotonic

MS = 1_000_000


def test_wall_stamps_use_the_offset_read_at_conversion():
    # the wall clock is 1000 s ahead of the monotonic clock, then stepped back by 3 s
    assert wall_to_monotonic(1_000_500 * MS, monotonic_now_ns=600 * MS, wall_now_ns=1_000_600 * MS) == 500 * MS
    assert wall_to_monotonic(997_700 * MS, monotonic_now_ns=800 * MS, wall_now_ns=997_800 * MS) == 700 * MS


def test_device_fit_recovers_offset_and_drift_through_the_least_delays():
    rng = random.Random(1)
    fit = DeviceClockFit(tick_ns=8.0)  # 125 MHz device clock
    true_offset, drift = 5_000 * MS, 1 + 40e-6  # the device clock runs 40 ppm slow
    for k in range(200):
        capture_ticks = 1_000_000 + k * 6_250_000  # 50 ms apart
        capture_host = true_offset + drift * capture_ticks * 8.0
        delay = 2 * MS + (0 if k % 10 == 0 else rng.uniform(0, 3 * MS))  # some frames least delayed
        fit.add(capture_ticks, int(capture_host + delay))
    probe = 1_000_000 + 150 * 6_250_000
    expected = true_offset + drift * probe * 8.0 + 2 * MS  # capture + the least delay
    assert fit.to_host(probe) == pytest.approx(expected, abs=0.3 * MS)
    assert fit.drift == pytest.approx(drift, rel=2e-5)


def test_device_fit_restarts_when_the_device_clock_goes_back():
    fit = DeviceClockFit()
    fit.add(1000, 5000)
    fit.add(2000, 6000)
    fit.add(10, 9000)  # the camera rebooted
    assert len(fit) == 1 and fit.to_host(10) == 9000


def test_device_fit_needs_a_frame():
    with pytest.raises(ValueError):
        DeviceClockFit().to_host(1)


def test_a_ptp_camera_s_time_is_moved_into_the_service_clock_as_it_is():
    from fxis_shm.core.clocks import PtpClock

    tai_minus_service = 37 * 10**9 + 123  # e.g. a service on CLOCK_REALTIME
    clock = PtpClock(lambda: (1_000_000, 1_000_000 + tai_minus_service))
    clock.add(5, 10**12)  # nothing is fitted: arrival times do not move it
    assert len(clock) == 1
    assert clock.to_host(2_000_000_000_000) == 2_000_000_000_000 - tai_minus_service
    ticks = PtpClock(lambda: (0, 0), tick_ns=8.0)  # a camera counting 125 MHz ticks
    assert ticks.to_host(1000) == 8000
