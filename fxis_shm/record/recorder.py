"""``fxis record``: the cameras' frames into a rosbag2 bag (MCAP storage), through the
client API, so recording is one more reader of the rings and never slows acquisition.

Each poll lists every camera's frames (the ``frames`` op, no pixels), takes the new
ones as one ``range`` sequence per camera (``--tuples``: one ``interval`` sequence of
synchronized tuples) and writes them. A recorder that falls behind loses frames to
the ring, and says how many (fxis_shm.record.recording); it never thins silently.
Message layout, clock and topics: docs/recording.md.
"""

from __future__ import annotations

import errno
import math
import os
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from fxis_shm.client.client import Client
from fxis_shm.client.snapshot import interrupted_by
from fxis_shm.core import timebase
from fxis_shm.errors import CameraDown, ConfigError, DiskFull, Overwritten, ServiceError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagWriter
from fxis_shm.formats.videotracks import CannotCarry, VideoPlan, VideoSettings, VideoTracks
from fxis_shm.record.recording import Follower, Steps, restart_record
from fxis_shm.wire import encoding as codec

_MAX_TUPLES_PER_REQUEST = 16  # bounds a reply's size (and the service's sequence limit)
_POLL_MIN_S, _POLL_MAX_S = 0.005, 0.1
_MIN_SECONDS = 3  # a disk that cannot hold this much of a raw recording refuses it at start


def _size(n: float) -> str:
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.1f} MB"


@dataclass
class RecordSettings:
    out: str
    endpoint: str
    cameras: list[str] | None = None
    seconds: float | None = None
    frames: int | None = None  # per camera (per-camera mode) or tuples (--tuples)
    rate_hz: float | None = None
    tuples: bool = False
    encoding: str = codec.RAW
    quality: int = codec.DEFAULT_JPEG_QUALITY
    video: VideoSettings | None = None  # --codec: video instead of images (fxis_shm.formats.videotracks)


