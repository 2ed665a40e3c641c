"""Cameras and videos that OpenCV opens (``cv2.VideoCapture``).

``source`` is a device index (``0`` for /dev/video0), a video file or a URL
(rtsp://, http://, ...).

- A file plays at its own frame rate (``rate=file``, the default), at another
  rate (``rate=30``) or as fast as it decodes (``rate=max``). Frame k of the
  playback is due at ``start + k/rate`` on CLOCK_MONOTONIC, where start is the
  first grab; that scheduled time is its t_capture, so stamps are spaced by
  exactly one period whatever the decoding jitter. Playback never skips frames:
  when decoding falls more than a period behind, the schedule restarts from the
  late frame (t_capture is then when it was decoded). With ``rate=max``
  t_capture is the time the frame was decoded. At the end, ``loop=true`` starts
  the file again (frame ids go on counting); ``loop=false`` stops delivering
  frames (without spinning the CPU) and says so in ``note``.
- A device or URL is read by a thread as frames arrive; t_capture is the host
  arrival time (CLOCK_MONOTONIC when ``VideoCapture.grab`` returned). A source
  that stops delivering raises CameraLost, and the worker reopens it.

Frames come as BGR (``pixel_format=bgr8``) or converted to grey (``mono8``).
"""

from __future__ import annotations

import fcntl
import glob
import logging
import math
import os
import queue
import re
import struct
import threading
import time

import cv2
import numpy as np

from fxis_shm.core import timebase
from fxis_shm.core.tuning import READ_ONLY, RESTART, describe
from fxis_shm.shm.ring import FrameLayout

from .base import Camera, CameraLost, Capture

log = logging.getLogger("camera")

_LIVE_FAILURES = 25  # consecutive failed reads (about 1 s at >= 25 ms each) before a source is lost
_LIVE_RETRY_S = 0.04
_OPEN_TIMEOUT_MS = 5000


def source_kind(source: str) -> str:
    """``device``, ``url`` or ``file``."""
    if source.isdigit():
        return "device"
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*://", source):
        return "url"
    return "file"


