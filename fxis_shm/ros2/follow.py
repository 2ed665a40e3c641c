"""Every frame a camera stores, in order, to its ROS 2 topics: one thread per camera.

The thread asks its own client (the local path: no round trip, no copy until the CDR is
built) for the camera's first frame after the last one published, and waits for it as a
request does, so a frame reaches ROS as soon as it is stored. A bridge that falls a whole
ring behind starts again from the newest frame and counts what it skipped; nothing it
publishes was overwritten while it was read.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

from fxis_shm.client.single import SingleClient
from fxis_shm.errors import Code, FxisError, RequestTimeout, ServiceError
from fxis_shm.ros2.rostime import RosTime
from fxis_shm.ros2.topics import CameraTopics

log = logging.getLogger("ros2")

WAIT_S = 0.5  # one request's wait for the next frame: a stop is seen this soon; a silent camera asks again
RETRY_S = 1.0  # after an error (camera down, service restarting)


@dataclass
class Counts:
    published: int = 0  # frames on the topics
    skipped: int = 0  # frames stored that the bridge did not publish (it fell behind, or a torn copy)
    errors: int = 0
    last_error: str | None = None

    def as_dict(self) -> dict:
        return dict(vars(self))

    def failed(self, what: str, exc: Exception) -> None:
        """Count an error; log it when it is not the one logged last (a camera down for
        minutes is one line, not one a second)."""
        self.errors += 1
        if str(exc) != self.last_error:
            log.warning("%s: %s", what, exc)
        self.last_error = str(exc)


class CameraFollower(threading.Thread):
    def __init__(
        self, client: SingleClient, camera: str, topics: CameraTopics, ros_time: RosTime, stop: threading.Event
    ):
        super().__init__(name=f"ros2-{camera}", daemon=True)
        self.client, self.camera, self.topics, self.ros_time, self.stop = client, camera, topics, ros_time, stop
        self.counts = Counts()
        self._last: tuple[int, int, int] | None = None  # generation, frame id, t_capture published last

    def run(self) -> None:
        try:
            while not self.stop.is_set():
                self._next()
        finally:
            self.client.close()

    def _next(self) -> None:
        try:
            frame = self._fetch()
        except (RequestTimeout, ServiceError) as exc:
            if isinstance(exc, ServiceError) and exc.code == Code.OUT_OF_RANGE:
                self._last = None  # the ring came round before we asked: start from the newest
            elif not (isinstance(exc, ServiceError) and exc.code == Code.TIMEOUT):
                self._failed(exc)
            return
        except FxisError as exc:
            self._failed(exc)
            return
        if self._last is not None and frame.generation == self._last[0]:
            self.counts.skipped += max(0, frame.frame_id - self._last[1] - 1)
        if self.topics.publish(frame, self.ros_time.to_ros(frame.t_capture)):
            self.counts.published += 1
        else:
            self.counts.skipped += 1
        self._last = (frame.generation, frame.frame_id, frame.t_capture)

    def _fetch(self):
        if self._last is None:
            return self.client.latest([self.camera], copy=False)[self.camera]
        after = self._last[2] + 1
        frames = self.client.sequence(
            "consecutive", camera=self.camera, count=1, direction="after", at=after, timeout=WAIT_S, copy=False
        )
        return frames[0]

    def _failed(self, exc: Exception) -> None:
        self.counts.failed(self.camera, exc)
        self._last = None
        self.stop.wait(RETRY_S)
