"""The camera worker's trigger log (workers/triggers.py): which trigger each stored frame answers,
the latency it learns, and the figures status shows. A plain object: no thread, no camera."""

from fxis_shm.core.schedule import MS
from fxis_shm.core.snapshot import CAPTURE_FREE, CAPTURE_LATE, CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED
from fxis_shm.workers.triggers import TriggerLog

T0 = 10_000 * MS


def test_each_frame_takes_the_trigger_it_answers_and_the_latency_is_learned():
    log = TriggerLog()
    log.fired(T0)  # "now", for a request
    log.fired(T0 + 100 * MS, T0 + 103 * MS, CAPTURE_SCHEDULED, late_ns=20_000)
    assert log.answer(T0 + 3 * MS) == (0, CAPTURE_FREE)
    assert log.answer(T0 + 103 * MS) == (T0 + 103 * MS, CAPTURE_SCHEDULED)
    assert log.latency_ns == 3 * MS and log.samples == 2
    assert log.answer(T0 + 200 * MS) == (0, CAPTURE_FREE)  # nothing fired for it: free


def test_a_lockstep_trigger_that_got_no_frame_is_missed_and_residuals_are_kept():
    log = TriggerLog()
    log.reset_lockstep((20.0, 0))
    for k in range(3):
        log.fired(T0 + k * 50 * MS - 3 * MS, T0 + k * 50 * MS, CAPTURE_LOCKSTEP, late_ns=10_000 * k)
    log.latency_ns, log.samples = 3 * MS, 8  # learned before
    assert log.answer(T0 + 100 * MS + 40_000) == (T0 + 100 * MS, CAPTURE_LOCKSTEP)  # points 0 and 1 got none
    figures = log.figures()
    assert figures["triggers_missed"] == 2 and figures["frames_lockstep"] == 1
    assert figures["residual_p50_ns"] == 40_000 and figures["lockstep_mhz"] == 20_000
    assert figures["timer_late_p99_ns"] == 20_000
    log.reset_lockstep(None)
    assert log.figures()["lockstep_mhz"] == 0 and log.figures()["triggers_missed"] == 0


def test_a_frame_that_missed_its_t_by_more_than_the_tolerance_is_answered_late():
    log = TriggerLog(tolerance_ns=MS)
    log.latency_ns, log.samples = 3 * MS, 8  # learned before
    log.fired(T0 - 3 * MS, T0, CAPTURE_SCHEDULED)
    log.fired(T0 + 97 * MS, T0 + 100 * MS, CAPTURE_SCHEDULED)
    assert log.answer(T0 + 500_000) == (T0, CAPTURE_SCHEDULED)
    assert log.answer(T0 + 101 * MS + 1) == (T0 + 100 * MS, CAPTURE_LATE)
    assert log.figures()["frames_scheduled"] == 2  # captured for a T, both
