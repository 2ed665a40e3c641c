"""Frames, video packets and tuples' sync as a Rerun recording (rerun-sdk, the optional extra
``rerun``), logged one way for ``fxis export BAG --rerun`` (fxis_shm.record.rerunexport) and
``fxis view --rerun`` (fxis_shm.viewers.rerunview); docs/rerun.md.

Entities: ``cameras/NAME``, one per camera: ``Image`` (raw pixels), ``EncodedImage`` (JPEG, its
bytes as they are) or ``VideoStream`` (H.264, H.265, AV1: each frame's packet as it is, never
re-encoded); ``sync/skew_ms`` and ``sync/synced`` (``Scalars``), one row per joint tuple: its skew
(max - min capture time) and 1 when it is complete and within the threshold, else 0 (the
``synced`` of fxis sync-report, fxis_shm.core.syncstats).

Timelines: ``capture_time``, each frame's capture time in the clock its times are in (a
timestamp for a wall clock, CLOCK_REALTIME or CLOCK_TAI; else a duration since that clock's zero,
e.g. since boot for CLOCK_MONOTONIC), to the nanosecond; ``frame_id`` (a sequence), the camera's
frame counter, where the source says it.

The rerun package is imported only here and only when asked for: the base install needs none.
"""

from __future__ import annotations

import numpy as np

from fxis_shm.errors import ConfigError, FxisError

APPLICATION_ID = "fxis"
CAPTURE_TIME, FRAME_ID = "capture_time", "frame_id"
SKEW, SYNCED = "sync/skew_ms", "sync/synced"
VIDEO_CODECS = {"h264": "H264", "h265": "H265", "av1": "AV1"}  # a CompressedVideo's format -> rr.VideoCodec
# The Rerun color model of each channel count of the rings' layouts (bgr8, bgra8; mono8, mono16, 32FC1)
COLOR_MODELS = {1: "L", 3: "BGR", 4: "BGRA"}
WALL_CLOCKS = ("realtime", "tai")
FLUSH_TIMEOUT_S = 10.0  # a viewer that has not taken the data by then is not there


def require_rerun(flag: str):
    """The rerun module, or ConfigError in one line saying how to install it."""
    try:
        import rerun
    except ImportError as exc:
        raise ConfigError(
            f"{flag} needs the optional extra 'rerun' (rerun-sdk; {exc}): pip install 'fxis-shm[rerun]' "
            "(or `make setup`)"
        ) from None
    return rerun


def camera_entity(camera: str) -> str:
    return f"cameras/{camera}"


def is_wall_clock(clock: str | None) -> bool:
    """Whether times of ``clock`` (a name as fxis writes it: "CLOCK_REALTIME", "monotonic", ...) are
    moments of the calendar, shown as dates, rather than a count from an arbitrary zero."""
    return any(wall in (clock or "").lower() for wall in WALL_CLOCKS)


class RerunLog:
    """One Rerun recording being written (to a file, a viewer it starts, or a running viewer)."""

    def __init__(self, flag: str, clock: str | None, name: str):
        self.rr = require_rerun(flag)
        self.recording = self.rr.RecordingStream(APPLICATION_ID)
        self.recording.send_recording_name(name)
        self.wall_clock = is_wall_clock(clock)
        self._video_codecs: set[str] = set()

    def save(self, path: str) -> RerunLog:
        self.recording.save(path)
        return self

    def connect(self, url: str) -> RerunLog:
        self.recording.connect_grpc(url)
        return self

    def spawn(self) -> RerunLog:
        self.recording.spawn()
        return self

    def at(self, t_ns: int, frame_id: int | None = None) -> None:
        """What is logged next is at capture time ``t_ns`` (and at ``frame_id``, None: on no frame id)."""
        recording = self.recording
        recording.reset_time()  # the frame id of what was logged before does not carry over
        if self.wall_clock:
            recording.set_time(CAPTURE_TIME, timestamp=np.datetime64(int(t_ns), "ns"))
        else:
            recording.set_time(CAPTURE_TIME, duration=np.timedelta64(int(t_ns), "ns"))
        if frame_id is not None:
            recording.set_time(FRAME_ID, sequence=int(frame_id))

    def image(self, camera: str, image: np.ndarray, t_ns: int, frame_id: int | None = None) -> None:
        """Raw pixels, (h, w) or (h, w, c) in the rings' channel order (BGR, BGRA)."""
        self.at(t_ns, frame_id)
        channels = 1 if image.ndim == 2 else image.shape[2]
        self.recording.log(camera_entity(camera), self.rr.Image(image, color_model=COLOR_MODELS[channels]))

    def jpeg(self, camera: str, data: bytes, t_ns: int, frame_id: int | None = None) -> None:
        self.at(t_ns, frame_id)
        self.recording.log(camera_entity(camera), self.rr.EncodedImage(contents=data, media_type="image/jpeg"))

    def video(
        self, camera: str, codec: str, data: bytes, keyframe: bool | None, t_ns: int, frame_id: int | None = None
    ) -> None:
        """One encoded frame of ``codec`` ("h264", "h265", "av1"; Annex B / low-overhead OBUs, as
        fxis records them), its bytes as they are."""
        entity = camera_entity(camera)
        if camera not in self._video_codecs:  # the codec: once, static, as Rerun asks
            if codec not in VIDEO_CODECS:
                raise ConfigError(f"{camera}: video format {codec!r}; Rerun takes {', '.join(VIDEO_CODECS)}")
            self.recording.log(entity, self.rr.VideoStream(codec=self.rr.VideoCodec[VIDEO_CODECS[codec]]), static=True)
            self._video_codecs.add(camera)
        self.at(t_ns, frame_id)
        self.recording.log(entity, self.rr.VideoStream.from_fields(sample=data, is_keyframe=keyframe))

    def sync(self, t_ns: int, capture_ns: list[int], complete: bool, threshold_ms: float) -> bool:
        """A joint tuple asked for at ``t_ns``: its skew over ``capture_ns`` and whether it is
        synced (complete and within ``threshold_ms``), which is returned."""
        skew_ms = (max(capture_ns) - min(capture_ns)) / 1e6 if capture_ns else float("nan")
        synced = complete and skew_ms <= threshold_ms
        self.at(t_ns)
        self.recording.log(SKEW, self.rr.Scalars(skew_ms))
        self.recording.log(SYNCED, self.rr.Scalars(1.0 if synced else 0.0))
        return synced

    def close(self) -> None:
        """Everything logged is written (a file gets its footer) and the sink let go; FxisError
        when a viewer did not take it within FLUSH_TIMEOUT_S (none at the URL, or it closed)."""
        try:
            self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as exc:  # what rerun-sdk raises for a sink it cannot reach
            raise FxisError(f"Rerun did not take what was logged: {' '.join(str(exc).split())}") from None
        finally:
            self.recording.disconnect()
