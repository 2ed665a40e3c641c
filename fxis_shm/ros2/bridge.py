"""The ROS 2 bridge (``fxis run --ros2``): the service as a participant of the ROS 2 graph,
a plain DDS participant following ROS 2's wire conventions, with no ROS install.

    NS/NAME/image_raw, NS/NAME/image_raw/compressed, NS/NAME/camera_info
                                   every frame camera NAME stores (fxis_shm.ros2.follow)
    NS/tuple/NAME/image_raw, NS/tuple/NAME/camera_info
                                   joint tuples at --ros2-tuples HZ (fxis_shm.ros2.tuples)
    NS/frames_at -> NS/frames_at/R/NAME/...
                                   frames at t* on request (fxis_shm.ros2.frames_at)
    NS/frames_at/capture -> the same, captured at t* (and NS/frames_at/R/capture: how)

It runs in a process of its own (workers/ros2_bridge.py), a client of the service like any
other: its threads read the rings through ``Client`` on the local path, so the cameras
never wait for it and a reader that stops reading holds up only itself. Stamps are capture
times in ROS time (the system clock; fxis_shm.ros2.rostime). Its counters go to the service's
status (``fxis status --json``, key ``ros2``) once a second. docs/ros2.md says more.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable

from fxis_shm.client.client import Client
from fxis_shm.core import timebase
from fxis_shm.formats import rosnames
from fxis_shm.formats.calibration import read_calibration
from fxis_shm.ros2.diagnostics_topic import Diagnostics
from fxis_shm.ros2.follow import CameraFollower
from fxis_shm.ros2.frames_at import FramesAt
from fxis_shm.ros2.participants import open_participant
from fxis_shm.ros2.rostime import RosTime
from fxis_shm.ros2.settings import SettingsRequests
from fxis_shm.ros2.snapshots import SnapshotRequests
from fxis_shm.ros2.topics import CameraTopics
from fxis_shm.ros2.tuples import TupleStream
from fxis_shm.service.childspec import Ros2Spec
from fxis_shm.shm import naming

log = logging.getLogger("ros2")

STATUS_PERIOD_S = 1.0
STOP_S = 1.5  # the threads' time to finish their request on a stop (the supervisor waits 3 s)
CLIENT_TIMEOUT_S = 5.0


class Bridge:
    def __init__(self, spec: Ros2Spec, stop: threading.Event):
        self.spec, self.stop = spec, stop
        keys = spec.client_keys()
        with Client(spec.endpoint, timeout=CLIENT_TIMEOUT_S, keys=keys) as probe:
            clock = timebase.of_status(probe.status())
        # Every client reads the service's own clock: on this host that is exact, no estimate.
        self.make_client: Callable[[], Client] = lambda: Client(
            spec.endpoint, timeout=CLIENT_TIMEOUT_S, keys=keys, clock=clock
        )
        self.ros_time = RosTime(clock)
        self.calibrations = {
            name: read_calibration(info["calibration"]) if info.get("calibration") else None
            for name, info in spec.cameras.items()
        }
        self.participant = open_participant(spec.via, spec.domain, spec.namespace, spec.service)
        log.info("ROS 2 through %s", type(self.participant).__name__)
        self.diagnostics = Diagnostics(self.participant, spec.service, list(spec.cameras), self.make_client())
        ns = spec.namespace
        cameras = {
            name: CameraTopics(
                participant=self.participant, base=rosnames.topic(ns, name), compressed=True, **self._of(name)
            )
            for name in spec.cameras
        }
        self.followers = [
            CameraFollower(self.make_client(), name, topics, self.ros_time, stop) for name, topics in cameras.items()
        ]
        self.tuples = (
            TupleStream(
                self.make_client(), self.topics_under(rosnames.topic(ns, "tuple")), spec.tuples_hz, self.ros_time, stop
            )
            if spec.tuples_hz
            else None
        )
        self.settings = SettingsRequests(self.participant, ns, self.make_client, stop, may_change=spec.may_change)
        self.frames_at = FramesAt(self.participant, ns, self.topics_under, self.make_client, self.ros_time, stop)
        self.snapshots = (
            SnapshotRequests(
                self.participant,
                ns,
                spec.snapshots,
                lambda: Client(spec.endpoint, timeout=CLIENT_TIMEOUT_S, keys=keys, clock="realtime"),
                stop,
            )
            if spec.snapshots
            else None
        )

    def _of(self, camera: str) -> dict:
        return {"frame_id": self.spec.cameras[camera]["frame_id"], "calibration": self.calibrations[camera]}

    def topics_under(self, base: str) -> dict[str, CameraTopics]:
        """Every camera's image_raw and camera_info under ``base`` (BASE/NAME/...)."""
        return {
            name: CameraTopics(participant=self.participant, base=rosnames.topic(base, name), **self._of(name))
            for name in self.spec.cameras
        }

    def run(self, on_ready: Callable[[], None]) -> None:
        threads = [*self.followers, *([self.tuples] if self.tuples else [])]
        for thread in threads:
            thread.start()
        self.frames_at.start()
        self.settings.start()
        if self.snapshots:
            self.snapshots.start()
        self.report()
        on_ready()
        log.info(
            "ROS 2 topics under %s on DDS domain %d: %s",
            self.spec.namespace or "/",
            self.spec.domain,
            ", ".join(self.spec.cameras),
        )
        try:
            while not self.stop.wait(STATUS_PERIOD_S):
                self.report()
                self.diagnostics.publish(timebase.reader("realtime")())  # ROS time
        finally:
            self.diagnostics.close()
            self.stop.set()
            deadline = time.monotonic() + STOP_S
            for thread in [*threads, *self.frames_at.threads, *self.settings.threads]:  # a request may still be waiting
                thread.join(timeout=max(0.0, deadline - time.monotonic()))
            self.participant.close()
            _remove(naming.state_path(self.spec.service, "ros2"))

    def status(self) -> dict:
        return {
            "pid": os.getpid(),
            "domain": self.spec.domain,
            "namespace": self.spec.namespace,
            "cameras": {f.camera: f.counts.as_dict() for f in self.followers},
            "tuples": self.tuples.counts.as_dict() if self.tuples else None,
            "frames_at": self.frames_at.status(),
            "snapshots": self.snapshots.counts.as_dict() if self.snapshots else None,
            "settings": self.settings.counts.as_dict(),
            "via": self.participant.VIA,
            "topics": self.participant.matches.status(),
        }

    def report(self) -> None:
        """The counters where the coordinator's status finds them (written whole, then renamed)."""
        path = naming.state_path(self.spec.service, "ros2")
        with open(path + ".tmp", "w") as f:
            json.dump(self.status(), f)
        os.replace(path + ".tmp", path)


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
