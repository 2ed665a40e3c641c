"""The sync report's figures (fxis_shm.core.syncstats): gaps, synced and dropped tuples, frame-id
faults, capture methods, residuals and the verdict, from hand-made schedules."""

import numpy as np
import pytest

from fxis_shm.core.syncstats import (
    ABSENT,
    CAPTURE_METHODS,
    Samples,
    Thresholds,
    advance_faults,
    estimated_period_ns,
    figures,
    gaps_ns,
)

MS = 1_000_000
PERIOD = 50 * MS  # 20 fps
FREE, SCHEDULED, LOCKSTEP, LATE = (CAPTURE_METHODS.index(m) for m in ("free", "scheduled", "lockstep", "late"))


def schedule(n: int, offsets_ms: list[float], interval: int = PERIOD, period: int = PERIOD) -> dict:
    """n slots every ``interval``; camera c captures frame k at k*period + offsets_ms[c], and each
    slot's tuple holds each camera's frame nearest to t_k (what a joint tuple would hold)."""
    slots = np.arange(n, dtype=np.int64) * interval + 1_000 * MS
    ids, times = [], []
    for offset in offsets_ms:
        frame = np.rint((slots - offset * MS) / period).astype(np.int64)
        ids.append(frame)
        times.append(frame * period + round(offset * MS))
    return {
        "slots": slots,
        "frame_id": np.stack(ids, axis=1),
        "t_capture": np.stack(times, axis=1),
        "generation": np.zeros((n, len(offsets_ms)), dtype=np.int64),
        "capture": np.full((n, len(offsets_ms)), FREE, dtype=np.int64),
        "residual_ns": np.full((n, len(offsets_ms)), np.nan),
    }


def samples(parts: dict, cameras=("a", "b")) -> Samples:
    return Samples(cameras=list(cameras), **parts)


def test_cameras_in_phase_pass_librealsenses_criteria():
    report = figures(samples(schedule(100, [0.0, 0.4])))
    assert report.slots == 100 and report.complete == 100
    assert report.gap_ms["p50"] == pytest.approx(0.4) and report.gap_ms["p99"] == pytest.approx(0.4)
    assert report.synced_pct == 100.0 and report.dropped_pct == 0.0
    assert all(cam.missing == cam.repeated == cam.skipped == 0 for cam in report.cameras.values())
    assert report.cameras["a"].period_ms == pytest.approx(50.0)  # estimated from the frames
    assert report.cameras["a"].captures == {"free": 100, "scheduled": 0, "lockstep": 0, "late": 0}
    assert report.cameras["a"].residual_ms is None  # free frames have no target
    assert report.passed and [c.passed for c in report.checks] == [True, True, True]


def test_a_phase_of_20_ms_fails_on_the_gap_and_the_synced_share_not_on_drops():
    report = figures(samples(schedule(100, [0.0, 20.0])))
    assert report.gap_ms["p95"] == pytest.approx(20.0)
    assert report.synced_pct == 0.0 and report.dropped_pct == 0.0
    assert not report.passed
    assert {c.name: c.passed for c in report.checks} == {"p95 gap": False, "synced": False, "dropped": True}


def test_the_threshold_and_limits_are_the_callers():
    parts = schedule(100, [0.0, 20.0])
    loose = Thresholds(threshold_ms=25.0, max_p95_ms=25.0)
    assert figures(samples(parts), loose).passed
    strict = Thresholds(threshold_ms=1.0, max_p95_ms=1.0)
    assert not figures(samples(schedule(100, [0.0, 2.0])), strict).checks[0].passed


def test_a_camera_missing_from_tuples_drops_them_and_leaves_their_gaps_out():
    parts = schedule(100, [0.0, 0.5])
    parts["capture"][40:50, 1] = ABSENT  # camera b down for 10 slots
    parts["t_capture"][40:50, 1] = 0  # whatever the arrays hold there is not read
    report = figures(samples(parts))
    assert report.complete == 90 and report.cameras["b"].missing == 10
    assert report.gap_ms["max"] == pytest.approx(0.5)
    assert report.synced_pct == 90.0 and report.dropped_pct == 10.0
    assert report.cameras["b"].repeated == report.cameras["b"].skipped == 0  # ids resume as the period says
    assert not report.passed and {c.name for c in report.checks if not c.passed} == {"synced", "dropped"}


