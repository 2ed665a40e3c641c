"""The synthetic camera counts as dropped only frames it fell behind on while streaming, not
the frames due while its worker was still setting up (a newcomer saw one drop at start)."""

from __future__ import annotations

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
