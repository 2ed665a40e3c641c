"""One camera's video encoder: a PyAV (FFmpeg) encoder of its stream (``StreamEncoder``, which
a snapshot runs in its writer's thread) and, for ``fxis record --codec``, the same in a thread
of its own (``CameraEncoder``), fed frames copied out of the ring, so a slow encoder never holds
up the recorder's reading of the rings or the other cameras. A full queue means the encoder
fell behind: the frame is skipped and counted, never waited for.

The stream is what Foxglove plays: one frame per packet, in capture order, no B-frames, Annex B
with the parameter sets (SPS/PPS) repeated on every keyframe, and a keyframe forced on the first
frame and then at least every ``gop_s`` seconds of capture time. Each packet keeps its frame's
capture time (variable frame rate: the encoder's pts are microseconds of capture time).
"""

from __future__ import annotations

import os
import queue
import threading
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.threadsched import normal_scheduling_kept
from fxis_shm.formats.videochoice import Choice, check_camera

QUEUE_FRAMES = 16  # frames waiting for an encoder; more and the camera's frames are skipped
_PTS_NS = 1000  # pts in microseconds of capture time
_INPUT_FORMATS = {1: "gray", 3: "bgr24", 4: "bgra"}  # the channels of the carried 8-bit layouts
_JOIN_S = 30.0  # finishing waits this long for an encoder to flush


def require_av():
    try:
        import av
    except ImportError as exc:
        raise ConfigError(
            f"--codec needs the optional extra 'video' (PyAV; {exc}): pip install 'fxis-shm[video]' (or `make setup`)"
        ) from None
    return av


@dataclass
class Packet:
    """One encoded frame: its capture time, the frame it is, its bytes."""

    t_ns: int
    frame_id: int
    generation: int
    data: bytes
    keyframe: bool


def encoder_options(choice: Choice, crf: int, preset: str | None, gop_frames: int) -> dict[str, str]:
    """FFmpeg options for one frame out per frame in, no B-frames, parameter sets on keyframes."""
    name = choice.encoder
    if name == "libx264":
        params = "bframes=0:repeat-headers=1:annexb=1:scenecut=0:rc-lookahead=0:sync-lookahead=0"
        options = {"crf": str(crf), "x264-params": params, "forced-idr": "1"}
    elif name == "libx265":
        params = f"bframes=0:repeat-headers=1:annexb=1:scenecut=0:rc-lookahead=0:keyint={gop_frames}:log-level=error"
        options = {"crf": str(crf), "x265-params": params, "forced-idr": "1"}
    elif name == "libsvtav1":
        # low delay (pred-struct 1): frames out in order, none held back for later ones
        options = {"crf": str(crf), "svtav1-params": f"pred-struct=1:keyint={gop_frames}:scd=0"}
    elif name.endswith("_nvenc"):
        options = {"cq": str(crf), "bf": "0", "forced-idr": "1", "zerolatency": "1"}
    elif name.endswith("_qsv"):
        options = {"global_quality": str(crf), "bf": "0", "forced_idr": "1"}
    else:  # VAAPI
        options = {"qp": str(crf), "bf": "0"}
    if preset is not None:
        options["preset"] = preset
    return options