class Recorder:
    def __init__(self, settings: RecordSettings, client: Client, progress=None):
        self.s = settings
        self.client = client
        self.stopped_by: str | None = None  # what ended the recording before its end: a size video cannot carry
        self.progress = progress or Progress(sys.stderr)
        status = client.status()
        known = list(status["cameras"])
        self.cameras = settings.cameras or known
        unknown = [c for c in self.cameras if c not in known]
        if unknown:
            raise ConfigError(f"--cameras: unknown camera(s) {', '.join(unknown)}; the service has {', '.join(known)}")
        self._dropped_at_start = {c: status["cameras"][c].get("frames_dropped") or 0 for c in self.cameras}
        listing = client.frame_times(self.cameras)
        self.t_start = self._polled_at = listing["now"]
        # The stamps are in the service's clock; MCAP log times are wall-clock (what Foxglove
        # and `ros2 bag info` show as dates): the stamp plus this offset.
        self.service_clock = timebase.WIRE_NAMES[timebase.of_status(status)]
        self.to_realtime = time.time_ns() - self.client.time()
        periods = {c: listing["cameras"][c].get("period_ns") or 0 for c in self.cameras}
        self.periods = periods
        if settings.tuples:
            slowest = max(periods.values())
            rate = settings.rate_hz or (1e9 / slowest if slowest else None)
            if rate is None:
                raise ConfigError("--tuples: the cameras have no frame period (triggered?); give --rate")
            self.steps = Steps(self.t_start, rate)
        else:
            self.followers = {c: Follower(self.t_start, settings.rate_hz) for c in self.cameras}
        self._check_room(status["cameras"])
        plan = self._video_plan(status["cameras"])  # before the bag: bad settings leave nothing behind
        self.bag = BagWriter(settings.out, self._custom_data())
        self.video = VideoTracks(plan, self.cameras) if plan else None
        self.poll_s = min(_POLL_MAX_S, max(_POLL_MIN_S, min((p for p in periods.values() if p), default=1e8) / 2e9))

    def _video_plan(self, status: dict) -> VideoPlan | None:
        if self.s.video is None:
            return None
        if self.s.tuples:
            raise ConfigError("--codec records every frame of each camera; it does not take --tuples")
        plan = VideoPlan.make(self.s.video, {c: status[c] for c in self.cameras})
        self.progress.stage(plan.describe())
        return plan

    def _topic(self, cam: str) -> str:
        if self.s.video is not None:
            return rosmsgs.video_topic(cam)
        return rosmsgs.image_topic(cam, self.s.encoding == codec.JPEG)

    def _custom_data(self) -> dict:
        return {
            "clock": self.service_clock,
            "stamps": "header.stamp: capture time"
            if not self.s.tuples
            else "header.stamp: the tuple's step time (the same in every image of a tuple)",
            "log_time": "header.stamp + clock_to_realtime_ns (CLOCK_REALTIME)",
            "clock_to_realtime_ns": self.to_realtime,
            "endpoint": self.s.endpoint,
            "cameras": ",".join(self.cameras),
            "mode": "tuples" if self.s.tuples else "frames",
            "rate_hz": self.s.rate_hz or (self.steps.rate_hz if self.s.tuples else "all frames"),
            "encoding": self.s.video.codec if self.s.video else self.s.encoding,
            "recorder": "fxis record",
            "ended": "",  # complete, interrupted by SIGINT / SIGTERM, the disk was full: set when closed
        }

    # ---- the loop ----

    def run(self) -> dict:
        """Record until --seconds or --frames is reached or Ctrl-C (SIGINT, SIGTERM). A signal
        only asks the loop to stop, so it never lands in the middle of writing a message; a
        second Ctrl-C interrupts at once."""
        self._stopping = False
        self.interrupted_by: str | None = None  # the signal that ended the recording, if one did
        previous = (
            {sig: signal.signal(sig, self._ask_to_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
            if _main_thread()
            else {}
        )
        self.progress.stage(f"recording {', '.join(self.cameras)} into {self.s.out}")
        self.progress.stage(self._data_rate_line())
        ended = "complete"
        try:
            try:
                while not self._stopping and not self._done():
                    began = time.monotonic()
                    self._poll()
                    if self.video is not None:
                        self._write_video()
                    self.progress.update(self._line())
                    time.sleep(max(0.0, self.poll_s - (time.monotonic() - began)))
                if self._stopping:
                    ended = f"interrupted by {self.interrupted_by}"
                    self.progress.stage(f"{ended}: closing the bag")
            except CannotCarry as exc:  # the bag is closed with the frames before it, and summed up
                self.stopped_by = str(exc)
                ended = f"stopped: {exc}"
            except KeyboardInterrupt as exc:  # a second Ctrl-C: the bag is closed all the same
                self.interrupted_by = interrupted_by(exc)
                ended = f"interrupted by {self.interrupted_by}"
                raise
            except BaseException as exc:
                ended = f"stopped by an error: {exc}"
                raise
            finally:
                self.bag.custom_data["ended"] = self._ended(ended)
                if self.video is not None and not self.bag.closed:
                    self.video.finish(self.bag, self.to_realtime)  # what the encoders still hold
                self.bag.close()
        except DiskFull as exc:  # the bag was closed with what fitted
            raise self._disk_full(exc) from None
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        summary = self.summary()
        self.progress.stage(f"recorded {summary['seconds']:.1f} s into {self.s.out}")
        return summary

    def _ended(self, ended: str) -> str:
        """How the recording ended, with the frames restarts cost (also as JSON, ``restarts``)."""
        if self.s.tuples:  # a tuple a camera could not give is counted in tuples_missed
            return ended
        missing, self.bag.custom_data["restarts"] = restart_record(self.followers)
        if not missing:
            return ended
        return f"done, but {missing}" if ended == "complete" else f"{ended}; {missing}"

    def _write_video(self) -> None:
        self.video.write_ready(self.bag, self.to_realtime)
        for cam in self.video.newly_behind():
            self.progress.stage(
                f"{cam}: the {self.video.plan.choice.encoder} encoder is behind: skipping frames (counted)"
            )

    def _disk_full(self, exc: DiskFull) -> DiskFull:
        """The bag's DiskFull in the recording's words: frames per camera, seconds, bytes."""
        if not exc.valid:
            return exc
        kept = ", ".join(f"{cam} {exc.kept.get(self._topic(cam), 0)} frames" for cam in self.cameras)
        if self.s.tuples:
            kept += f", {exc.kept.get(rosmsgs.TUPLES_TOPIC, 0)} tuples"
        return DiskFull(
            f"{exc.reason} in {self.s.out}: the recording stopped and kept {kept}, "
            f"{exc.seconds:.1f} s, {exc.file_bytes / 1e6:.1f} MB, in a valid bag",
            **{k: getattr(exc, k) for k in ("folder", "reason", "kept", "seconds", "file_bytes", "valid")},
        )

    def _pixel_rate(self, status: dict) -> float:
        """Bytes of pixels a second the recording takes (a raw recording of two 1360x1024
        cameras at 20 fps writes 56 MB/s)."""
        rate = 0.0
        for cam in self.cameras:
            info = status[cam]
            frame_bytes = math.prod(info.get("shape") or [0]) * np.dtype(info.get("dtype") or "uint8").itemsize
            fps = self.s.rate_hz or info.get("fps") or 0.0
            rate += frame_bytes * min(fps, info.get("fps") or fps)
        return rate

    def _free(self) -> int:
        return shutil.disk_usage(os.path.dirname(os.path.abspath(self.s.out))).free

    def _check_room(self, status: dict) -> None:
        """DiskFull, before the bag is made, if its disk cannot hold even a few seconds of a raw
        recording (issue 33: it would start, and stop with nothing), as a snapshot's bag says
        when there is no room to start it."""
        rate, free = self._pixel_rate(status), self._free()
        raw = self.s.encoding == codec.RAW and self.s.video is None  # (video: its size is not known ahead)
        if raw and rate and free < _MIN_SECONDS * rate:
            raise DiskFull(
                f"--out {self.s.out}: {_size(free)} free there holds {free / rate:.1f} s of this recording "
                f"({_size(rate)}/s raw): nothing was recorded; free some room, record elsewhere, or record "
                "less (--cameras, --rate, --encoding jpeg)",
                folder=self.s.out,
                reason=os.strerror(errno.ENOSPC),
            )

    def _data_rate_line(self) -> str:
        """What the recording will write a second, and how long the disk lasts at that rate."""
        rate, free = self._pixel_rate(self.client.status()["cameras"]), self._free()
        if self.s.encoding != codec.RAW or self.s.video is not None:
            before = self.s.video.codec if self.s.video else "JPEG"
            return f"about {rate / 1e6:.0f} MB/s of pixels before {before}; {_size(free)} free"
        seconds = free / rate if rate else 0.0
        lasts = f"full in about {seconds / 60:.0f} min" if seconds >= 120 else f"full in about {seconds:.0f} s"
        return f"writing about {rate / 1e6:.0f} MB/s (raw); {_size(free)} free there: " + (
            lasts if rate else "no frame rate known yet"
        )

    def _ask_to_stop(self, signum, frame) -> None:
        self._stopping = True
        self.interrupted_by = self.interrupted_by or signal.Signals(signum).name
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C: at once

    def _now(self) -> int:
        """The service's clock at the last poll."""
        return self._polled_at

    def _done(self) -> bool:
        if self.s.seconds is not None and self._now() - self.t_start >= self.s.seconds * 1e9:
            return True
        if self.s.frames is not None:
            taken = [self.steps.taken] if self.s.tuples else [f.taken for f in self.followers.values()]
            return min(taken) >= self.s.frames
        return False

    def _poll(self) -> None:
        listing = self.client.frame_times(self.cameras)
        self._polled_at = listing["now"]
        if self.s.tuples:
            self._poll_tuples(listing)
        else:
            for cam in self.cameras:
                self._poll_camera(cam, listing["cameras"][cam])

    def _poll_camera(self, cam: str, info: dict) -> None:
        if not info.get("alive"):
            return  # its worker restarts it; the frames after the outage are taken then
        follower = self.followers[cam]
        rows = follower.new_frames(info["frames"], info.get("period_ns") or 0)
        if self.s.frames is not None:
            rows = rows[: max(0, self.s.frames - follower.taken)]
        if self.s.seconds is not None:
            rows = [r for r in rows if r[1] - self.t_start < self.s.seconds * 1e9]
        if not rows:
            return
        wanted = {r[0] for r in rows}
        try:
            mapping = self.client.clock_estimate()  # the listing is in the service's clock, the API in ours
            frames = self.client.sequence(
                "range", camera=cam, start=mapping.to_caller(rows[0][1]), end=mapping.to_caller(rows[-1][1])
            )
        except (Overwritten, ServiceError) as exc:
            if not _frames_gone(exc):
                raise
            if isinstance(exc, CameraDown):
                follower.give_back()  # still in the ring: taken when the camera is back
            else:
                follower.lost(len(rows))  # the ring came round between listing and copying
            return
        kept = [f for f in frames if f.frame_id in wanted]
        follower.lost(len(rows) - len(kept))
        for frame in kept:
            with frame:
                self._write_image(frame, frame.service_t_capture)
        follower.taken += len(kept)

    def _poll_tuples(self, listing: dict) -> None:
        cams = listing["cameras"]
        oldest = max((c["frames"][0][1] if c["frames"] else listing["now"]) for c in cams.values())
        # A step is due once every camera could have its frame: one period past it.
        horizon = listing["now"] - max(self.periods.values())
        limit = _MAX_TUPLES_PER_REQUEST
        if self.s.frames is not None:
            limit = min(limit, self.s.frames - self.steps.taken)
        times = self.steps.due(horizon, oldest, limit)
        if self.s.seconds is not None:
            times = [t for t in times if t - self.t_start < self.s.seconds * 1e9]
        if not times:
            return
        try:
            tuples = self.client.sequence(
                "interval",
                cameras=self.cameras,
                count=len(times),
                interval_ms=self.steps.interval_ns / 1e6,
                at=self.client.clock_estimate().to_caller(times[0]),
            )
        except (Overwritten, ServiceError) as exc:
            if not _frames_gone(exc):
                raise
            self.steps.advance(len(times), answered=False)
            return
        for t_step, frames in zip(times, tuples):
            with frames:
                for cam in self.cameras:
                    self._write_image(frames[cam], t_step)
                self.bag.write(
                    rosmsgs.TUPLES_TOPIC,
                    rosmsgs.TUPLE,
                    rosmsgs.tuple_message(t_step, [frames[c] for c in self.cameras]),
                    t_step + self.to_realtime,
                )
        self.steps.advance(len(times))

    def _write_image(self, frame, t_stamp: int) -> None:
        if self.video is not None:
            restarted = self.video.offer(frame, t_stamp)  # copied: the encoder's thread writes it later
            if restarted:
                self.progress.stage(restarted)
            return
        image = frame.image
        if self.s.encoding == codec.JPEG:
            data = codec.encode(image, codec.JPEG, self.s.quality)
            msg = rosmsgs.compressed_message(data, t_stamp, frame.camera)
            topic, msgtype, size = rosmsgs.image_topic(frame.camera, True), rosmsgs.COMPRESSED, len(data)
        else:
            msg = rosmsgs.image_message(image, t_stamp, frame.camera)
            topic, msgtype, size = rosmsgs.image_topic(frame.camera), rosmsgs.IMAGE, image.nbytes
        self.bag.write(topic, msgtype, msg, t_stamp + self.to_realtime, size)

    # ---- reporting ----

    def _line(self) -> str:
        if self.s.tuples:
            counts = f"tuples {self.steps.taken}  missed {self.steps.missed}"
        else:
            counts = "  ".join(f"{c} {f.taken}" for c, f in self.followers.items())
            counts += f"  missed {sum(f.missed for f in self.followers.values())}"
            if self.video is not None:
                counts += f"  skipped {sum(e.skipped for e in self.video.encoders.values())}"
        return f"{(self._now() - self.t_start) / 1e9:6.1f} s  {counts}  {self.bag.bytes_written / 1e6:.1f} MB"

    def summary(self) -> dict:
        try:
            status = self.client.status()["cameras"]
        except Exception:  # the service may be gone: the bag is still what counts
            status = {}
        per_camera = {}
        for cam in self.cameras:
            topic = self._topic(cam)
            counted = self.bag.topics.get(topic)
            dropped = status.get(cam, {}).get("frames_dropped")
            follower = None if self.s.tuples else self.followers[cam]
            per_camera[cam] = {
                "topic": topic,
                "frames": counted.count if counted else 0,
                "missed": None if follower is None else follower.missed,
                "missing_at_restarts": None if follower is None else follower.missing_at_restarts,
                "restarts": [] if follower is None else [gap.describe() for gap in follower.restarts],
                "lost_to_restarts": follower is not None and follower.lost_to_restarts,
                "dropped_by_camera": None if dropped is None else dropped - self._dropped_at_start[cam],
                "skipped_by_encoder": self.video.encoders[cam].skipped if self.video else None,
            }
        file_path = os.path.join(self.s.out, self.bag.file_name)
        return {
            "out": self.s.out,
            "interrupted_by": self.interrupted_by,
            "stopped_by": self.stopped_by,
            "seconds": (self._now() - self.t_start) / 1e9,
            "cameras": per_camera,
            "tuples": self.steps.taken if self.s.tuples else None,
            "tuples_missed": self.steps.missed if self.s.tuples else None,
            "image_bytes": self.bag.bytes_written,
            "file_bytes": os.path.getsize(file_path) if os.path.exists(file_path) else 0,
        }


def summary_table(summary: dict) -> str:
    rows = [["camera", "topic", "frames", "missed", "dropped by camera"]]
    for cam, c in summary["cameras"].items():
        rows.append(
            [
                cam,
                c["topic"],
                str(c["frames"]),
                "-" if c["missed"] is None else str(c["missed"]),
                "-" if c["dropped_by_camera"] is None else str(c["dropped_by_camera"]),
            ]
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows]
    lines += [f"{cam}: restarted, {gap}" for cam, c in summary["cameras"].items() for gap in c.get("restarts", [])]
    lines += [
        f"{cam}: the encoder fell behind and skipped {c['skipped_by_encoder']} frames"
        for cam, c in summary["cameras"].items()
        if c.get("skipped_by_encoder")
    ]
    if summary["tuples"] is not None:
        lines.append(f"tuples {summary['tuples']}, missed {summary['tuples_missed']}")
    lines.append(
        f"{summary['seconds']:.1f} s, {summary['image_bytes'] / 1e6:.1f} MB of images, "
        f"bag file {summary['file_bytes'] / 1e6:.1f} MB: {summary['out']}"
    )
    return "\n".join(lines)


class Progress:
    """On a terminal one line rewritten in place (at most 4 times a second); otherwise
    (a log) only a line per stage."""

    def __init__(self, stream):
        self.stream = stream
        self.tty = stream.isatty()
        self._shown = 0.0

    def stage(self, text: str) -> None:
        if self.tty and self._shown:
            self.stream.write("\n")
            self._shown = 0.0
        self.stream.write(f"fxis record: {text}\n")
        self.stream.flush()

    def update(self, text: str) -> None:
        if not self.tty or time.monotonic() - self._shown < 0.25:
            return
        self._shown = time.monotonic()
        self.stream.write(f"\r\x1b[K{text}")
        self.stream.flush()


def _frames_gone(exc: Exception) -> bool:
    """Whether a sequence failed because its frames are no longer there to copy: the ring
    came round (the recorder was too slow) or the camera went down meanwhile."""
    return isinstance(exc, (Overwritten, CameraDown)) or getattr(exc, "code", None) == "OUT_OF_RANGE"


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()
