"""Snapshots asked for from ROS 2 (``fxis run --ros2 --ros2-snapshots DIR``): a node publishes
a ``std_msgs/msg/Header`` on ``NS/snapshot`` whose ``stamp`` is the event's time t in ROS time
and whose ``frame_id`` names the bag; the bridge keeps every frame of every camera captured in
[t - 2 s, t + 1 s] as DIR/NAME (fxis_shm.client.snapshot; stamps in ROS time, as the request's)
and answers on ``NS/snapshot/result``
with a ``std_msgs/msg/String``: JSON with the bag's path and what it holds, or the error.

The same request on ``NS/snapshot/h264`` (``h265``, ``av1``) keeps the window as video
(``client.snapshot(encoding="h264")``: each camera's track starting with a keyframe at the
window's first frame). The codec is the topic's name rather than a field because a Header has
none to spare, and a topic per codec is typed, listed by ``ros2 topic list``, and takes the
same ``ros2 topic pub`` line as the raw one.

Each request runs in a thread of its own, at most MAX_AT_ONCE at a time: a snapshot lasts
until t + 1 s has passed, and requests may overlap.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from collections.abc import Callable

from fxis_shm.errors import FxisError
from fxis_shm.formats import cdr, rosnames
from fxis_shm.formats.videochoice import CODECS
from fxis_shm.ros2.endpoints import Participant
from fxis_shm.ros2.follow import Counts
from fxis_shm.ros2.frames_at import STRING, HeaderRequests
from fxis_shm.wire.encoding import RAW

log = logging.getLogger("ros2")

BEFORE_S, AFTER_S = 2.0, 1.0
MAX_AT_ONCE = 4


class SnapshotRequests(HeaderRequests):
    def __init__(
        self,
        participant: Participant,
        namespace: str,
        folder: str,
        make_client: Callable,
        stop: threading.Event,
    ):
        self.folder, self.make_client, self.stop = folder, make_client, stop  # clients in ROS time
        self.counts = Counts()
        self._reader = participant.header_reader(rosnames.topic(namespace, "snapshot"))
        self._result = participant.writer(rosnames.topic(namespace, "snapshot", "result"), STRING)
        self._slots = threading.BoundedSemaphore(MAX_AT_ONCE)
        self.threads = [threading.Thread(target=self._listen, name="ros2-snapshots", daemon=True)]
        for codec in CODECS:  # each its own reader and thread: a request waits for no other topic
            reader = participant.header_reader(rosnames.topic(namespace, "snapshot", codec))
            thread = threading.Thread(
                target=self._listen_video, args=(reader, codec), name=f"ros2-snapshots-{codec}", daemon=True
            )
            self.threads.append(thread)

    def _listen_video(self, reader, codec: str) -> None:
        while not self.stop.is_set():
            for request in reader.wait(0.1):
                self._dispatch(request.header, codec)

    def _dispatch(self, header: cdr.Header, codec: str = RAW) -> None:
        name = header.frame_id
        try:
            rosnames.check_token(name, "snapshot name")
        except ValueError as exc:
            self._answer({"name": name, "error": f"frame_id must name the bag: {exc}"})
            return
        if os.path.exists(os.path.join(self.folder, name)):
            self._answer({"name": name, "error": f"{name} exists in {self.folder}: choose another name"})
            return
        if not self._slots.acquire(blocking=False):
            self._answer({"name": name, "error": f"busy: {MAX_AT_ONCE} snapshots are being taken"})
            return
        take = threading.Thread(target=self._take, args=(name, header.stamp_ns, codec), name=f"ros2-snapshot-{name}")
        take.start()

    def _take(self, name: str, t_ros: int, encoding: str) -> None:
        out = os.path.join(self.folder, name)
        try:
            with self.make_client() as client:
                kept = client.snapshot(t_ros, BEFORE_S, AFTER_S, out, encoding=encoding)
            cameras = kept["cameras"]
            self.counts.published += 1
            # "bag" None: the rings held no frame of the window (no bag written)
            answer = {"name": name, "bag": kept["out"], "encoding": encoding, "event_ros_ns": t_ros}
            self._answer({**answer, "cameras": cameras})
        except FxisError as exc:  # a bad time, a full disk (its bag is kept), a camera down
            self._answer({"name": name, "error": str(exc)})
        finally:
            self._slots.release()

    def _answer(self, answer: dict) -> None:
        if "error" in answer:
            self.counts.failed(f"snapshot {answer['name']!r}", ValueError(answer["error"]))
        self._result.write(cdr.encode_string(json.dumps(answer)))