def open_context(av, choice: Choice, width: int, height: int, fps: float, options: dict[str, str]):
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1 prints its whole configuration otherwise; errors only
    context = av.CodecContext.create(choice.encoder, "w")
    context.width, context.height = width, height
    context.pix_fmt = "yuv420p"
    context.time_base = Fraction(1, 1_000_000_000 // _PTS_NS)
    context.framerate = Fraction(fps or 30).limit_denominator(1001)
    context.gop_size = 1 << 20  # keyframes are forced by capture time (CameraEncoder._keyframe_due)
    context.max_b_frames = 0
    context.options = options
    with normal_scheduling_kept():  # SVT-AV1 as root leaves the opener and its threads at FIFO 99
        context.open()
    return context


def opens(encoder: Choice) -> bool:
    """Whether ``encoder`` opens and encodes a frame here (a hardware encoder FFmpeg lists may
    have no device behind it)."""
    av = require_av()
    try:
        context = open_context(av, encoder, 64, 64, 30.0, encoder_options(encoder, 30, None, 30))
        frame = av.VideoFrame.from_ndarray(np.zeros((64, 64), np.uint8), format="gray").reformat(format="yuv420p")
        frame.pts = 0
        context.encode(frame)
        context.encode(None)
        return True
    except Exception:  # noqa: BLE001 (any failure to open means: not this one)
        return False


class StreamEncoder:
    """One camera's stream, encoded in the caller's thread: ``encode(image, t_ns, frame_id,
    generation)`` returns the packets ready so far, ``finish()`` flushes the last ones.

    A new generation (the camera restarted, maybe at a new size or pixel format: docs/design.md,
    "Commands to a camera worker") closes the encoder, flushing its frames, and opens a new one
    for the new layout, whose first frame is a keyframe with its parameter sets: the stream stays
    one track, and a player (which sizes its picture from each keyframe's SPS) goes on across the
    boundary."""

    def __init__(self, camera: str, choice: Choice, crf: int, preset: str | None, gop_s: float, fps: float):
        self.camera, self.choice = camera, choice
        self.gop_ns = int(gop_s * 1e9)
        self._av = require_av()
        self._options = encoder_options(choice, crf, preset, max(1, round(gop_s * (fps or 30))))
        self._fps = fps
        self._context = None
        self._generation: int | None = None  # of the frames the open encoder takes
        self._size: tuple[int, int] | None = None  # (height, width), likewise
        self._pending: dict[int, tuple[int, int, int]] = {}  # pts -> (t_ns, frame id, generation)
        self._t0: int | None = None
        self._last_key: int | None = None

    def encode(self, image: np.ndarray, t_ns: int, frame_id: int, generation: int) -> list[Packet]:
        av = self._av
        packets = []
        if self._context is not None and (generation != self._generation or image.shape[:2] != self._size):
            packets = self.finish()  # the old layout's last frames, before the new one starts
        if self._context is None:
            check_image(self.choice.codec, self.camera, image)
            height, width = image.shape[:2]
            self._context = open_context(av, self.choice, width, height, self._fps, self._options)
            self._size, self._generation, self._last_key = (height, width), generation, None
            self._t0 = t_ns if self._t0 is None else self._t0
        channels = 1 if image.ndim == 2 else image.shape[2]
        frame = av.VideoFrame.from_ndarray(image, format=_INPUT_FORMATS[channels]).reformat(format="yuv420p")
        frame.pts = (t_ns - self._t0) // _PTS_NS
        if self._last_key is None or t_ns - self._last_key >= self.gop_ns:
            frame.pict_type = av.video.frame.PictureType.I
            self._last_key = t_ns
        self._pending[frame.pts] = (t_ns, frame_id, generation)
        return packets + self._packets(self._context.encode(frame))

    def finish(self) -> list[Packet]:
        """Flush and close the encoder (the next frame opens a new one): its last packets."""
        if self._context is None:
            return []
        context, self._context = self._context, None
        return self._packets(context.encode(None))

    def _packets(self, encoded) -> list[Packet]:
        packets = []
        for packet in encoded:
            t_ns, frame_id, generation = self._pending.pop(packet.pts)
            packets.append(Packet(t_ns, frame_id, generation, bytes(packet), bool(packet.is_keyframe)))
        return packets


def check_image(codec: str, camera: str, image: np.ndarray) -> None:
    """ConfigError if ``image`` (the first of a camera's generation) is not what 8-bit 4:2:0
    video carries: a camera restarted at an odd size or in a 16-bit format, say."""
    height, width = image.shape[:2]
    check_camera(codec, camera, encoding_of(list(image.shape), image.dtype.name), width, height)


def encoding_of(shape: list[int], dtype: str | None) -> str:
    """The ROS encoding name of frames of this shape and dtype (as a camera's status gives them)."""
    channels = shape[2] if len(shape) == 3 else 1
    try:
        return rosmsgs.ros_encoding(np.empty((1, 1, channels), np.dtype(dtype or "uint8")))
    except InvalidArgument:
        return f"{channels}-channel {dtype}"


class CameraEncoder:
    """A StreamEncoder in a thread of its own: ``offer(image, t_ns, frame_id, generation)``
    from the recorder's thread; ``ready()`` the packets encoded since; ``finish()`` flushes and
    returns the last ones."""

    def __init__(self, stream: StreamEncoder):
        self.camera, self.choice = stream.camera, stream.choice
        self._stream = stream
        self._inbox: queue.Queue = queue.Queue(maxsize=QUEUE_FRAMES)
        self._outbox: queue.SimpleQueue[Packet] = queue.SimpleQueue()
        self.offered = self.skipped = 0
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=f"encode-{self.camera}", daemon=True)
        self._thread.start()

    def offer(self, image: np.ndarray, t_ns: int, frame_id: int, generation: int) -> bool:
        """Queue a copy of the frame; False (and counted) if the encoder is behind."""
        self.offered += 1
        try:
            self._inbox.put_nowait((np.array(image, copy=True), t_ns, frame_id, generation))
            return True
        except queue.Full:
            self.skipped += 1
            return False

    def ready(self) -> list[Packet]:
        packets = []
        while True:
            try:
                packets.append(self._outbox.get_nowait())
            except queue.Empty:
                return packets

    def finish(self) -> list[Packet]:
        """Encode what is queued, flush the encoder, stop its thread; the packets not taken yet."""
        if self._thread.is_alive():  # (a thread that failed empties its queue no more)
            try:
                self._inbox.put((None, 0, 0, 0), timeout=_JOIN_S)
            except queue.Full:
                pass
            self._thread.join(_JOIN_S)
        return self.ready()

    def _run(self) -> None:
        try:
            while True:
                image, t_ns, frame_id, generation = self._inbox.get()
                if image is None:
                    break
                self._deliver(self._stream.encode(image, t_ns, frame_id, generation))
            self._deliver(self._stream.finish())
        except BaseException as exc:  # noqa: BLE001 (kept for the recorder to report)
            self.error = exc

    def _deliver(self, packets: list[Packet]) -> None:
        for packet in packets:
            self._outbox.put(packet)
