"""Camera timestamps onto the service clock (CLOCK_MONOTONIC, ns).

- ``wall_to_monotonic``: a host timestamp taken on the wall clock (Aravis gives
  those) mapped with the offset read at conversion time, right after the frame
  arrived: a step of the wall clock (NTP, an operator) only affects a frame in
  flight at that instant, never the frames after it.
- ``DeviceClockFit``: a camera's own clock (ticks; PTP-synchronized cameras
  share it) mapped by a continuously fitted drift and offset. Each frame gives a
  pair (device ticks at capture, host time at arrival); arrival = capture +
  transfer delay >= capture, so the fit runs through the lower envelope of the
  pairs (the least delayed frames), not their mean.

- ``PtpClock``: a camera whose clock PTP keeps on the cell's grandmaster (IEEE 1588
  time, TAI ns: what GigE Vision cameras with PTP enabled stamp). Nothing to fit: its
  timestamps are moved into the service's clock by the difference between the two
  clocks read now, which is 0 when the service runs on ``--clock tai``.

Pure: the clocks are read by the caller and passed in (``PtpClock`` gets a function).
"""

from __future__ import annotations

import collections
from collections.abc import Callable


def wall_to_monotonic(wall_ns: int, monotonic_now_ns: int, wall_now_ns: int) -> int:
    """``wall_ns`` on CLOCK_MONOTONIC, given both clocks read at (almost) the same moment."""
    return wall_ns + (monotonic_now_ns - wall_now_ns)


class DeviceClockFit:
    """Maps device ticks onto host monotonic ns: host = offset + drift * ticks * tick_ns."""

    def __init__(self, tick_ns: float = 1.0, window: int = 256):
        self.tick_ns = tick_ns
        self._pairs: collections.deque[tuple[int, int]] = collections.deque(maxlen=window)
        self.drift = 1.0
        self.offset = 0.0

    def __len__(self) -> int:
        return len(self._pairs)

    def add(self, device_ticks: int, host_ns: int) -> None:
        """One frame: its device timestamp and the host time it arrived."""
        if self._pairs and device_ticks <= self._pairs[-1][0]:
            self._pairs.clear()  # the device clock went back: the camera restarted
        self._pairs.append((device_ticks, host_ns))
        self._refit()

    def _refit(self) -> None:
        pairs = list(self._pairs)
        d0 = pairs[0][0]
        if len(pairs) >= 2:
            # drift between the least delayed frames of the window's first and last
            # quarters: a long baseline, and a late frame at either end cannot skew it
            quarter = max(1, len(pairs) // 4)
            early = min(pairs[:quarter], key=lambda p: p[1] - p[0] * self.tick_ns)
            late = min(pairs[-quarter:], key=lambda p: p[1] - p[0] * self.tick_ns)
            span = (late[0] - early[0]) * self.tick_ns
            self.drift = (late[1] - early[1]) / span if span > 0 else 1.0
        # offset through the least delayed frame of the window
        self.offset = (
            min(h - self.drift * (d - d0) * self.tick_ns for d, h in self._pairs) - self.drift * d0 * self.tick_ns
        )

    def to_host(self, device_ticks: int) -> int:
        if not self._pairs:
            raise ValueError("no frames fitted yet")
        return int(round(self.offset + self.drift * device_ticks * self.tick_ns))


class PtpClock:
    """``DeviceClockFit``'s interface for a PTP-disciplined camera: ``clocks()`` returns
    (service clock now, CLOCK_TAI now), read together."""

    def __init__(self, clocks: Callable[[], tuple[int, int]], tick_ns: float = 1.0):
        self._clocks, self.tick_ns = clocks, tick_ns

    def __len__(self) -> int:
        return 1  # nothing to learn: ready from the first frame

    def add(self, device_ticks: int, host_ns: int) -> None:
        """Nothing to fit: PTP already put the camera on the cell's time."""

    def to_host(self, device_ticks: int) -> int:
        service_now, tai_now = self._clocks()
        return round(device_ticks * self.tick_ns) + service_now - tai_now