class OpenCVCamera(Camera):
    kind = "opencv"

    def __init__(self, name, options, time_origin_ns):
        super().__init__(name, options, time_origin_ns)
        self.note = ""
        source = self.options["source"]
        if source is None or not str(source).strip():
            raise ValueError(f"camera {name!r}: key 'source' is required: a device index (0), a video file or a URL")
        self._source = str(source).strip()
        self._kind = source_kind(self._source)
        if self._kind != "device":
            for key in ("width", "height", "fps"):
                if self.options[key] is not None:
                    hint = "use rate= for a file" if key == "fps" else f"a {self._kind} has its own size"
                    raise ValueError(f"camera {name!r}: key {key!r} applies to devices only; {hint}")
        if self._kind != "file":
            for key, default in (("rate", "file"), ("loop", False)):
                if self.options[key] != default:
                    raise ValueError(
                        f"camera {name!r}: key {key!r} applies to video files only, "
                        f"not to the {self._kind} {self._source!r}"
                    )
        self._cap: cv2.VideoCapture | None = None
        self._reader: _LiveReader | None = None
        self._layout: FrameLayout | None = None
        self._period_ns = 0
        self._k = 0  # the next frame id; continues across loops and reopenings
        self._pending: np.ndarray | None = None  # a frame read ahead by open()
        self._start_ns: int | None = None  # playback schedule: frame k at start + (k - k0) * period
        self._k0 = 0
        self._ended = False
        self._played = 0  # frames of the file read since the last loop

    def _refuse(self, key: str, why: str) -> ValueError:
        return ValueError(f"camera {self.name!r}: key {key!r}: {why}")

    # -- the Camera interface ------------------------------------------------------------

    def open(self) -> None:
        if self._kind == "file":
            self._open_file()
        else:
            self._open_live()

    def _open_file(self) -> None:
        path = self._source
        if not os.path.isfile(path):
            raise self._refuse(
                "source", f"no file {path!r} (source takes a device index, an existing video file or a URL)"
            )
        cap = cv2.VideoCapture(path)
        if not cap.isOpened():
            cap.release()
            raise self._refuse("source", f"OpenCV cannot read {path!r} as a video")
        ok, frame = cap.read()
        if not ok or frame is None:
            cap.release()
            raise self._refuse("source", f"OpenCV opens {path!r} but decodes no frame from it")
        wanted = self.options["rate"]
        if wanted == "file":
            fps = cap.get(cv2.CAP_PROP_FPS)
            if not (math.isfinite(fps) and fps > 0):
                cap.release()
                raise self._refuse(
                    "rate", f"{path!r} does not say its frame rate; set rate=<frames per second> or rate=max"
                )
            self._period_ns = round(1e9 / fps)
        elif wanted == "max":
            self._period_ns = 0
        else:
            self._period_ns = round(1e9 / wanted)
        self._cap = cap
        self._pending = self._convert(frame)
        self._layout = FrameLayout.of(self._pending)
        self._played, self._ended, self._start_ns = 1, False, None
        self.note = ""

    def _open_live(self) -> None:
        source = int(self._source) if self._kind == "device" else self._source
        params = []
        for prop, value in (
            ("CAP_PROP_OPEN_TIMEOUT_MSEC", _OPEN_TIMEOUT_MS),
            ("CAP_PROP_READ_TIMEOUT_MSEC", _OPEN_TIMEOUT_MS),
        ):
            if self._kind == "url" and hasattr(cv2, prop):
                params += [getattr(cv2, prop), value]
        cap = cv2.VideoCapture(source, cv2.CAP_ANY, params) if params else cv2.VideoCapture(source)
        if not cap.isOpened():
            cap.release()
            where = f"/dev/video{source}" if self._kind == "device" else repr(source)
            raise self._refuse("source", f"OpenCV cannot open {where}")
        try:
            self._apply_device_settings(cap)
        except BaseException:
            cap.release()
            raise
        fps = cap.get(cv2.CAP_PROP_FPS)
        self._period_ns = round(1e9 / fps) if math.isfinite(fps) and 0 < fps < 10_000 else 0
        self._cap = cap
        self._layout = None  # the first frame tells
        self._reader = _LiveReader(cap, self)
        self._reader.start()

    def _apply_device_settings(self, cap) -> None:
        """Ask for width, height and fps; refuse if the device delivers something else."""
        o = self.options
        props = {"width": cv2.CAP_PROP_FRAME_WIDTH, "height": cv2.CAP_PROP_FRAME_HEIGHT, "fps": cv2.CAP_PROP_FPS}
        for key in ("width", "height", "fps"):
            if o[key] is not None:
                cap.set(props[key], o[key])
        for key in ("width", "height", "fps"):
            if o[key] is None:
                continue
            got = cap.get(props[key])
            if not math.isclose(got, o[key], rel_tol=0.01, abs_tol=0.5):
                w, h = cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)
                raise self._refuse(
                    key,
                    f"the device does not accept {o[key]:g}; it gives {got:g} "
                    f"(now {w:g}x{h:g} at {cap.get(cv2.CAP_PROP_FPS):g} fps)",
                )

    # -- settings at run time ------------------------------------------------------------

    def settings(self, extra=()) -> dict[str, dict]:
        """A file: loop (live), rate and pixel_format (restart); it plays as recorded, so
        exposure, gain and size are read-only. A device or URL: its options by a restart of the
        stream (its reader thread owns the capture, so nothing is set under it)."""
        o = self.options
        out = {"pixel_format": describe(o["pixel_format"], "enum", RESTART, choices=["bgr8", "mono8"])}
        if self._kind == "file":
            out["loop"] = describe(o["loop"], "bool")
            out["rate"] = describe(o["rate"], "string", RESTART)
            for key in ("exposure_us", "gain", "width", "height", "fps"):
                out[key] = describe(None, "float", access=READ_ONLY)
                out[key]["note"] = "a video file plays as it was recorded" + ("; use rate" if key == "fps" else "")
        elif self._kind == "device":
            for key in ("width", "height"):
                out[key] = describe(o[key], "int", RESTART, lo=1, hi=65535)
            out["fps"] = describe(o["fps"], "float", RESTART, lo=0.01, hi=10_000.0)
        return out

    def set_live(self, values) -> None:
        self.options.update(values)  # loop: read when the file ends

    def grab(self, timeout: float) -> Capture | None:
        if self._reader is not None:
            return self._grab_live(timeout)
        if self._cap is None:
            raise CameraLost(f"camera {self.name!r} is not open")
        if self._pending is None and not self._ended:
            self._pending = self._read_next()  # decode while the frame is not due yet
        if self._pending is None:
            if self._ended:
                time.sleep(timeout)  # nothing more will come: wait without spinning
            return None
        now = timebase.now()
        if not self._period_ns:  # rate=max: stamped when decoded
            due = now
        else:
            if self._start_ns is None:
                self._start_ns, self._k0 = now, self._k
            due = self._start_ns + (self._k - self._k0) * self._period_ns
            if due - now > timeout * 1e9:
                time.sleep(timeout)
                return None
            if due > now:
                time.sleep((due - now) / 1e9)
            elif now - due > self._period_ns:  # decoding fell behind: restart the schedule here
                self._start_ns, self._k0, due = now, self._k, now
        image, self._pending = self._pending, None
        k, self._k = self._k, self._k + 1
        return Capture(image, k, due)

    def _read_next(self) -> np.ndarray | None:
        ok, frame = self._cap.read()
        if not ok and self.options["loop"] and self._played:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self._cap.read()
            if not ok:  # some containers do not seek: open the file again
                self._cap.release()
                self._cap = cv2.VideoCapture(self._source)
                ok, frame = self._cap.read()
            self._played = 0
        if not ok or frame is None:
            self._ended = True
            self.note = (
                f"end of file {os.path.basename(self._source)!r} after {self._played} frames "
                f"(loop=false): no more frames"
            )
            log.info("camera %s: %s", self.name, self.note)
            return None
        self._played += 1
        image = self._convert(frame)
        if FrameLayout.of(image) != self._layout:
            self.frames_dropped += 1
            log.warning(
                "camera %s: a %s frame in a file of %s frames; dropped", self.name, FrameLayout.of(image), self._layout
            )
            return None
        return image

    def _grab_live(self, timeout: float) -> Capture | None:
        reader = self._reader
        try:
            image, t_capture = reader.frames.get(timeout=timeout)
        except queue.Empty:
            if reader.lost:
                raise CameraLost(reader.lost) from None
            return None
        if self._layout is None:
            self._layout = FrameLayout.of(image)
        elif FrameLayout.of(image) != self._layout:
            self.frames_dropped += 1
            log.warning("camera %s: the source changed to %s frames; dropped", self.name, FrameLayout.of(image))
            return None
        k, self._k = self._k, self._k + 1
        return Capture(image, k, t_capture)

    def _convert(self, frame: np.ndarray) -> np.ndarray:
        """BGR or grey as configured, whatever the source delivers."""
        mono = self.options["pixel_format"] == "mono8"
        if frame.dtype != np.uint8:
            frame = (
                cv2.convertScaleAbs(frame, alpha=255.0 / np.iinfo(frame.dtype).max)
                if frame.dtype.kind == "u"
                else frame.astype(np.uint8)
            )
        if frame.ndim == 2 or frame.shape[2] == 1:
            return (
                np.ascontiguousarray(frame.reshape(frame.shape[:2]))
                if mono
                else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
            )
        if frame.shape[2] == 4:
            return cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY if mono else cv2.COLOR_BGRA2BGR)
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if mono else frame

    def close(self) -> None:
        reader, cap = self._reader, self._cap
        self._reader = self._cap = None
        if reader is not None and not reader.stop():
            log.warning("camera %s: its reader is still blocked in OpenCV; leaving the capture open", self.name)
            return
        if cap is not None:
            cap.release()

    @classmethod
    def discover(cls) -> list[dict]:
        """V4L2 capture devices (/dev/videoN), read without disturbing a running stream;
        files and URLs are not discoverable."""
        found = []
        for path in sorted(glob.glob("/dev/video*"), key=lambda p: (len(p), p)):
            index = path[len("/dev/video") :]
            if not index.isdigit():
                continue
            info = _v4l2_info(path)
            if info is not None:
                found.append({"id": int(index), "model": info[0], "format": info[1], "path": path})
        return found


