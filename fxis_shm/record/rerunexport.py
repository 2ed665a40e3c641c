"""``fxis export BAG --rerun OUT.rrd``: a recording (``fxis record``, ``snapshot``, the cell's
``record``) as a Rerun recording, each camera on its capture-time timeline (fxis_shm.formats.rerunlog).

- a video track (``/NAME/video``, foxglove CompressedVideo) becomes a ``VideoStream`` of the same
  packets, byte for byte: nothing is decoded or encoded; ``/NAME/video/frames`` gives each
  packet's frame id and whether it is a keyframe;
- raw images (``/NAME/image_raw``) become ``Image``s, JPEG ones (``.../compressed``) ``EncodedImage``s
  of the same bytes;
- a recording of tuples (``--tuples``) stamps each image with its step time, and ``/fxis/tuples``
  names each frame's id and capture time: the images are put at their capture time, and each
  tuple's skew and sync verdict are logged at its step time.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass, field

from fxis_shm.core.syncstats import DEFAULT_THRESHOLD_MS
from fxis_shm.errors import ConfigError, FxisError, InvalidArgument
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import RECORD, BagReader
from fxis_shm.formats.rerunlog import RerunLog, require_rerun

FLAG = "--rerun"
# the topic kinds that hold a camera's pictures, and what Rerun is given of each
KINDS = {rosmsgs.IMAGE: "images", rosmsgs.COMPRESSED: "JPEG images", rosmsgs.VIDEO: "video packets"}


@dataclass
class RerunExported:
    out: str
    clock: str
    frames: dict[str, tuple[str, int]] = field(default_factory=dict)  # camera -> (what, how many)
    tuples: int = 0

    def describe(self) -> str:
        cameras = ", ".join(f"{cam} {n} {what}" for cam, (what, n) in self.frames.items())
        sync = (
            f"; {self.tuples} tuples' skew and sync verdict"
            if self.tuples
            else "; no tuples (recorded without --tuples)"
        )
        return f"{self.out}: {cameras}{sync}; timeline capture_time in {self.clock}"


def camera_tracks(bag: BagReader) -> dict[str, tuple[str, str]]:
    """camera -> (topic, message type) of each camera's pictures in the bag."""
    return {topic.split("/")[1]: (topic, kind) for topic, kind in sorted(bag.topics.items()) if kind in KINDS}


def export_rerun(bag_path: str, out: str, threshold_ms: float = DEFAULT_THRESHOLD_MS) -> RerunExported:
    """Write the bag ``bag_path`` as the Rerun recording ``out`` (a new .rrd file): ConfigError for
    a bag without pictures (or without rerun-sdk), InvalidArgument for an ``out`` that exists."""
    require_rerun(FLAG)  # before the bag is read: a missing extra is said first
    bag = BagReader(bag_path)
    tracks = camera_tracks(bag)
    if not tracks:
        raise ConfigError(f"{bag.path}: no camera images or video in it (topics: {', '.join(sorted(bag.topics))})")
    check_new_file(out, FLAG)
    clock = bag.metadata.get(RECORD, {}).get("clock") or "the bag's clock"
    log = RerunLog(FLAG, clock, os.path.basename(os.path.normpath(bag_path))).save(out)
    try:
        done = RerunExported(out, clock)
        captures = _tuples(bag, log, list(tracks), threshold_ms, done)
        for camera, (topic, kind) in tracks.items():
            count = _pictures(bag, log, camera, topic, kind, captures)
            done.frames[camera] = (KINDS[kind], count)
    except BaseException:
        with contextlib.suppress(FxisError):
            log.close()
        os.remove(out)  # half a recording is no export
        raise
    log.close()
    return done


def check_new_file(out: str, flag: str) -> None:
    if os.path.lexists(out):
        raise InvalidArgument(f"{flag} {out}: it exists; give a new file name")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise InvalidArgument(f"{flag} {out}: the folder {folder} does not exist")


Captures = dict[tuple[str, int], tuple[int, int]]  # (camera, step time) -> (capture time, frame id)


def _tuples(bag: BagReader, log: RerunLog, cameras: list[str], threshold_ms: float, done: RerunExported) -> Captures:
    """Each tuple's skew and verdict logged; what its frames are, for the images stamped with its step."""
    captures: Captures = {}
    if bag.topics.get(rosmsgs.TUPLES_TOPIC) != rosmsgs.TUPLE:
        return captures
    for _, message in bag.messages(rosmsgs.TUPLES_TOPIC):
        step = rosmsgs.stamp_ns(message.header.stamp)
        times = [rosmsgs.stamp_ns(t) for t in message.capture_stamps]
        for camera, t_ns, frame_id in zip(message.cameras, times, message.frame_ids):
            captures[camera, step] = (t_ns, frame_id)
        log.sync(step, times, set(cameras) <= set(message.cameras), threshold_ms)
        done.tuples += 1
    return captures


def _pictures(bag: BagReader, log: RerunLog, camera: str, topic: str, kind: str, captures: Captures) -> int:
    count = 0
    if kind == rosmsgs.VIDEO:
        frames = {
            rosmsgs.stamp_ns(m.header.stamp): (m.frame_id, m.keyframe)
            for _, m in bag.messages(rosmsgs.video_frames_topic(camera))
        }
        for _, m in bag.messages(topic):
            t_ns = rosmsgs.stamp_ns(m.timestamp)
            frame_id, keyframe = frames.get(t_ns, (None, None))
            log.video(camera, m.format, bytes(m.data), keyframe, t_ns, frame_id)
            count += 1
        return count
    for _, m in bag.messages(topic):
        stamp = rosmsgs.stamp_ns(m.header.stamp)
        t_ns, frame_id = captures.get((camera, stamp), (stamp, None))  # frames mode: the stamp is the capture time
        if kind == rosmsgs.COMPRESSED:
            log.jpeg(camera, bytes(m.data), t_ns, frame_id)
        else:
            log.image(camera, rosmsgs.image_array(m), t_ns, frame_id)
        count += 1
    return count
