"""``fxis export``: one camera's video track of a bag (``/NAME/video``, what ``fxis record
--codec`` and ``fxis snapshot --codec`` write) into an MP4 file, without re-encoding.

The packets are copied as they are (FFmpeg's MP4 muxer, through PyAV, turns Annex B into the
length-prefixed form MP4 keeps and takes the parameter sets of the first keyframe for the
file's header). Each frame's presentation time is its capture time: pts = capture time minus
the first frame's, in microseconds, so the MP4 has a variable frame rate and a dropped frame
leaves a gap in time, never a shifted clip. What pts 0 is (the first capture time, in the
bag's clock) is in the file's metadata, and a sidecar ``FILE.frames.csv`` gives each frame's
pts, capture time, frame id and generation (from ``/NAME/video/frames``).
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from fractions import Fraction

from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import RECORD, BagReader
from fxis_shm.formats.videodecoder import DECODERS
from fxis_shm.formats.videoencoder import require_av

STREAMS = {"h264": "h264", "h265": "hevc", "av1": "av1"}  # the format field -> FFmpeg's codec name
RAW_FORMATS = {"h264": "h264", "h265": "hevc", "av1": "obu"}  # FFmpeg's demuxer of each raw bitstream
TIME_BASE = Fraction(1, 1_000_000)  # pts in microseconds of capture time
_US = 1000


@dataclass
class Exported:
    out: str
    sidecar: str
    topic: str
    codec: str
    frames: int
    seconds: float
    t0_ns: int  # the capture time pts 0 stands for, in the bag's clock
    skipped: int  # messages before the track's first keyframe (nothing to decode them from)


def sidecar_path(out: str) -> str:
    return os.path.splitext(out)[0] + ".frames.csv"


def video_cameras(bag: BagReader) -> list[str]:
    return sorted(t.split("/")[1] for t, kind in bag.topics.items() if kind == rosmsgs.VIDEO)


def export_mp4(bag_path: str, camera: str, out: str) -> Exported:
    """Write ``camera``'s video track of the bag ``bag_path`` into the MP4 file ``out`` (and its
    sidecar); ConfigError if the bag has no such track, InvalidArgument for an ``out`` that exists."""
    av = require_av()
    bag = BagReader(bag_path)
    topic = rosmsgs.video_topic(camera)
    if bag.topics.get(topic) != rosmsgs.VIDEO:
        have = video_cameras(bag)
        said = f"its video cameras: {', '.join(have)}" if have else "it holds no video (record with --codec h264)"
        raise ConfigError(f"{bag.path}: no video track of camera {camera} ({topic}); {said}")
    _check_out(out)
    frames = {
        rosmsgs.stamp_ns(m.header.stamp): (m.frame_id, m.generation)
        for _, m in bag.messages(rosmsgs.video_frames_topic(camera))
    }
    try:
        return _write(av, bag, topic, out, frames)
    except BaseException:
        for path in (out, sidecar_path(out)):
            if os.path.exists(path):
                os.remove(path)  # half a file is no export
        raise


def _check_out(out: str) -> None:
    for path in (out, sidecar_path(out)):
        if os.path.lexists(path):
            raise InvalidArgument(f"--out {out}: {path} exists; give a new file name")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise InvalidArgument(f"--out {out}: the folder {folder} does not exist")


def _write(av, bag: BagReader, topic: str, out: str, frames: dict) -> Exported:
    container = stream = None
    t0 = last = count = skipped = 0
    codec = ""
    with open(sidecar_path(out), "w", newline="") as side:
        rows = csv.writer(side, lineterminator="\n")  # (csv's default ends lines in CRLF)
        rows.writerow(["pts_us", "capture_ns", "frame_id", "generation"])
        for _, message in bag.messages(topic):
            t_ns, data, codec = rosmsgs.stamp_ns(message.timestamp), bytes(message.data), message.format
            if codec not in STREAMS:
                raise ConfigError(f"{topic}: format {codec!r}; MP4 export takes {', '.join(STREAMS)}")
            keyframe = _is_keyframe(av, codec, data)
            if container is None:
                if not keyframe:
                    skipped += 1  # a track cut before its first keyframe: nothing decodes from here
                    continue
                t0 = t_ns
                said = f"{topic}: pts 0 is capture time {t0} ns ({_clock(bag)})"
                container, stream = _open(av, out, codec, data, said)
            packet = av.Packet(data)
            packet.stream, packet.time_base, packet.is_keyframe = stream, TIME_BASE, keyframe
            packet.pts = packet.dts = (t_ns - t0) // _US
            container.mux(packet)
            frame_id, generation = frames.get(t_ns, ("", ""))
            rows.writerow([packet.pts, t_ns, frame_id, generation])
            count, last = count + 1, t_ns
    if container is None:
        raise ConfigError(f"{bag.path}: {topic} holds no keyframe: nothing in it decodes")
    container.close()
    return Exported(out, sidecar_path(out), topic, codec, count, (last - t0) / 1e9, t0, skipped)


def _clock(bag: BagReader) -> str:
    return bag.metadata.get(RECORD, {}).get("clock", "the bag's clock")


def _open(av, out: str, codec: str, keyframe: bytes, comment: str):
    """The MP4 and its one stream, whose parameters FFmpeg's demuxer of the raw bitstream reads
    from ``keyframe``: a stream copied as it is, with no encoder opened (an encoder's open
    printed libx265's and SVT-AV1's banners, 21 lines, though nothing is encoded)."""
    _size(av, codec, keyframe)  # a damaged keyframe: ConfigError, before the file is made
    with av.open(io.BytesIO(keyframe), "r", format=RAW_FORMATS[codec]) as raw:
        container = av.open(out, "w", format="mp4")
        container.metadata["comment"] = f"fxis export of {comment}"
        stream = container.add_stream_from_template(raw.streams.video[0], opaque=True)
    stream.time_base = TIME_BASE
    return container, stream


def _is_keyframe(av, codec: str, data: bytes) -> bool:
    """Whether FFmpeg's parser of the codec reads ``data`` as one keyframe (the sync samples of
    the MP4, where a player may start)."""
    parser = av.CodecContext.create(STREAMS[codec], "r")
    parsed = parser.parse(data) + parser.parse(None)
    return len(parsed) == 1 and bool(parsed[0].is_keyframe)


def _size(av, codec: str, keyframe: bytes) -> tuple[int, int]:
    """(width, height) of the picture of ``keyframe`` (the MP4's header holds the first's)."""
    decoder = av.CodecContext.create(DECODERS[codec], "r")
    pictures = decoder.decode(av.Packet(keyframe)) + decoder.decode(None)
    if not pictures:
        raise ConfigError(f"a keyframe of {len(keyframe)} bytes did not decode: the track is damaged")
    return pictures[0].width, pictures[0].height
