"""The video of a recording (``fxis record --codec``): the settings checked at start, before a
bag exists, then one CameraEncoder per camera and their packets written into the bag from the
recorder's own thread (the bag has one writer, so a full disk and Ctrl-C end it as they end a
raw recording).

Each camera has two topics, message for message: ``/NAME/video`` (foxglove_msgs/msg/CompressedVideo,
what Foxglove plays) and ``/NAME/video/frames`` (fxis_msgs/msg/VideoFrame: the frame id and
generation, which lossy video cannot be trusted to keep in the pixels), both stamped with the
frame's capture time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fxis_shm.errors import FxisError, InvalidArgument
from fxis_shm.formats import rosmsgs
from fxis_shm.record import videochoice
from fxis_shm.record.videoencoder import CameraEncoder, opens, require_av


@dataclass
class VideoSettings:
    codec: str
    encoder: str = videochoice.AUTO
    crf: int | None = None
    preset: str | None = None
    gop_s: float | None = None


def check_flags(video: VideoSettings) -> None:
    """What can be checked without FFmpeg or the service: ConfigError naming the flag."""
    videochoice.candidates(video.codec, video.encoder)
    videochoice.check_crf(video.codec, video.crf)
    videochoice.check_gop(video.gop_s)


@dataclass
class VideoPlan:
    """The settings checked against FFmpeg and the cameras: what a recording will use."""

    choice: videochoice.Choice
    crf: int
    preset: str | None
    gop_s: float
    fps: dict[str, float]

    @classmethod
    def make(cls, video: VideoSettings, cameras: dict[str, dict]) -> VideoPlan:
        """``cameras``: each recorded camera's status (shape, dtype, fps)."""
        check_flags(video)
        for name, info in cameras.items():
            shape = list(info.get("shape") or [0, 0])
            videochoice.check_camera(video.codec, name, _encoding(shape, info.get("dtype")), shape[1], shape[0])
        av = require_av()
        choice = videochoice.choose(video.codec, video.encoder, av.codecs_available, lambda n: opens(_as(video, n)))
        return cls(
            choice,
            videochoice.check_crf(video.codec, video.crf),
            videochoice.check_preset(choice, video.preset),
            videochoice.check_gop(video.gop_s),
            {name: float(info.get("fps") or 0.0) for name, info in cameras.items()},
        )

    def describe(self) -> str:
        preset = f", preset {self.preset}" if self.preset else ""
        return f"video: {self.choice.describe()}, CRF {self.crf}{preset}, a keyframe at least every {self.gop_s:g} s"


def _as(video: VideoSettings, encoder: str) -> videochoice.Choice:
    return videochoice.Choice(video.codec, encoder, encoder not in videochoice.SOFTWARE_ENCODERS[video.codec])


def _encoding(shape: list[int], dtype: str | None) -> str:
    channels = shape[2] if len(shape) == 3 else 1
    try:
        return rosmsgs.ros_encoding(np.empty((1, 1, channels), np.dtype(dtype or "uint8")))
    except InvalidArgument:
        return f"{channels}-channel {dtype}"


class VideoTracks:
    def __init__(self, plan: VideoPlan, cameras: list[str]):
        self.plan = plan
        self.encoders = {
            cam: CameraEncoder(cam, plan.choice, plan.crf, plan.preset, plan.gop_s, plan.fps.get(cam, 0.0))
            for cam in cameras
        }
        self.behind: set[str] = set()  # cameras whose encoder has skipped frames (said once)

    def offer(self, frame, t_stamp: int) -> None:
        self.encoders[frame.camera].offer(frame.image, t_stamp, frame.frame_id, frame.generation)

    def newly_behind(self) -> list[str]:
        """Cameras whose encoder began skipping frames since the last call."""
        now = {cam for cam, e in self.encoders.items() if e.skipped}
        fresh, self.behind = sorted(now - self.behind), now
        return fresh

    def write_ready(self, bag, to_realtime: int) -> None:
        for cam, encoder in self.encoders.items():
            self._write(bag, cam, encoder.ready(), to_realtime)
            if encoder.error is not None:
                raise FxisError(f"{cam}: the {self.plan.choice.encoder} encoder failed: {encoder.error}")

    def finish(self, bag, to_realtime: int) -> None:
        """Flush every encoder and write what it still held."""
        for cam, encoder in self.encoders.items():
            self._write(bag, cam, encoder.finish(), to_realtime)

    def _write(self, bag, cam: str, packets, to_realtime: int) -> None:
        for packet in packets:
            video, info = rosmsgs.video_messages(packet, cam, self.plan.choice.codec)
            log_time = packet.t_ns + to_realtime
            bag.write(rosmsgs.video_topic(cam), rosmsgs.VIDEO, video, log_time, len(packet.data))
            bag.write(rosmsgs.video_frames_topic(cam), rosmsgs.VIDEO_FRAME, info, log_time)
