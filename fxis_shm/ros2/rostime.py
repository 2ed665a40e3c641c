"""ROS time against the service's clock, on the service's host.

ROS time is the system clock (CLOCK_REALTIME: Unix epoch, UTC), whatever clock the service
runs on (``fxis run --clock``). The two are read here side by side, not estimated over a
socket: the bridge runs on the service's host. On a service that runs on CLOCK_TAI the
offset holds TAI - UTC (37 s since 2017, as the kernel was told by ptp4l or chrony); a PTP
cell that forgets it stamps everything 37 s off, so it is read, never assumed.
"""

from __future__ import annotations

import time

from fxis_shm.core import timebase

REFRESH_S = 1.0  # the system clock may be slewed (NTP, chrony): read the offset again this often


class RosTime:
    def __init__(self, service_clock: str):
        self.service_clock = timebase.check(service_clock)
        self._offset = 0
        self._read_at = float("-inf")

    def offset(self) -> int:
        """ROS time minus the service's clock, ns."""
        if time.monotonic() - self._read_at > REFRESH_S:
            self._offset = timebase.offset("realtime", self.service_clock)
            self._read_at = time.monotonic()
        return self._offset

    def to_ros(self, t_service: int) -> int:
        return t_service + self.offset()

    def to_service(self, t_ros: int) -> int:
        return t_ros - self.offset()
