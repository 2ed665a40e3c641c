"""The bridge's ``/diagnostics`` publisher: once a second, the service's status turned into one
DiagnosticStatus a camera by the rules of fxis_shm.ros2.diagnostics."""

from __future__ import annotations

import logging
import time

from fxis_shm.client.single import SingleClient
from fxis_shm.errors import FxisError
from fxis_shm.formats import cdr
from fxis_shm.ros2.diagnostics import Windows, diagnose, unanswered
from fxis_shm.ros2.endpoints import DEFAULT_SUBSCRIBER, Participant, Writer

log = logging.getLogger("ros2")

TOPIC, TYPE = "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"


class Diagnostics:
    def __init__(self, participant: Participant, service: str, cameras: list[str], client: SingleClient) -> None:
        self.service, self.cameras, self.client = service, cameras, client
        self.windows = Windows()
        self.writer: Writer | None = None
        try:
            self.writer = participant.writer(TOPIC, TYPE, DEFAULT_SUBSCRIBER)
        except ImportError as exc:  # a ROS install without diagnostic_msgs
            log.warning("no %s: %s (install diagnostic_msgs)", TOPIC, exc)

    def publish(self, now_ros_ns: int) -> None:
        if self.writer is None:
            return
        try:
            cameras = self.client.status()["cameras"]
        except FxisError as exc:
            statuses = unanswered(self.service, self.cameras, str(exc))
        else:
            now = time.monotonic()
            statuses = [
                diagnose(self.service, name, cameras[name], self.windows.add(name, now, cameras[name]))
                for name in self.cameras
                if name in cameras
            ]
        self.writer.write(cdr.encode_diagnostic_array(cdr.Header.at(now_ros_ns), statuses, pad=True))

    def close(self) -> None:
        self.client.close()
