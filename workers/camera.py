"""The camera worker process: one camera, one ring. It owns the ring's writer
side and stores every frame the camera delivers; it never waits for readers."""
from __future__ import annotations

import logging
import threading
import time

from fxis_shm.ring import FrameLayout, RingWriter

from ._child import Ready, child_main
from .backends import backend_class

log = logging.getLogger("camera")
_GRAB_TIMEOUT_S = 0.1  # also the heartbeat interval while no frames come
_FIRST_FRAME_TIMEOUT_S = 10.0


def run(spec: dict, ready: Ready, stop: threading.Event) -> None:
    name = spec["camera"]
    camera = backend_class(spec["kind"])(name, spec["options"], spec["time_origin_ns"])
    camera.open()
    try:
        first = None
        layout = camera.layout
        if layout is None:  # the first frame fixes the layout
            first = _first_frame(camera, stop)
            layout = FrameLayout.of(first.image)
        ring = RingWriter(spec["service"], name, layout, spec["slots"], camera.nominal_period_ns)
        log.info("camera %s (%s) streaming %s into %s, generation %d",
                 name, spec["kind"], layout, ring.name, ring.generation)
        ready.ok()
        try:
            _stream(camera, ring, stop, first)
        finally:
            ring.close()
    finally:
        camera.close()


def _first_frame(camera, stop):
    deadline = time.monotonic() + _FIRST_FRAME_TIMEOUT_S
    while not stop.is_set() and time.monotonic() < deadline:
        capture = camera.grab(_GRAB_TIMEOUT_S)
        if capture is not None:
            return capture
    raise TimeoutError(f"camera {camera.name!r} delivered no frame in {_FIRST_FRAME_TIMEOUT_S:.0f} s")


def _stream(camera, ring: RingWriter, stop: threading.Event, capture=None) -> None:
    dropped = camera.frames_dropped
    while not stop.is_set():
        if capture is None:
            capture = camera.grab(_GRAB_TIMEOUT_S)
        if capture is None:
            ring.heartbeat()
        else:
            t_available = time.monotonic_ns()
            ring.write(capture.image, capture.frame_id, capture.t_capture, t_available)
            ring.count("frames_captured")
        if camera.frames_dropped != dropped:
            ring.count("frames_dropped", camera.frames_dropped - dropped)
            dropped = camera.frames_dropped
        capture = None


if __name__ == "__main__":
    child_main("camera", run)
