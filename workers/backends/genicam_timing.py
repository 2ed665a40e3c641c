"""What the two GenICam backends (aravis.py, genicam.py) do alike with time: the clock
that puts a camera's own timestamps on the service's clock (``timestamp=``), the
period of a frame rate, and when a camera that sends nothing is due a check that it
still answers."""

from __future__ import annotations

import time

from fxis_shm.core import timebase
from fxis_shm.core.clocks import DeviceClockFit, PtpClock


def device_clock(timestamp: str, tick_ns: float = 1.0) -> DeviceClockFit | PtpClock | None:
    """What maps the device timestamps (in ticks of ``tick_ns``) onto the service's
    clock for ``timestamp=``; None for ``host``, which needs none."""
    if timestamp == "ptp":
        return PtpClock(timebase.service_and_tai, tick_ns)  # PTP put the camera on TAI already
    if timestamp == "device":
        return DeviceClockFit(tick_ns=tick_ns)
    return None


def period_ns(fps: float) -> int:
    """The frame period of a frame rate, 0 if the rate is unknown (0 or less)."""
    return round(1e9 / fps) if fps > 0 else 0


class SilenceWatch:
    """When a camera that sends no frames is due a check that it still answers: after
    ``limit`` seconds without a frame, then once per ``limit`` while the silence lasts
    (a check may block or cost a round trip: not at every empty grab)."""

    def __init__(self) -> None:
        self.last_frame = self._last_check = time.monotonic()

    def frame_arrived(self) -> None:
        self.last_frame = time.monotonic()

    def check_due(self, limit: float) -> float | None:
        """Seconds since the last frame if a check is due now (it counts as made), else None."""
        now = time.monotonic()
        if now - max(self.last_frame, self._last_check) < limit:
            return None
        self._last_check = now
        return now - self.last_frame
