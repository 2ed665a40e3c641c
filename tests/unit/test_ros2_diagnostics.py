"""The /diagnostics rules (fxis_shm.ros2.diagnostics, docs/ros2.md): a camera's status and its
counters over the window in, a level and a message out."""

from fxis_shm.ros2.diagnostics import ERROR, OK, WARN, Sample, Windows, diagnose, unanswered

RUNNING = {"kind": "synthetic", "alive": True, "fps": 20.0, "trigger": "free", "last_frame_age_ms": 30.0}


def window(rate: float, dropped=0, restarts=0, seconds=5):
    return [Sample(0.0, 0, 0, 0), Sample(float(seconds), int(rate * seconds), dropped, restarts)]


def values(status):
    return dict(status.values)


def test_a_camera_at_its_rate_is_ok_and_says_what_it_measured():
    status = diagnose("cell", "cam0", RUNNING, window(20.0))
    assert (status.level, status.message, status.name) == (OK, "streaming", "fxis cell: cam0")
    assert values(status)["rate_measured_hz"] == "20.00" and values(status)["rate_configured_hz"] == "20"
    assert values(status)["worker"] == "running" and status.hardware_id == "synthetic"


def test_a_slow_camera_drops_or_restarts_warn():
    assert diagnose("s", "c", RUNNING, window(17.0)).level == WARN
    assert "17.0 frames/s of 20" in diagnose("s", "c", RUNNING, window(17.0)).message
    assert diagnose("s", "c", RUNNING, window(18.5)).level == OK  # above 90 %
    assert diagnose("s", "c", RUNNING, window(20.0, dropped=3)).level == WARN
    assert diagnose("s", "c", RUNNING, window(20.0, restarts=1)).level == WARN


def test_a_worker_down_or_a_silent_camera_is_an_error():
    down = diagnose("s", "c", {**RUNNING, "alive": False, "note": "exited 1"}, window(0.0))
    assert down.level == ERROR and "worker not running: exited 1" in down.message
    silent = diagnose("s", "c", {**RUNNING, "last_frame_age_ms": 1500.0}, window(20.0))
    assert silent.level == ERROR and "no frame for 1.5 s" in silent.message


def test_a_triggered_camera_has_no_rate_to_meet():
    triggered = {**RUNNING, "trigger": "software", "last_frame_age_ms": 60_000.0}
    assert diagnose("s", "c", triggered, window(0.0)).level == OK


def test_the_window_keeps_its_span_and_a_restart_still_shows_after_the_ring_starts_again():
    windows = Windows()
    for t in range(10):
        samples = windows.add("c", float(t), {**RUNNING, "frames_stored": 20 * t})
    assert samples[-1].t - samples[0].t == 5.0
    samples = windows.add("c", 10.0, {**RUNNING, "frames_stored": 5, "restarts": 1})
    assert diagnose("s", "c", RUNNING, samples).level == WARN


def test_a_service_that_does_not_answer_makes_every_camera_stale():
    assert [s.level for s in unanswered("s", ["a", "b"], "timeout")] == [3, 3]
