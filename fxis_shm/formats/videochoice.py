"""Which video encoder and settings a recording uses (``fxis record --codec``), checked
before anything is written: the codec, the encoder (``--encoder auto|software|NAME``), the
CRF, the GOP and the cameras' pixel formats.

``auto`` tries the hardware encoders FFmpeg names for the codec (NVENC, VAAPI, QSV) first and
falls back to software; an encoder counts as present only if it opens (``opens``), since
FFmpeg lists NVENC whether or not there is an NVIDIA card. Pure: names, numbers and a probe in,
a choice or a ConfigError out.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from fxis_shm.errors import ConfigError
from fxis_shm.wire.encoding import RAW

CODECS = ("h264", "h265", "av1")  # the `format` names foxglove.CompressedVideo uses
AUTO, SOFTWARE = "auto", "software"
HARDWARE = {
    "h264": ("h264_nvenc", "h264_vaapi", "h264_qsv"),
    "h265": ("hevc_nvenc", "hevc_vaapi", "hevc_qsv"),
    "av1": ("av1_nvenc", "av1_vaapi", "av1_qsv"),
}
SOFTWARE_ENCODERS = {"h264": ("libx264",), "h265": ("libx265",), "av1": ("libsvtav1",)}
DEFAULT_CRF = {"h264": 23, "h265": 28, "av1": 35}  # each library's own default
CRF_RANGE = {"h264": (0, 51), "h265": (0, 51), "av1": (1, 63)}
# Software presets: fast enough to keep up with a camera on one core (docs/recording.md).
DEFAULT_PRESET = {"libx264": "veryfast", "libx265": "ultrafast", "libsvtav1": "11"}
X26X_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
PRESETS = {"libx264": X26X_PRESETS, "libx265": X26X_PRESETS, "libsvtav1": tuple(str(n) for n in range(14))}
DEFAULT_GOP_S = 2.0
GOP_RANGE_S = (0.1, 60.0)  # a seek lands on a keyframe at most this far back
# The pixel layouts (ROS encoding names) that 8-bit 4:2:0 video carries; 16-bit and float
# frames would be cut to 8 bits, so they are refused rather than silently changed.
CARRIED = ("mono8", "bgr8", "bgra8")


@dataclass(frozen=True)
class Choice:
    codec: str
    encoder: str
    hardware: bool

    def describe(self) -> str:
        kind = "hardware" if self.hardware else "software"
        return f"{self.codec} with {self.encoder} ({kind})"


def split_encoding(encoding: str, codec: str | None, flag: str = "") -> tuple[str, str | None]:
    """(image encoding, video codec) of an ``encoding`` and ``codec`` given together: an
    encoding that names a video codec (``encoding="h264"``, the issue's spelling) is that codec,
    as ``codec="h264"`` is. ConfigError if the two name different codecs. ``flag``: "--" for
    the command line's words."""
    if encoding not in CODECS:
        return encoding, codec
    if codec is not None and codec != encoding:
        raise ConfigError(
            f"{flag}encoding {encoding} and {flag}codec {codec} disagree: give one of them (both name the video codec)"
        )
    return RAW, encoding


def candidates(codec: str, encoder: str) -> list[str]:
    """The encoders to try, in order, for ``--codec codec --encoder encoder``."""
    if codec not in CODECS:
        raise ConfigError(f"--codec {codec}: unknown; one of {', '.join(CODECS)}")
    hardware, software = list(HARDWARE[codec]), list(SOFTWARE_ENCODERS[codec])
    if encoder == AUTO:
        return hardware + software
    if encoder == SOFTWARE:
        return software
    if encoder in hardware + software:
        return [encoder]
    raise ConfigError(
        f"--encoder {encoder}: not an encoder of {codec}; one of {AUTO}, {SOFTWARE}, {', '.join(hardware + software)}"
    )


def choose(codec: str, encoder: str, available: Iterable[str], opens: Callable[[str], bool]) -> Choice:
    """The first of ``candidates`` that FFmpeg has (``available``) and that opens."""
    tried = [name for name in candidates(codec, encoder) if name in set(available)]
    for name in tried:
        if opens(name):
            return Choice(codec, name, name not in SOFTWARE_ENCODERS[codec])
    wanted = ", ".join(candidates(codec, encoder))
    said = f"{', '.join(tried)} would not open" if tried else "the bundled FFmpeg has none of them"
    raise ConfigError(f"--codec {codec} --encoder {encoder}: needs {wanted}; {said}")


def check_crf(codec: str, crf: int | None) -> int:
    """The CRF to use: the codec's default, or ``crf`` if in its range."""
    if crf is None:
        return DEFAULT_CRF[codec]
    low, high = CRF_RANGE[codec]
    if not low <= crf <= high:
        raise ConfigError(f"--crf {crf}: out of range for {codec}, from {low} to {high} (default {DEFAULT_CRF[codec]})")
    return crf


def check_preset(choice: Choice, preset: str | None) -> str | None:
    """The preset to use (None: a hardware encoder's own default), or ConfigError."""
    known = PRESETS.get(choice.encoder)
    if preset is None:
        return DEFAULT_PRESET.get(choice.encoder)
    if known is not None and preset not in known:
        raise ConfigError(f"--preset {preset}: not a preset of {choice.encoder}; one of {', '.join(known)}")
    return preset


def check_gop(gop_s: float | None) -> float:
    if gop_s is None:
        return DEFAULT_GOP_S
    low, high = GOP_RANGE_S
    if not low <= gop_s <= high:
        raise ConfigError(f"--gop {gop_s}: out of range, from {low} to {high} seconds (default {DEFAULT_GOP_S})")
    return gop_s


def check_camera(codec: str, camera: str, encoding: str, width: int, height: int) -> None:
    """ConfigError if the camera's frames are not something ``codec`` at 8-bit 4:2:0 carries."""
    if encoding not in CARRIED:
        raise ConfigError(
            f"--codec {codec}: camera {camera} gives {encoding} frames, which 8-bit video would cut; "
            f"video carries {', '.join(CARRIED)} (record it with --encoding raw, or leave it out with --cameras)"
        )
    if width % 2 or height % 2:
        raise ConfigError(
            f"--codec {codec}: camera {camera} is {width}x{height}; 4:2:0 video needs an even width and height"
        )
