"""The arguments of every client operation checked before anything is sent or read: a bad one
is InvalidArgument naming it and its range (fxis_shm.wire.ranges), never a TypeError from
deep inside, an OverflowError or a ProtocolError of the wire's own check."""

from __future__ import annotations

import math
import warnings
from typing import Any

from fxis_shm.errors import InvalidArgument, ProtocolError, SettingRejected
from fxis_shm.formats import videochoice
from fxis_shm.formats.videotracks import VideoSettings
from fxis_shm.wire import protocol, ranges
from fxis_shm.wire.fieldchecks import MAX_SETTINGS

TIMES = ("at", "start", "end")  # ns of the caller's clock


def camera_names(cameras: Any) -> list[str] | None:
    """``cameras`` as the list the wire takes (a list or tuple of names; None: all)."""
    if cameras is None:
        return None
    if not isinstance(cameras, (list, tuple)) or not all(isinstance(c, str) and c for c in cameras):
        raise InvalidArgument(f"cameras must be a list of camera names (or None: all), got {cameras!r}")
    return list(cameras)


def camera_name(camera: Any) -> str:
    if not isinstance(camera, str) or not camera:
        raise InvalidArgument(f"camera must be a camera's name, got {camera!r}")
    return camera


def check_numbers(timeout: Any, **fields: Any) -> None:
    """InvalidArgument if a number of a request is out of its range (cheap: before the local
    fast path, which must not pay for the wire's whole check)."""
    if timeout is not None:
        ranges.TIMEOUT_S.check(timeout, "timeout")
    for key in TIMES:
        if fields.get(key) is not None:
            ranges.AT_NS.check(fields[key], key)
    if fields.get("count") is not None:
        ranges.SEQUENCE_COUNT.check(fields["count"], "count")
    if fields.get("max_skew_ms") is not None:
        ranges.MILLISECONDS.check(fields["max_skew_ms"], "max_skew_ms")
    interval = fields.get("interval_ms")
    if interval is not None:  # either sign: before or after t*
        ranges.MILLISECONDS.check(abs(interval) if isinstance(interval, (int, float)) else interval, "interval_ms")


def check_request(op: str, **fields: Any) -> None:
    """InvalidArgument if the request ``op`` with these fields is not one a service takes
    (before it is sent: the wire's own check, fxis_shm.wire.protocol)."""
    try:
        protocol.request_of(op, **fields)
    except ProtocolError as exc:
        raise InvalidArgument(exc.message) from None


def setting_values(values: dict[str, Any]) -> dict[str, Any]:
    """A settings change as the wire carries it: SettingRejected for a value no camera takes (not
    a finite number, a string or a boolean), InvalidArgument for none at all."""
    if not values:
        raise InvalidArgument("configure needs at least one KEY=VALUE")
    for key, value in values.items():
        finite = not isinstance(value, float) or math.isfinite(value)
        if not isinstance(value, (str, int, float, bool)) or not finite:
            raise SettingRejected(
                "SETTING_REFUSED", f"{key}={value!r}: a setting takes a finite number, a string or true/false"
            )
    if len(values) > MAX_SETTINGS:
        raise InvalidArgument(f"configure takes at most {MAX_SETTINGS} settings at once, got {len(values)}")
    return values


def check_queue(queue: Any) -> int:
    if isinstance(queue, bool) or not isinstance(queue, int) or not 1 <= queue <= 1_000_000:
        raise InvalidArgument(f"queue must be a whole number of messages from 1 to 1000000, got {queue!r}")
    return queue


def video_of(
    video: VideoSettings | None,
    *,
    codec: str | None,
    encoder: str | None,
    crf: int | None,
    preset: str | None,
    gop_s: float | None,
) -> VideoSettings | None:
    """A snapshot's video settings: ``video``, or the deprecated keywords that give its fields
    apart (a DeprecationWarning pointing at the caller of ``snapshot``; without ``codec`` they
    ask for no video, as they did)."""
    apart = {"codec": codec, "encoder": encoder, "crf": crf, "preset": preset, "gop_s": gop_s}
    given = [f"{name}=" for name, value in apart.items() if value is not None]
    if not given:
        return video
    warnings.warn(
        f"snapshot({', '.join(given)}) is deprecated: give video=VideoSettings(...)", DeprecationWarning, stacklevel=3
    )
    if video is not None:
        raise InvalidArgument(f"give video= or {', '.join(given)}, not both")
    if codec is None:
        return None
    return VideoSettings(codec, encoder or videochoice.AUTO, crf, preset, gop_s)
