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

from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.formats import rosmsgs, videochoice
from fxis_shm.formats.videoencoder import CameraEncoder, StreamEncoder, check_image, encoding_of, opens, require_av


class CannotCarry(FxisError):
    """A camera restarted in a size or format its video track cannot carry (an odd width for
    4:2:0 video): the recording ends there, with what it has (fxis_shm.record.recorder)."""


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
            videochoice.check_camera(video.codec, name, encoding_of(shape, info.get("dtype")), shape[1], shape[0])
        av = require_av()
        choice = videochoice.choose(video.codec, video.encoder, av.codecs_available, lambda n: opens(_as(video, n)))
        return cls(
            choice,
            videochoice.check_crf(video.codec, video.crf),
            videochoice.check_preset(choice, video.preset),
            videochoice.check_gop(video.gop_s),
            {name: float(info.get("fps") or 0.0) for name, info in cameras.items()},
        )

    def stream_encoder(self, camera: str) -> StreamEncoder:
        return StreamEncoder(camera, self.choice, self.crf, self.preset, self.gop_s, self.fps.get(camera, 0.0))

    def describe(self) -> str:
        preset = f", preset {self.preset}" if self.preset else ""
        return f"video: {self.choice.describe()}, CRF {self.crf}{preset}, a keyframe at least every {self.gop_s:g} s"


def _as(video: VideoSettings, encoder: str) -> videochoice.Choice:
    return videochoice.Choice(video.codec, encoder, encoder not in videochoice.SOFTWARE_ENCODERS[video.codec])


class VideoTracks:
    def __init__(self, plan: VideoPlan, cameras: list[str]):
        self.plan = plan
        self.encoders = {cam: CameraEncoder(plan.stream_encoder(cam)) for cam in cameras}
        self.behind: set[str] = set()  # cameras whose encoder has skipped frames (said once)
        self._generations: dict[str, int] = {}

    def offer(self, frame, t_stamp: int) -> str | None:
        """Hand the frame to its camera's encoder; the words for a new generation (a camera
        restarted, maybe at a new size), which its encoder begins with a keyframe, or
        CannotCarry for one the track cannot carry (its frames are not offered)."""
        before = self._generations.get(frame.camera)
        if before is not None and before != frame.generation:
            try:
                check_image(self.plan.choice.codec, frame.camera, frame.image)
            except ConfigError as exc:
                raise CannotCarry(f"{exc} (from its generation {frame.generation} on)") from None
        self.encoders[frame.camera].offer(frame.image, t_stamp, frame.frame_id, frame.generation)
        self._generations[frame.camera] = frame.generation
        if before is None or before == frame.generation:
            return None
        height, width = frame.image.shape[:2]
        return (
            f"{frame.camera}: generation {frame.generation}, {width}x{height}: the same track "
            f"{rosmsgs.video_topic(frame.camera)} goes on with a keyframe at the new size"
        )

    def newly_behind(self) -> list[str]:
        """Cameras whose encoder began skipping frames since the last call."""
        now = {cam for cam, e in self.encoders.items() if e.skipped}
        fresh, self.behind = sorted(now - self.behind), now
        return fresh

    def write_ready(self, bag, to_realtime: int) -> None:
        for cam, encoder in self.encoders.items():
            write_packets(bag, cam, self.plan.choice.codec, encoder.ready(), to_realtime)
            if encoder.error is not None:
                raise FxisError(f"{cam}: the {self.plan.choice.encoder} encoder failed: {encoder.error}")

    def finish(self, bag, to_realtime: int) -> None:
        """Flush every encoder and write what it still held."""
        for cam, encoder in self.encoders.items():
            write_packets(bag, cam, self.plan.choice.codec, encoder.finish(), to_realtime)


def write_packets(bag, cam: str, codec: str, packets, to_realtime: int) -> None:
    """A camera's encoded frames into the bag: /NAME/video and /NAME/video/frames, message for
    message, logged at the capture time moved to the wall clock (``to_realtime``)."""
    for packet in packets:
        video, info = rosmsgs.video_messages(packet, cam, codec)
        log_time = packet.t_ns + to_realtime
        bag.write(rosmsgs.video_topic(cam), rosmsgs.VIDEO, video, log_time, len(packet.data))
        bag.write(rosmsgs.video_frames_topic(cam), rosmsgs.VIDEO_FRAME, info, log_time)
