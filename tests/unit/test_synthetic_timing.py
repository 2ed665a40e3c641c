"""When the synthetic camera's frames are due and which it counts as dropped: not the frames due
while its worker was still setting up (a newcomer saw one drop at start), nor those a late worker
still finds in its driver's buffers; only those older than its buffers hold. On a virtual clock
(tests/virtualtime): the worker is late by exactly what the test says."""

from __future__ import annotations

import subprocess
import sys

from fxis_shm.formats.stamp import read_stamp
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.workers.backends.synthetic import SyntheticCamera

from ..virtualtime import MS, VirtualClock

PERIOD = 10 * MS  # 100 fps


def _camera(**options) -> tuple[SyntheticCamera, VirtualClock]:
    clock = VirtualClock()
    options = camera_options("a", "synthetic", {"fps": 100, "width": 64, "height": 48, **options})
    camera = SyntheticCamera("a", options, clock.now_ns(), clock=clock)
    camera.open()
    return camera, clock


def test_frames_due_before_the_first_grab_are_not_drops():
    camera, clock = _camera()
    clock.advance_to(clock.now_ns() + 5 * PERIOD - MS)  # setting up the ring took five periods
    first = camera.grab(timeout=1.0)
    assert read_stamp(first.image) == first.frame_id  # the image is the camera's until the next grab
    second = camera.grab(timeout=1.0)
    assert camera.frames_dropped == 0 and second.frame_id == first.frame_id + 1
    assert first.frame_id == 5  # numbered from the shared origin, as every camera of the service is
    assert clock.now_ns() == second.t_capture  # grab waited (on the clock) for the frame due


def _late_camera(buffers: int, late_periods: int) -> tuple[SyntheticCamera, object, int]:
    """A 100 fps camera whose worker took one frame, then came back ``late_periods`` later
    (and the time it came back)."""
    camera, clock = _camera(buffers=buffers)
    first = camera.grab(timeout=1.0)
    clock.advance_to(first.t_capture + late_periods * PERIOD)  # the worker is late: descheduled, say
    return camera, first, clock.now_ns()


def test_a_late_worker_gets_the_frames_its_buffers_held_with_their_own_capture_times():
    camera, first, back = _late_camera(buffers=10, late_periods=6)
    first_id, first_t = first.frame_id, first.t_capture
    later = [camera.grab(timeout=1.0) for _ in range(7)]
    assert [c.frame_id for c in later] == list(range(first_id + 1, first_id + 8))
    assert [c.t_capture - first_t for c in later] == [k * PERIOD for k in range(1, 8)]
    assert camera.frames_dropped == 0 and later[5].t_capture == back  # the six held, at once


def test_a_worker_later_than_its_buffers_loses_the_oldest_frames_and_counts_them():
    camera, first, back = _late_camera(buffers=2, late_periods=8)
    after = camera.grab(timeout=1.0)
    assert camera.frames_dropped == 5  # 8 periods late, 2 frames held: frames 1 to 5 after the first are lost
    assert after.frame_id == first.frame_id + 6 and after.t_capture == back - 2 * PERIOD


WAIT_UNDER_SIGNALS = """
import signal, sys
from fxis_shm.core import timebase
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.workers.backends.synthetic import SyntheticCamera

options = camera_options("t", "synthetic", {"width": 64, "height": 48, "trigger": "software"})
camera = SyntheticCamera("t", options, timebase.now())
camera.open()
signal.signal(signal.SIGALRM, lambda *_: None)
signal.setitimer(signal.ITIMER_REAL, 0.0005, 0.0005)  # a signal every half millisecond
returned = sum(camera.grab(timeout=0.01) is None for _ in range(100))
signal.setitimer(signal.ITIMER_REAL, 0)
print(returned)
"""


def test_a_triggered_camera_waiting_for_a_trigger_returns_at_its_timeout_whatever_signals_land():
    """A signal landing near the deadline of the wait for a trigger once left a camera worker
    waiting for ever, deaf to its SIGTERM (queue.SimpleQueue on Python 3.11): run in a child, so
    that a wait that never ends fails here rather than hanging the suite."""
    done = subprocess.run([sys.executable, "-c", WAIT_UNDER_SIGNALS], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["100"]
