"""The frames of each camera of a bag written by ``fxis record``, with their true capture
times: raw (``/NAME/image_raw``), JPEG (``/NAME/image_raw/compressed``) or video
(``/NAME/video``). A first pass reads the capture times only; ``images`` then walks the
camera's messages once more and yields the pictures asked for, in the order asked.

In a bag recorded with ``--tuples`` every image is stamped with its tuple's step time; the
capture times are those of ``/fxis/tuples`` (fxis_shm.formats.rosmsgs).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from fxis_shm.errors import ConfigError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import RECORD, BagReader
from fxis_shm.wire import encoding

RAW, JPEG, VIDEO = "raw", "jpeg", "video"


@dataclass
class CameraTrack:
    camera: str
    kind: str  # RAW, JPEG or VIDEO
    topic: str
    times: list[int]  # true capture times (ns, the bag's clock), one per usable message, in order
    skipped: int = 0  # video messages before the first keyframe (nothing decodes from them)


def camera_tracks(bag: BagReader) -> list[CameraTrack]:
    """Each camera's track of the bag (video preferred over images when both are there)."""
    found: dict[str, tuple[str, str]] = {}
    for topic, msgtype in sorted(bag.topics.items()):
        parts = topic.split("/")
        if msgtype == rosmsgs.IMAGE and topic == rosmsgs.image_topic(parts[1]):
            found.setdefault(parts[1], (RAW, topic))
        elif msgtype == rosmsgs.COMPRESSED and topic == rosmsgs.image_topic(parts[1], True):
            found.setdefault(parts[1], (JPEG, topic))
        elif msgtype == rosmsgs.VIDEO and topic == rosmsgs.video_topic(parts[1]):
            found[parts[1]] = (VIDEO, topic)
    if not found:
        raise ConfigError(f"{bag.path}: no camera images in it (fxis record writes /NAME/image_raw or /NAME/video)")
    tuples = _tuple_captures(bag)
    return [_track(bag, cam, kind, topic, tuples) for cam, (kind, topic) in sorted(found.items())]


def _tuple_captures(bag: BagReader) -> dict[tuple[str, int], int] | None:
    """(camera, step stamp) -> capture time, for a bag recorded with --tuples; else None."""
    if bag.metadata.get(RECORD, {}).get("mode") != "tuples" or rosmsgs.TUPLES_TOPIC not in bag.topics:
        return None
    captures = {}
    for _, m in bag.messages(rosmsgs.TUPLES_TOPIC):
        step = rosmsgs.stamp_ns(m.header.stamp)
        for cam, stamp in zip(m.cameras, m.capture_stamps):
            captures[(cam, step)] = rosmsgs.stamp_ns(stamp)
    return captures


def _track(bag: BagReader, cam: str, kind: str, topic: str, tuples) -> CameraTrack:
    if kind == VIDEO:
        keyframes = [m.keyframe for _, m in bag.messages(rosmsgs.video_frames_topic(cam))]
        stamps = [rosmsgs.stamp_ns(m.timestamp) for _, m in bag.messages(topic)]
        first = keyframes.index(True) if True in keyframes else len(stamps)
        track = CameraTrack(cam, kind, topic, stamps[first:], skipped=first)
    else:
        stamps = [rosmsgs.stamp_ns(m.header.stamp) for _, m in bag.messages(topic)]
        if tuples is not None:
            stamps = [tuples.get((cam, s), s) for s in stamps]
        track = CameraTrack(cam, kind, topic, stamps)
    if len(track.times) < 2:
        raise ConfigError(f"{bag.path}: camera {cam} has {len(track.times)} usable frame(s) on {topic}; too few")
    if any(b < a for a, b in zip(track.times, track.times[1:])):
        raise ConfigError(f"{bag.path}: {topic}'s capture times go backwards; this export needs them in order")
    return track


def images(bag: BagReader, track: CameraTrack, wanted: Sequence[int]) -> Iterator[np.ndarray]:
    """The RGB picture (h, w, 3 uint8) of each message position in ``wanted`` (positions in
    ``track.times``, in the order given, repeats allowed), reading the topic once."""
    uses = Counter(wanted)
    kept: dict[int, np.ndarray] = {}
    messages = _pictures(bag, track)
    position = -1
    for i in wanted:
        while i not in kept:
            position, picture = next(messages)
            if position in uses:
                kept[position] = picture
        yield kept[i]
        uses[i] -= 1
        if not uses[i]:
            del kept[i]


def _pictures(bag: BagReader, track: CameraTrack) -> Iterator[tuple[int, np.ndarray]]:
    """(position, RGB picture) of every usable message of the track, in order; a picture is
    decoded only when needed (raw copies nothing, JPEG decodes, video decodes every frame)."""
    if track.kind == VIDEO:
        from fxis_shm.formats.videodecoder import TrackDecoder

        decoder = TrackDecoder(next(m.format for _, m in bag.messages(track.topic)), "rgb24")
        for n, (_, m) in enumerate(bag.messages(track.topic)):
            if n >= track.skipped:
                yield n - track.skipped, decoder.decode(bytes(m.data))
        return
    for n, (_, m) in enumerate(bag.messages(track.topic)):
        if track.kind == RAW:
            image = rosmsgs.image_array(m)
        else:
            image = encoding.decode(bytes(m.data), encoding.JPEG, None, None)
        yield n, rgb(image)


def rgb(image: np.ndarray) -> np.ndarray:
    """An (h, w, 3) uint8 RGB picture of a mono8, bgr8 or bgra8 frame."""
    if image.dtype != np.uint8:
        raise ConfigError(f"a {image.dtype.name} frame: LeRobot's videos take 8-bit frames (mono8, bgr8)")
    if image.ndim == 2:
        return np.repeat(image[:, :, None], 3, axis=2)
    return np.ascontiguousarray(image[:, :, 2::-1])
