"""The camera kinds the service knows: for each, its option schema, a one-line
description, and the worker-side class that implements it, named by a string.

The library reads only this table (config checks options against it, the CLI
lists it); the camera worker imports the class it names. Adding a kind is one
entry in KINDS plus a backend module under workers/backends/.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fxis_shm.core.schedule import CAPTURE_TOLERANCE_MS
from fxis_shm.errors import ConfigError
from fxis_shm.formats.calibration import read_calibration
from fxis_shm.service.options import Option, boolean, choice, number, parse_options, text

BACKENDS_PACKAGE = "fxis_shm.workers.backends"
DISCOVERY_MODULE = "fxis_shm.workers.discover"  # `fxis cameras` runs it as a child process


@dataclass(frozen=True)
class CameraKind:
    name: str
    description: str
    options: Mapping[str, Option]
    backend: str  # "module:Class" under BACKENDS_PACKAGE, imported by the camera worker only

    @property
    def backend_path(self) -> tuple[str, str]:
        """(module, class) of the implementation."""
        module, _, cls = self.backend.partition(":")
        return f"{BACKENDS_PACKAGE}.{module}", cls


# ---- options every kind takes: the processing hook (workers/processing.py), and how
# ROS 2 messages and recordings name the camera and describe its optics ----


def hook_path(value: Any) -> str:
    module, sep, function = str(value).partition(":")
    if not sep or not module or not function.isidentifier():
        raise ValueError(f"expected package.module:function, got {value!r}")
    return str(value)


def calibration_file(value: Any) -> str:
    read_calibration(str(value))  # refused at start-up, not when the first frame is published
    return str(value)


def frame_id(value: Any) -> str:
    name = text(value)
    if not name or any(c.isspace() for c in name):
        raise ValueError(f"expected a frame name without spaces, got {value!r}")
    return name


COMMON_OPTIONS = {
    "process": Option(hook_path, None, "package.module:function run on every frame before it is stored"),
    "process_workers": Option(number(int, 1, 64), 1, "processes that run the hook side by side"),
    "history": Option(
        number(float, 0, 86_400, exclusive_min=True), None, "seconds of frames its ring holds (default: slots)"
    ),
    "frame_id": Option(frame_id, None, "header.frame_id of the camera's ROS 2 messages (default: its name)"),
    "calibration": Option(
        calibration_file, None, "camera_info_manager YAML file for its ROS 2 camera_info (default: size only)"
    ),
    "capture_tolerance_ms": Option(
        number(float, 0, 10_000),
        CAPTURE_TOLERANCE_MS,
        "a frame captured at T that lands further than this from T is marked late (docs/sync.md)",
    ),
}


# ---- synthetic ----

SYNTHETIC_EXPOSURE_US = 10_000.0  # the exposure at which the pattern shows as drawn (brightness x 1)
DRIVER_BUFFERS = 12  # frames a camera's driver holds for a late worker (the Aravis backend queues as many)

SYNTHETIC = CameraKind(
    "synthetic",
    "the embedded test camera: a moving, stamped pattern at a set rate",
    {
        "fps": Option(number(float, 0, 10_000, exclusive_min=True), 20.0, "frames per second"),
        "width": Option(number(int, 16, 16384), 1360, "image width in pixels"),
        "height": Option(number(int, 1, 16384), 1024, "image height in pixels"),
        "pixel_format": Option(choice("mono8", "bgr8"), "mono8", "mono8 or bgr8"),
        "exposure_us": Option(
            number(float, 1, 1_000_000),
            SYNTHETIC_EXPOSURE_US,
            "exposure time, microseconds: the picture's brightness scales with it (the default leaves it as drawn)",
        ),
        "gain": Option(number(float, 0, 24), 0.0, "gain in dB: brightness x 10^(gain/20)"),
        "phase_ms": Option(number(float), 0.0, "offset of this camera's frame times, ms"),
        "jitter_ms": Option(number(float, 0), 0.0, "uniform timing noise of the capture time, +/- ms"),
        "drop": Option(number(float, 0, 1), 0.0, "probability that a frame is lost"),
        "buffers": Option(
            number(int, 1, 10_000),
            DRIVER_BUFFERS,
            "frames held for a worker that falls behind, as a driver's buffer pool: "
            "a worker later than that loses the oldest (1: only the newest frame is kept)",
        ),
        "seed": Option(number(int, 0), 0, "seed of the jitter and drop noise (0: random)"),
        "pattern": Option(
            choice("stripes", "chessboard"),
            "stripes",
            "stripes (moving, every frame differs) or chessboard (9x6 inner corners, for cv2.findChessboardCorners)",
        ),
        "shift_px": Option(
            number(int, -16384, 16384),
            0,
            "moves the picture left by this many pixels: the disparity of a stereo "
            "pair made of cameras with different shift_px",
        ),
        "trigger": Option(
            choice("free", "software"),
            "free",
            "free-running, or one frame per software trigger, captured at the trigger",
        ),
        "trigger_latency_ms": Option(
            number(float, 0, 1000),
            0.0,
            "with trigger=software: the time from a trigger to the exposure (t_capture), as a real camera's",
        ),
    },
    "synthetic:SyntheticCamera",
)


# ---- opencv ----


def rate(value: Any) -> str | float:
    """``file`` (the file's own rate), ``max`` (as fast as it decodes) or frames per second."""
    if isinstance(value, str) and value.strip().lower() in ("file", "max"):
        return value.strip().lower()
    try:
        fps = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"expected file, max or a number of frames per second, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"expected file, max or a number of frames per second > 0, got {value!r}")
    return fps


OPENCV = CameraKind(
    "opencv",
    "what cv2.VideoCapture opens: a device, a video file or a URL",
    {
        "source": Option(text, None, "a device index (0 = /dev/video0), a video file or a URL"),
        "rate": Option(
            rate, "file", "files: file (their own frame rate), max (as fast as they decode) or frames per second"
        ),
        "loop": Option(boolean, False, "files: start again at the end (false: stop delivering)"),
        "width": Option(number(int, 1, 65535), None, "devices: requested width (default: as set)"),
        "height": Option(number(int, 1, 65535), None, "devices: requested height (default: as set)"),
        "fps": Option(
            number(float, 0, 10_000, exclusive_min=True), None, "devices: requested frame rate (default: as set)"
        ),
        "pixel_format": Option(choice("bgr8", "mono8"), "bgr8", "bgr8 or mono8 (converted with cv2)"),
    },
    "opencv:OpenCVCamera",
)


# ---- aravis ----

# Options both GenICam kinds (aravis, genicam) take
_GENICAM_TRIGGER = Option(
    choice("free", "software"), "free", "free-running, or one frame per software trigger (TriggerSoftware)"
)
_GENICAM_TIMESTAMP = Option(
    choice("host", "device", "ptp"),
    "host",
    "host: the frame's arrival time; device: the camera's timestamp, fitted "
    "onto the host's clock; ptp: the camera's PTP time as it is (docs/cameras.md)",
)

# The GenICam formats the aravis backend stores (a subset of workers/backends/pixelformats.py).
ARAVIS_PIXEL_FORMATS = (
    "Mono8",
    "Mono10",
    "Mono12",
    "Mono16",
    "RGB8",
    "BGR8",
    "BayerRG8",
    "BayerGR8",
    "BayerGB8",
    "BayerBG8",
)

ARAVIS = CameraKind(
    "aravis",
    "GigE Vision and USB3 Vision cameras through the Aravis library",
    {
        "device": Option(text, None, "camera id as `fxis cameras` lists it (default: the first camera found)"),
        "fps": Option(
            number(float, 0, exclusive_min=True),
            None,
            "frames per second (AcquisitionFrameRate; default: as the camera is set)",
        ),
        "width": Option(number(int, 1, 65535), None, "image width in pixels (default: as set)"),
        "height": Option(number(int, 1, 65535), None, "image height in pixels (default: as set)"),
        "offset_x": Option(number(int, 0, 65535), None, "left edge of the region, pixels"),
        "offset_y": Option(number(int, 0, 65535), None, "top edge of the region, pixels"),
        "pixel_format": Option(
            choice(*ARAVIS_PIXEL_FORMATS),
            None,
            f"one of {', '.join(ARAVIS_PIXEL_FORMATS)} (default: as set); Bayer becomes BGR, "
            "RGB8 becomes BGR, unless raw=true",
        ),
        "raw": Option(boolean, False, "store Bayer mosaics and RGB8 as the camera sends them"),
        "exposure_us": Option(
            number(float, 0, exclusive_min=True), None, "exposure time, microseconds (turns auto off)"
        ),
        "gain": Option(number(float, 0), None, "gain, in the camera's unit (usually dB; turns auto off)"),
        "packet_size": Option(
            number(int, 64, 65535), None, "GigE Vision packet size in bytes (default: as negotiated)"
        ),
        "trigger": _GENICAM_TRIGGER,
        "timestamp": _GENICAM_TIMESTAMP,
    },
    "aravis:AravisCamera",
)


# ---- genicam ----

GENTL_PATH_VAR = "GENICAM_GENTL64_PATH"

GENICAM = CameraKind(
    "genicam",
    "any camera a GenTL producer (.cti) reaches, through harvesters",
    {
        "cti": Option(
            text, None, f"GenTL producer: a .cti file or a folder of them (default: the folders of ${GENTL_PATH_VAR})"
        ),
        "device": Option(
            text, None, "serial number, device id, user-defined name or index (default: the first device)"
        ),
        "fps": Option(
            number(float, 0, 100_000, exclusive_min=True), None, "AcquisitionFrameRate (default: as the device is set)"
        ),
        "width": Option(number(int, 1, 65535), None, "Width in pixels (default: as set)"),
        "height": Option(number(int, 1, 65535), None, "Height in pixels (default: as set)"),
        "offset_x": Option(number(int, 0, 65535), None, "OffsetX (default: as set; 0 when width is given)"),
        "offset_y": Option(number(int, 0, 65535), None, "OffsetY (default: as set; 0 when height is given)"),
        "pixel_format": Option(text, None, "PFNC name the device offers, e.g. Mono8, BayerRG8 (default: as set)"),
        "exposure_us": Option(
            number(float, 0, exclusive_min=True),
            None,
            "ExposureTime in microseconds, ExposureAuto off (default: as set)",
        ),
        "gain": Option(number(float), None, "Gain in the device's unit (dB per SFNC), GainAuto off (default: as set)"),
        "trigger": _GENICAM_TRIGGER,
        "timestamp": _GENICAM_TIMESTAMP,
        "raw": Option(boolean, False, "keep colour and Bayer data as delivered (no BGR conversion)"),
    },
    "genicam:GenicamCamera",
)


BAG = CameraKind(
    "bag",
    "a recorded topic (fxis record) played back into a ring at its recorded spacing",
    {
        "path": Option(text, None, "the bag: a rosbag2 folder (fxis record --out DIR) or its .mcap file"),
        "topic": Option(
            text, None, "the image topic to play, e.g. /left/image_raw (default: the bag's only image topic)"
        ),
        "loop": Option(boolean, True, "start again at the end (false: stop delivering, and say so)"),
        "speed": Option(
            number(float, 0, 1000, exclusive_min=True),
            1.0,
            "playback speed: 2 plays twice as fast (the spacing halves)",
        ),
        "stamps": Option(
            choice("now", "recorded"),
            "now",
            "now: each frame is stamped with its play time (at the recorded spacing); "
            "recorded: the recorded header.stamp",
        ),
    },
    "bag:BagCamera",
)


KINDS: dict[str, CameraKind] = {k.name: k for k in (SYNTHETIC, OPENCV, ARAVIS, GENICAM, BAG)}


def camera_kind(kind: str) -> CameraKind:
    try:
        return KINDS[kind]
    except KeyError:
        raise ConfigError(f"unknown camera kind {kind!r}; known kinds: {', '.join(KINDS)}") from None


def camera_options(camera: str, kind: str, raw: Mapping[str, Any]) -> dict[str, Any]:
    """The typed options of a camera of this kind (its own and the processing hook's),
    defaults filled in; ConfigError naming the camera and key for a bad one."""
    return parse_options(camera, kind, {**camera_kind(kind).options, **COMMON_OPTIONS}, raw)
