"""A recorded topic played into a ring as a camera (``bag:path=DIR,topic=/left/image_raw``).

Plays a rosbag2 bag with MCAP storage (``fxis record``'s, or any with
sensor_msgs/msg/Image or CompressedImage topics) at the recorded spacing, so vision code
runs against yesterday's cell as against the live one.

A video track (``/NAME/video``, foxglove_msgs/msg/CompressedVideo: ``fxis record --codec``,
``fxis snapshot --codec``) is decoded frame by frame (fxis_shm.formats.videodecoder), each
frame at its recorded time. Playback that starts (or restarts) part-way decodes from the
keyframe before (the keyframes are those ``/NAME/video/frames`` marks; a bag without that
topic decodes from its start), playing only the frames from where it joins.

Timing: a message logged at L plays at ``origin + (L - bag start + pass * loop) / speed``
on CLOCK_MONOTONIC, where the origin is the service's (shared by all its cameras, as the
synthetic cameras share it) plus ``LEAD_NS``, and bag start and the loop length are the
bag's own. So
several ``bag`` cameras of one bag stay in step, as they were recorded: frames recorded
together play together. ``loop`` is the bag's span plus one mean frame interval of its
fastest image topic, the same for every topic of the bag. A camera that starts (or
restarts) late joins the playback where it is now, like a live camera; a frame more
than one interval late is dropped and counted, as a camera would, to stay in step.

A bag whose recording was cut off (no summary, a torn last record) plays its complete
messages (fxis_shm.formats.bagfile.BagReader reads it record by record, without changing
it), and the camera's status note says how many and where the file ends.

Stamps: ``stamps=now`` (default) stamps each frame with its play time, so a client
asks for ``at=now`` as of a live camera; ``stamps=recorded`` keeps the recorded
header.stamp (plus ``pass * loop``, so that stamps keep increasing), for code that
matches frames with other recorded data: it must then ask for frames by those times
(``at=``, ``wait="none"``), as the service sees them as long past.
"""

from __future__ import annotations

import logging
from contextlib import closing

import numpy as np

from fxis_shm.core import timebase
from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagReader
from fxis_shm.formats.videodecoder import COLOUR, DECODERS, TrackDecoder, pixels_of
from fxis_shm.shm.ring import FrameLayout
from fxis_shm.wire import encoding as codec

from .base import Camera, Capture

log = logging.getLogger("camera")
_IMAGE_TYPES = (rosmsgs.IMAGE, rosmsgs.COMPRESSED, rosmsgs.VIDEO)
_DEFAULT_INTERVAL_NS = 100_000_000  # the loop's gap for a topic of a single frame
# The bag starts playing this long after the service's origin: time enough for every camera
# worker to open, so that the first frame of the bag plays too (a worker that opens later
# joins the playback where it is).
LEAD_NS = 2_000_000_000