def test_repeated_and_skipped_frame_ids_are_dropped_tuples():
    parts = schedule(100, [0.0, 0.5])
    parts["frame_id"][10, 0] = parts["frame_id"][9, 0]  # the same frame twice: a repeat at 10, a skip at 11
    parts["frame_id"][30:, 1] += 3  # three frames of b lost before slot 30
    report = figures(samples(parts))
    assert report.cameras["a"].repeated == 1 and report.cameras["a"].skipped == 1
    assert report.cameras["b"].repeated == 0 and report.cameras["b"].skipped == 3
    assert report.dropped_pct == 3.0  # slots 10, 11 and 30
    assert report.synced_pct == 100.0  # their gaps are fine: dropped and synced are separate questions


def test_ids_are_judged_by_the_nominal_period_when_given():
    parts = schedule(20, [0.0, 0.0], period=PERIOD // 2)  # cameras at 40 fps, slots at 20 Hz: e = 2
    assert figures(samples(parts)).dropped_pct == 0.0
    # told the cameras run at 20 fps, every advance of 2 is a skip of 1
    judged = figures(samples(parts), nominal_period_ns={"a": PERIOD, "b": PERIOD})
    assert judged.cameras["a"].skipped == 19 and judged.dropped_pct == 95.0


def test_slots_at_a_rate_that_does_not_divide_the_frames_take_either_nearest_frame_without_fault():
    parts = schedule(70, [0.0, 7.0], interval=round(1e9 / 7))  # 2.857 periods a slot: ids advance 2 or 3
    steps = set(np.diff(parts["frame_id"][:, 0]).tolist())
    assert steps == {2, 3}
    assert figures(samples(parts)).dropped_pct == 0.0
    parts["frame_id"][30:, 0] += 1  # a fourth frame in one step: one lost
    parts["frame_id"][50, 1] = parts["frame_id"][49, 1] + 1  # one new frame where 2 or 3 were due
    report = figures(samples(parts))
    assert (report.cameras["a"].skipped, report.cameras["a"].repeated) == (1, 0)
    assert report.cameras["b"].repeated == 1 and report.dropped_pct == pytest.approx(100 * 3 / 70, abs=0.01)


def test_a_rate_rounded_to_whole_ns_is_still_judged_strictly():
    period = 1e9 / 30  # 30 fps: the slot interval round(1e9 / 30) is not a whole number of periods
    slots = np.arange(6, dtype=np.int64) * round(period)
    ids = np.array([0, 1, 1, 3, 4, 5])  # a repeat at slot 2, then the frame after the one it missed
    faulty, repeated, skipped = advance_faults(slots, ids, np.zeros(6, dtype=np.int64), np.ones(6, dtype=bool), period)
    assert faulty.tolist() == [False, False, True, True, False, False] and (repeated, skipped) == (1, 1)


def test_a_faster_cameras_frames_matched_to_the_slowest_ones_are_no_fault():
    """a at 20 fps, b at 10; joint tuples at 20 Hz hold a's frame at b's moment: a's ids go 0, 2, 2, 4 ..."""
    parts = schedule(40, [0.0, 0.0], period=PERIOD)
    b_ids = np.rint((parts["slots"] - parts["slots"][0] + 1) / (2 * PERIOD)).astype(np.int64)
    parts["frame_id"][:, 1] = b_ids
    parts["frame_id"][:, 0] = 2 * b_ids  # matched to b's frame, not the nearest of a's own
    parts["t_capture"][:, 0] = parts["t_capture"][:, 1] = b_ids * 2 * PERIOD
    report = figures(samples(parts), nominal_period_ns={"a": PERIOD, "b": 2 * PERIOD})
    assert report.dropped_pct == 0.0 and report.gap_ms["max"] == 0.0
    assert parts["frame_id"][20, 0] == parts["frame_id"][19, 0]  # a repeat, explained by the matching
    parts["frame_id"][20:, 0] += 4  # four of a's frames lost there: two beyond what matching explains
    lost = figures(samples(parts), nominal_period_ns={"a": PERIOD, "b": 2 * PERIOD})
    assert lost.cameras["a"].skipped == 2 and lost.dropped_pct == 2.5


def test_slots_faster_than_frames_repeat_ids_without_fault():
    parts = schedule(40, [0.0, 1.0], interval=PERIOD // 4)
    report = figures(samples(parts))
    assert report.cameras["a"].repeated == report.cameras["a"].skipped == 0 and report.dropped_pct == 0.0


def test_a_restart_resets_ids_without_counting_a_fault():
    parts = schedule(20, [0.0, 0.0])
    parts["frame_id"][10:, 0] -= parts["frame_id"][10, 0]  # ids from 0 again ...
    parts["generation"][10:, 0] = 1  # ... in a new generation
    assert figures(samples(parts)).dropped_pct == 0.0


def test_residuals_and_capture_methods_per_camera():
    parts = schedule(10, [0.0, 0.0])
    parts["capture"][:, 1] = [SCHEDULED] * 4 + [LOCKSTEP] * 6
    parts["residual_ns"][:, 1] = [0.1 * MS, -0.2 * MS, 0.3 * MS, 0.2 * MS, 0.0, 0.1 * MS, 0.2 * MS, 0, 0, 2 * MS]
    report = figures(samples(parts))
    b = report.cameras["b"]
    assert b.captures == {"free": 0, "scheduled": 4, "lockstep": 6, "late": 0}
    assert b.residual_ms["p50"] == pytest.approx(0.15) and b.residual_ms["max"] == pytest.approx(2.0)
    assert b.residual_ms["p50"] <= b.residual_ms["p99"] <= b.residual_ms["max"]


def test_cameras_that_capture_on_request_are_judged_on_the_slots_moments_not_a_period():
    # each slot asks both cameras to capture at t_k: their frames say "scheduled", t_target = t_k
    n = 10
    parts = schedule(n, [0.0, 0.0])
    parts["frame_id"] = np.stack([np.arange(n), np.arange(n) + 100], axis=1)  # one new frame per request
    parts["t_capture"] = parts["slots"][:, None] + np.array([[10_000, 30_000]])  # captured 10 and 30 us late
    parts["capture"][:] = SCHEDULED
    parts["residual_ns"] = (parts["t_capture"] - parts["slots"][:, None]).astype(float)
    # b's capture for slot 6 never came: the tuple holds its frame of slot 5 again
    parts["frame_id"][6, 1], parts["t_capture"][6, 1] = parts["frame_id"][5, 1], parts["t_capture"][5, 1]
    parts["residual_ns"][6, 1] = parts["residual_ns"][5, 1]
    spacing = {"a": 154 * MS, "b": 154 * MS}  # a "period" measured from earlier triggers, as status gave it
    report = figures(samples(parts), None, spacing, on_request=["a", "b"])
    a, b = report.cameras["a"], report.cameras["b"]
    assert (a.on_request, a.period_ms, a.repeated, a.skipped) == (True, None, 0, 0)
    assert (b.repeated, b.skipped) == (1, 0)
    assert report.dropped_pct == 10.0 and report.gap_ms["p50"] == pytest.approx(0.02)


def test_a_capture_for_the_slots_moment_that_landed_late_is_late_not_a_repeat():
    n = 10
    parts = schedule(n, [0.0, 0.0])
    parts["frame_id"] = np.stack([np.arange(n), np.arange(n) + 100], axis=1)
    parts["t_capture"] = parts["slots"][:, None] + np.array([[10_000, 30_000]])
    parts["capture"][:] = SCHEDULED
    # b's trigger for slot 4 fired 3 ms late: its frame is slot 4's, marked late beyond the tolerance
    parts["t_capture"][4, 1] = parts["slots"][4] + 3 * MS
    parts["capture"][4, 1] = LATE
    parts["residual_ns"] = (parts["t_capture"] - parts["slots"][:, None]).astype(float)
    report = figures(samples(parts), on_request=["a", "b"])
    b = report.cameras["b"]
    assert (b.repeated, b.captures["late"], b.captures["scheduled"]) == (0, 1, 9)
    assert b.residual_ms["max"] == pytest.approx(3.0)
    assert report.dropped_pct == 0.0 and report.gap_ms["max"] == pytest.approx(2.99)


def test_no_tuple_at_all_fails_every_check():
    parts = schedule(5, [0.0, 0.0])
    parts["capture"][:] = ABSENT
    report = figures(samples(parts))
    assert report.complete == 0 and report.gap_ms is None
    assert report.dropped_pct == 100.0 and report.synced_pct == 0.0
    assert [c.passed for c in report.checks] == [False, False, False]
    assert report.as_dict()["verdict"] == "FAIL"


def test_gaps_and_period_helpers():
    parts = schedule(4, [0.0, 1.0, 3.0])
    parts["capture"][2, 1] = ABSENT
    assert np.isnan(gaps_ns(samples(parts, "abc"))[2])
    assert gaps_ns(samples(parts, "abc"))[0] == 3 * MS
    ids, times = np.array([1, 1, 2, 4]), np.array([0, 0, 50, 150]) * MS
    assert estimated_period_ns(ids, times, np.zeros(4, dtype=np.int64)) == 50 * MS
    assert estimated_period_ns(np.array([3, 3]), np.array([0, 0]), np.zeros(2, dtype=np.int64)) is None
    faulty, repeated, skipped = advance_faults(
        np.arange(4) * PERIOD, np.array([0, 1, 1, 9]), np.zeros(4, dtype=np.int64), np.ones(4, dtype=bool), PERIOD
    )
    assert faulty.tolist() == [False, False, True, True] and (repeated, skipped) == (1, 7)
