"""Joint tuples at a rate on ``NS/tuple/NAME/image_raw`` (and ``camera_info``): every image
of one tuple carries one identical header.stamp, so message_filters' ExactTime policy (and
stereo_image_proc) group them without ApproximateTime's guesswork.

The stamp is the middle of the tuple's capture times, (earliest + latest) / 2, in ROS time:
within half the tuple's skew of every frame's own capture time, which the per-camera topics
keep. Tuples are asked for on a schedule of the service's clock, one every 1/rate, each
waiting for frames still to come; a schedule time missed in a stall is given up, not caught
up in a burst. A tuple goes out whole or not at all: every image is serialized and checked
before the first is sent. A tuple goes out only if it is newer than the last one: a camera
whose worker is held up longer than a period gives the next times its frames from before
the stall, the same tuple again, which is counted skipped, not published twice.
"""

from __future__ import annotations

import threading

from fxis_shm.client.single import SingleClient
from fxis_shm.errors import Code, FxisError, RequestTimeout, ServiceError
from fxis_shm.ros2.follow import RETRY_S, Counts
from fxis_shm.ros2.rostime import RosTime
from fxis_shm.ros2.topics import CameraTopics


def tuple_stamp(captures: list[int]) -> int:
    """The one stamp of a tuple: the middle of its capture times."""
    return (min(captures) + max(captures)) // 2


class TupleStream(threading.Thread):
    def __init__(
        self,
        client: SingleClient,
        topics: dict[str, CameraTopics],
        rate_hz: float,
        ros_time: RosTime,
        stop: threading.Event,
    ):
        super().__init__(name="ros2-tuples", daemon=True)
        self.client, self.topics, self.ros_time, self.stop = client, topics, ros_time, stop
        self.period_ns = round(1e9 / rate_hz)
        self.counts = Counts()
        self._last_middle: int | None = None  # the service-clock middle of the tuple published last

    def run(self) -> None:
        try:
            due = self.client.clock()
            while not self.stop.is_set():
                self._one(due)
                due += self.period_ns
                now = self.client.clock()
                if due < now - self.period_ns:  # a stall: give the missed times up
                    due = now
        finally:
            self.client.close()

    def _one(self, due: int) -> None:
        try:
            frames = self.client.tuple(
                list(self.topics), at=due, timeout=max(2.0, 2 * self.period_ns / 1e9), copy=False
            )
        except (RequestTimeout, ServiceError) as exc:
            if not (isinstance(exc, ServiceError) and exc.code in (Code.TIMEOUT, Code.OUT_OF_RANGE)):
                self._failed(exc)
            return
        except FxisError as exc:
            self._failed(exc)
            return
        middle = tuple_stamp([frames[c].t_capture for c in frames])
        if self._last_middle is not None and middle <= self._last_middle:
            self.counts.skipped += 1
            return
        stamp = self.ros_time.to_ros(middle)
        messages = {camera: self.topics[camera].serialize(frames[camera], stamp) for camera in frames}
        if not frames.still_valid():
            self.counts.skipped += 1
            return
        for camera, serialized in messages.items():
            self.topics[camera].write(serialized)
        self.counts.published += 1
        self._last_middle = middle

    def _failed(self, exc: Exception) -> None:
        self.counts.failed("tuples", exc)
        self.stop.wait(RETRY_S)
