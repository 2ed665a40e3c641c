"""When the synthetic camera's frames are due and which it counts as dropped: not the frames due
while its worker was still setting up (a newcomer saw one drop at start), nor those a late worker
still finds in its driver's buffers; only those older than its buffers hold."""

from __future__ import annotations

import subprocess
import sys
import time

from fxis_shm.core import timebase
from fxis_shm.formats.stamp import read_stamp
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.workers.backends.synthetic import SyntheticCamera


def test_frames_due_before_the_first_grab_are_not_drops():
    options = camera_options("a", "synthetic", {"fps": 100, "width": 64, "height": 48})
    camera = SyntheticCamera("a", options, timebase.now())
    camera.open()
    time.sleep(0.05)  # setting up the ring takes five periods here
    first = camera.grab(timeout=1.0)
    assert read_stamp(first.image) == first.frame_id  # the image is the camera's until the next grab
    second = camera.grab(timeout=1.0)
    assert camera.frames_dropped == 0 and second.frame_id == first.frame_id + 1
    assert first.frame_id >= 5  # numbered from the shared origin, as every camera of the service is


def _late_camera(buffers: int, late_periods: float) -> tuple[SyntheticCamera, object, int]:
    """A 100 fps camera whose worker took one frame, then came back ``late_periods`` later
    (and the time it came back)."""
    options = camera_options("a", "synthetic", {"fps": 100, "width": 64, "height": 48, "buffers": buffers})
    camera = SyntheticCamera("a", options, timebase.now())
    camera.open()
    first = camera.grab(timeout=1.0)
    time.sleep(late_periods / 100)  # the worker is late on purpose: descheduled, say
    return camera, first, timebase.now()


def test_a_late_worker_gets_the_frames_its_buffers_held_with_their_own_capture_times():
    camera, first, _ = _late_camera(buffers=10_000, late_periods=6)  # however late a loaded machine makes it
    first_id, first_t = first.frame_id, first.t_capture
    later = [camera.grab(timeout=1.0) for _ in range(6)]
    assert [c.frame_id for c in later] == list(range(first_id + 1, first_id + 7))
    assert [c.t_capture - first_t for c in later] == [k * 10_000_000 for k in range(1, 7)]
    assert camera.frames_dropped == 0


def test_a_worker_later_than_its_buffers_loses_the_oldest_frames_and_counts_them():
    camera, first, back = _late_camera(buffers=2, late_periods=8)
    after = camera.grab(timeout=1.0)
    assert camera.frames_dropped >= 5  # 8 periods late, 2 frames held (more if the machine was slower)
    assert after.frame_id == first.frame_id + 1 + camera.frames_dropped
    assert after.t_capture >= back - 2 * 10_000_000  # one of the two newest when it came back, or newer


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