class _LiveReader:
    """Reads a device or stream in a thread, so that ``grab`` honours its timeout."""

    def __init__(self, cap, camera: OpenCVCamera):
        self.cap, self.camera = cap, camera
        self.frames: queue.Queue[tuple[np.ndarray, int]] = queue.Queue(maxsize=2)
        self.lost = ""  # why the source stopped, once it has
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"opencv-{camera.name}")

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> bool:
        """True once the thread has ended (it may be blocked in a read)."""
        self._stop.set()
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        failures = 0
        while not self._stop.is_set():
            ok = self.cap.grab()
            t_arrival = timebase.now()
            if ok:
                ok, frame = self.cap.retrieve()
            if not ok or frame is None:
                failures += 1
                if failures >= _LIVE_FAILURES:
                    self.lost = f"{self.camera._source!r} delivered no frame in {failures} reads"
                    return
                self._stop.wait(_LIVE_RETRY_S)
                continue
            failures = 0
            image = self.camera._convert(frame)
            try:
                self.frames.put_nowait((image, t_arrival))
            except queue.Full:  # the worker is behind: the oldest frame is lost
                try:
                    self.frames.get_nowait()
                    self.camera.frames_dropped += 1
                except queue.Empty:
                    pass
                self.frames.put_nowait((image, t_arrival))


