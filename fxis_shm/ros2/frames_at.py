"""Frames at t* for any ROS 2 node, C++ included, with standard types only.

A node publishes on ``NS/frames_at`` a ``std_msgs/msg/Header``: ``stamp`` is t* in ROS time,
``frame_id`` a reply name R (one or more ROS name tokens, ``robot1`` or ``arm/left``). The
bridge answers with one tuple, chosen as ``Client.tuple(at=t*)`` chooses it (waiting for
frames still to come), on ``NS/frames_at/R/NAME/image_raw`` and ``.../camera_info``, each
image with its own capture time; all images of one reply go out before any of the next
reply to R. A request the bridge cannot answer (t* outside the history, a camera down) is
answered with a ``std_msgs/msg/String`` on ``NS/frames_at/R/error``; one whose R is not a
ROS name, on ``NS/frames_at/error``. Either way it is logged and counted in the status.

The same request on ``NS/frames_at/capture`` asks for a capture at a future t*
(``Client.tuple(at=t*, capture=True)``): every camera that can be triggered is triggered to
expose at t*, the others answer with their frame nearest t*. A topic rather than a convention
in ``frame_id``, as the snapshot codecs are (``NS/snapshot/h264``): a Header has no field to
spare, and the topic takes the same ``ros2 topic pub`` line. sensor_msgs/Image has no field for
how a frame was captured, so after the images the bridge publishes a ``std_msgs/msg/String`` on
``NS/frames_at/R/capture``: JSON ``{"t_target": T, "cameras": {NAME: {"capture": "scheduled"
or "free" or "lockstep", "t_capture": ..., "residual_ns": ... or null}}}``, times in ROS ns.
A t* in the past, or too near to schedule, is answered on ``NS/frames_at/R/error``.

Requests are spread over a few workers by R, each with its own client, so a request that
waits for the future holds up only the requests with the same reply name.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fxis_shm.client.frames import FrameTuple
from fxis_shm.client.single import SingleClient
from fxis_shm.errors import Code, FxisError
from fxis_shm.formats import cdr, rosnames
from fxis_shm.ros2.endpoints import Participant, Writer
from fxis_shm.ros2.follow import Counts
from fxis_shm.ros2.rostime import RosTime
from fxis_shm.ros2.topics import CameraTopics

log = logging.getLogger("ros2")

STRING = "std_msgs/msg/String"
WORKERS = 4
QUEUED_PER_WORKER = 16  # requests beyond this are refused (busy), not queued without bound
MAX_REPLY_NAMES = 64  # each reply name holds a set of writers
MATCH_WAIT_S = 2.0  # a new reply name: how long its first reply waits for the requester's readers
REQUEST_TIMEOUT_S = 5.0


class HeaderRequests:
    """Requests that arrive as std_msgs/Header on a topic (``_reader``), read by a thread of
    their own until ``stop`` and each handed to ``_dispatch``; ``start`` starts ``threads``."""

    stop: threading.Event
    threads: list[threading.Thread]
    _reader: Any

    def start(self) -> None:
        for thread in self.threads:
            thread.start()

    def _listen(self) -> None:
        while not self.stop.is_set():
            for request in self._reader.wait(0.1):
                self._dispatch(request.header)

    def _dispatch(self, header: cdr.Header) -> None:
        raise NotImplementedError


class FramesAt(HeaderRequests):
    def __init__(
        self,
        participant: Participant,
        namespace: str,
        make_topics: Callable[[str], dict[str, CameraTopics]],
        make_client: Callable[[], SingleClient],
        ros_time: RosTime,
        stop: threading.Event,
    ):
        self.participant, self.namespace, self.ros_time, self.stop = participant, namespace, ros_time, stop
        self.make_topics = make_topics  # base name -> {camera: topics under it}
        self.counts = Counts()
        self.refused = 0
        self._replies: dict[str, ReplyTopics] = {}
        self._lock = threading.Lock()  # guards _replies, made by the workers
        self._reader = participant.header_reader(rosnames.topic(namespace, "frames_at"))
        self._capture_reader = participant.header_reader(rosnames.topic(namespace, "frames_at", "capture"))
        self._bad_names = participant.writer(rosnames.topic(namespace, "frames_at", "error"), STRING)
        self._queues = [queue.Queue(QUEUED_PER_WORKER) for _ in range(WORKERS)]
        self.threads = [
            threading.Thread(target=self._listen, name="ros2-frames-at", daemon=True),
            threading.Thread(target=self._listen_captures, name="ros2-frames-at-capture", daemon=True),
        ]
        self.threads += [
            threading.Thread(target=self._work, args=(q, make_client()), name=f"ros2-frames-at-{i}", daemon=True)
            for i, q in enumerate(self._queues)
        ]

    def status(self) -> dict:
        return {**self.counts.as_dict(), "refused": self.refused}

    def _listen_captures(self) -> None:
        while not self.stop.is_set():
            for request in self._capture_reader.wait(0.1):
                self._dispatch(request.header, capture=True)

    def _dispatch(self, header: cdr.Header, capture: bool = False) -> None:
        name = header.frame_id
        try:
            rosnames.check_relative(name)
        except ValueError as exc:
            self._refuse(None, f"reply name {name!r} in frame_id is not a ROS name: {exc}")
            return
        try:
            self._queues[zlib.crc32(name.encode()) % WORKERS].put_nowait((name, header, capture))
        except queue.Full:
            self._refuse(name, f"busy: {QUEUED_PER_WORKER} requests of this reply name's worker are waiting already")

    def _work(self, requests: queue.Queue, client: SingleClient) -> None:
        try:
            while not self.stop.is_set():
                try:
                    name, header, capture = requests.get(timeout=0.1)
                except queue.Empty:
                    continue
                self._answer(client, name, header, capture)
        finally:
            client.close()

    def _answer(self, client: SingleClient, name: str, header: cdr.Header, capture: bool) -> None:
        t_star = self.ros_time.to_service(header.sec * 1_000_000_000 + header.nanosec)
        if t_star < 0:  # before the service clock's zero (its host's boot, for CLOCK_MONOTONIC): no frame is that old
            self._refuse(name, f"{Code.OUT_OF_RANGE}: t* lies {-t_star / 1e9:.3f} s before the service clock began")
            return
        try:
            frames = client.tuple(at=t_star, timeout=REQUEST_TIMEOUT_S, copy=False, capture=capture)
        except FxisError as exc:  # a service error says its code first: "OUT_OF_RANGE: ..."
            self._refuse(name, str(exc))
            return
        reply = self._reply(name)
        messages = {c: reply.cameras[c].serialize(frames[c], self.ros_time.to_ros(frames[c].t_capture)) for c in frames}
        if not frames.still_valid():
            self._refuse(name, "the frames were overwritten while they were read: ask for a more recent t*")
            return
        reply.wait_for_readers([reply.cameras[c].image for c in frames], self.stop)
        for camera, serialized in messages.items():
            reply.cameras[camera].write(serialized)
        if capture:
            reply.wait_for_readers([reply.captured], self.stop)
            reply.captured.write(cdr.encode_string(json.dumps(self._how_captured(header, frames))))
        self.counts.published += 1

    def _how_captured(self, header: cdr.Header, frames: FrameTuple) -> dict:
        """What the Image messages cannot carry: each frame's capture method and residual."""
        cameras = {
            c: {"capture": f.capture, "t_capture": self.ros_time.to_ros(f.t_capture), "residual_ns": f.residual_ns}
            for c, f in frames.items()
        }
        return {"t_target": header.stamp_ns, "cameras": cameras}

    def _reply(self, name: str) -> ReplyTopics:
        """The topics of reply name ``name``, made on its first request."""
        with self._lock:
            reply = self._replies.get(name)
            if reply is None:
                if len(self._replies) >= MAX_REPLY_NAMES:
                    self._replies.pop(next(iter(self._replies)))  # the oldest name's writers go
                base = rosnames.topic(self.namespace, "frames_at", *name.split("/"))
                error = self.participant.writer(rosnames.topic(base, "error"), STRING)
                captured = self.participant.writer(rosnames.topic(base, "capture"), STRING)
                reply = self._replies[name] = ReplyTopics(self.make_topics(base), error, captured)
            return reply

    def _refuse(self, name: str | None, message: str) -> None:
        self.refused += 1
        self.counts.failed(f"frames_at {name or '?'}", ValueError(message))
        if name is None:
            self._bad_names.write(cdr.encode_string(message))
            return
        reply = self._reply(name)
        reply.wait_for_readers([reply.error], self.stop)
        reply.error.write(cdr.encode_string(message))


@dataclass
class ReplyTopics:
    """The writers of one reply name: an image and camera_info per camera, the error, and how a
    capture request's frames were captured."""

    cameras: dict[str, CameraTopics]
    error: Writer
    captured: Writer
    waited: set[int] = field(default_factory=set)  # ids of the writers already waited for

    def wait_for_readers(self, writers: list[Writer], stop: threading.Event) -> None:
        """Once per writer, before its first message: a volatile reader receives only what is
        written after it matched our new writer, which takes a discovery round."""
        fresh = [w for w in writers if id(w) not in self.waited]
        self.waited.update(map(id, fresh))
        deadline = time.monotonic() + MATCH_WAIT_S
        while any(w.matched_count() == 0 for w in fresh) and time.monotonic() < deadline and not stop.wait(0.005):
            pass