class BagCamera(Camera):
    kind = "bag"

    def __init__(self, name, options, time_origin_ns, clock: timebase.Clock = timebase.REAL):
        super().__init__(name, options, time_origin_ns)
        self.clock = clock  # the playback's clock and waits: a virtual one in tests
        path = self.options["path"]
        if path is None or not str(path).strip():
            raise ValueError(
                f"camera {name!r}: key 'path' is required: a bag folder recorded with fxis record (or its .mcap file)"
            )
        try:
            self._bag = BagReader(str(path).strip())
        except ConfigError as exc:
            raise ValueError(f"camera {name!r}: key 'path': {exc}") from None
        self._topic = self._choose_topic(self.options["topic"])
        self._compressed = self._bag.topics[self._topic] == rosmsgs.COMPRESSED
        self._video = self._bag.topics[self._topic] == rosmsgs.VIDEO
        self._keyframes = self._keyframe_times() if self._video else []
        self._decoder: TrackDecoder | None = None  # of the video pass playing now
        self._pixels = COLOUR  # a video track's layout, read from its first picture (open)
        self._codec = self._video_codec() if self._video else ""
        self._start = self._bag.start_time
        counts = [self._bag.counts.get(t, 0) for t, kind in self._bag.topics.items() if kind in _IMAGE_TYPES]
        span = self._bag.end_time - self._start
        most = max(counts, default=1)
        interval = span // (most - 1) if most > 1 and span > 0 else _DEFAULT_INTERVAL_NS
        self._loop_ns = span + interval  # the same for every camera of this bag: they stay in step
        mine = self._bag.counts.get(self._topic, 0)
        mean = span / (mine - 1) if mine > 1 and span > 0 else interval
        self._period_ns = round(mean / self.options["speed"])
        self._k = 0
        self._frames = None
        self._next: tuple[int, int, np.ndarray] | None = None  # (due, t_capture, image)
        self._damage = self._bag.damage(self._topic)  # a file cut off plays what is complete, and says so
        self.note = self._damage
        if self._damage:
            log.warning("camera %s (%s): %s", name, self._topic, self._bag.damage(self._topic, detail=True))

    def _choose_topic(self, topic) -> str:
        images = sorted(t for t, kind in self._bag.topics.items() if kind in _IMAGE_TYPES)
        listing = f"its image topics: {', '.join(images) or 'none'}; all topics: " + ", ".join(
            f"{t} ({kind})" for t, kind in sorted(self._bag.topics.items())
        )
        if topic is None or not str(topic).strip():
            if len(images) != 1:
                raise ValueError(
                    f"camera {self.name!r}: key 'topic' is required: the bag "
                    f"{self._bag.path!r} has {len(images)} image topics; {listing}"
                )
            return images[0]
        topic = str(topic).strip()
        if topic not in self._bag.topics:
            raise ValueError(
                f"camera {self.name!r}: key 'topic': no topic {topic!r} in the bag {self._bag.path!r}; {listing}"
            )
        if topic not in images:
            raise ValueError(
                f"camera {self.name!r}: key 'topic': {topic!r} holds {self._bag.topics[topic]}, not images; {listing}"
            )
        if not self._bag.counts.get(topic):
            raise ValueError(f"camera {self.name!r}: key 'topic': {topic!r} has no messages")
        return topic

    def _video_codec(self) -> str:
        with closing(self._bag.messages(self._topic)) as messages:
            _, first = next(messages)
        if first.format not in DECODERS:
            raise ValueError(
                f"camera {self.name!r}: {self._topic} is {first.format!r} video; the bag camera plays "
                + ", ".join(DECODERS)
            )
        return first.format

    def _keyframe_times(self) -> list[int]:
        """Log times of the video track's keyframes, from its /frames topic ([] if it has none)."""
        frames = rosmsgs.video_frames_topic(self._topic.removeprefix("/").removesuffix("/video"))
        if self._bag.topics.get(frames) != rosmsgs.VIDEO_FRAME:
            return []
        return [log_time for log_time, info in self._bag.messages(frames) if info.keyframe]

    def _decode_from(self, start: int) -> int:
        """A new video decoder, and the log time of the keyframe to decode ``start`` from."""
        self._decoder = TrackDecoder(self._codec, self._pixels)
        return max((t for t in self._keyframes if t <= start), default=self._start)

    # -- the Camera interface ------------------------------------------------------------

    def open(self) -> None:
        with closing(self._bag.messages(self._topic)) as messages:
            _, first = next(messages)
        if self._video:  # its layout: the first picture's size, mono or colour as its chroma says
            picture = TrackDecoder(self._codec).picture(bytes(first.data))
            self._pixels = pixels_of(picture)
            image = picture.to_ndarray(format=self._pixels)
        else:
            image = self._image(first)
        self._layout = FrameLayout.of(image)
        self._frames = self._play_from(self.clock.now_ns())
        self._next = None

    def close(self) -> None:
        if self._frames is not None:
            self._frames.close()
            self._frames = None

    def _play_from(self, now: int):
        """(due, t_capture, message) of each frame to play, from the first due at or after ``now``."""
        speed = self.options["speed"]
        origin = self.time_origin_ns + LEAD_NS
        elapsed = max(0, int((now - origin) * speed))
        playback, within = divmod(elapsed, self._loop_ns)
        while self.options["loop"] or playback == 0:
            joins = self._start + within
            begin = self._decode_from(joins) if self._video else joins
            for log_time, msg in self._bag.messages(self._topic, begin):
                if log_time < joins:  # decoded for the frames after it, not played
                    self._decode_quietly(msg)
                    continue
                offset = log_time - self._start + playback * self._loop_ns
                due = origin + round(offset / speed)
                stamp = msg.timestamp if self._video else msg.header.stamp  # (CompressedVideo has no header)
                recorded = rosmsgs.stamp_ns(stamp) + playback * self._loop_ns
                yield due, due if self.options["stamps"] == "now" else recorded, msg
            within = 0
            playback += 1
        self.note = (
            f"end of bag (loop=false); {self._damage}" if self._damage else f"end of bag {self._bag.path} (loop=false)"
        )

    def _decode_quietly(self, msg) -> None:
        try:
            self._image(msg)
        except FxisError:
            pass  # a frame before the joining point: the frames that depend on it say so

    def _image(self, msg) -> np.ndarray:
        if self._video:
            assert self._decoder is not None
            return self._decoder.decode(bytes(msg.data))
        if self._compressed:
            return codec.decode(bytes(msg.data), codec.JPEG if "jpeg" in msg.format.lower() else codec.PNG, None, None)
        return rosmsgs.image_array(msg)

    def _pull(self) -> tuple[int, int, np.ndarray] | None:
        """The next frame to play with its pixels decoded, or None at the end."""
        while True:
            try:
                due, t_capture, msg = next(self._frames)
            except StopIteration:
                return None
            try:
                image = self._image(msg)
            except FxisError as exc:  # one undecodable message: skip it, say why
                self.frames_dropped += 1
                self.note = f"a message of {self._topic} could not be played: {exc}"
                continue
            if FrameLayout.of(image) != self._layout:
                self.frames_dropped += 1
                self.note = f"a frame of {self._topic} is {FrameLayout.of(image)}, not {self._layout}"
                continue
            return due, t_capture, image

    def grab(self, timeout: float) -> Capture | None:
        give_up = self.clock.now_ns() + int(timeout * 1e9)
        while True:
            if self._next is None:
                self._next = self._pull()
            if self._next is None:  # the end of a bag played once
                self.clock.sleep_until(give_up)
                return None
            due, t_capture, image = self._next
            now = self.clock.now_ns()
            if due < now - self._period_ns:  # more than a frame late: lost, as on a camera
                self.frames_dropped += 1
                self._next = None
                continue
            if due > give_up:
                self.clock.sleep_until(give_up)
                return None
            self.clock.sleep_until(due)
            self._next = None
            self._k += 1
            return Capture(image, self._k - 1, t_capture)