# V4L2 ioctls (linux/videodev2.h), 64-bit layout
_VIDIOC_QUERYCAP = 0x80685600  # struct v4l2_capability, 104 bytes
_VIDIOC_G_FMT = 0xC0D05604  # struct v4l2_format, 208 bytes
_V4L2_CAP_VIDEO_CAPTURE = 0x1
_V4L2_CAP_DEVICE_CAPS = 0x80000000
_V4L2_BUF_TYPE_VIDEO_CAPTURE = 1


def capture_card(caps: bytes) -> str | None:
    """The card name of a ``struct v4l2_capability``, None unless the node captures video
    (the node's own capabilities where the driver gives them)."""
    capabilities, device_caps = struct.unpack_from("<II", caps, 84)
    if capabilities & _V4L2_CAP_DEVICE_CAPS:
        capabilities = device_caps
    if not capabilities & _V4L2_CAP_VIDEO_CAPTURE:
        return None
    return bytes(caps[16:48]).split(b"\0")[0].decode(errors="replace")


def format_of(fmt: bytes) -> str:
    """ "FOURCC WxH" of a ``struct v4l2_format`` of a capture buffer type."""
    width, height, fourcc = struct.unpack_from("<III", fmt, 8)
    return f"{fourcc.to_bytes(4, 'little').decode(errors='replace')} {width}x{height}"


def _v4l2_info(path: str) -> tuple[str, str] | None:
    """(card name, current format) of a V4L2 video capture node, None if it is not one.
    QUERYCAP and G_FMT only read: they do not disturb a stream another process runs."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        caps = bytearray(104)
        fcntl.ioctl(fd, _VIDIOC_QUERYCAP, caps)
        card = capture_card(caps)
        if card is None:
            return None  # a metadata or output node
        fmt = bytearray(208)
        struct.pack_into("<I", fmt, 0, _V4L2_BUF_TYPE_VIDEO_CAPTURE)
        try:
            fcntl.ioctl(fd, _VIDIOC_G_FMT, fmt)
            form = format_of(fmt)
        except OSError:
            form = "?"
        return card, form
    except OSError:
        return None
    finally:
        os.close(fd)
