"""The header of a frame op's reply written as text from templates: the bytes
``protocol.encode_reply`` makes of the same body, without building its dicts.

Cold, as a request is when it comes tens of milliseconds after the last, making the body's
dicts and letting the JSON encoder walk them cost two thirds of what the coordinator spends on
a tuple beside the copy (about 70 of 100 µs); written from templates, about 25. Used where the
coordinator answers in one step (fxis_shm.service.fastanswers); the differential test
(tests/unit/test_replytext.py) holds it to ``encode_reply`` byte for byte.
"""

from __future__ import annotations

from collections.abc import Sequence

from fxis_shm.core import timebase
from fxis_shm.wire import fastjson
from fxis_shm.wire.protocol import VERSION

_HEAD = '{"v": %d, "id": %s, "ok": true, "clock": %s, "op": %s'
_TAIL = (
    ', "frames": [%s], "timing": {"searched": %d, "received": %d, "waited": %d, "copied": %d, '
    '"cameras": {%s}, "sent": %d}}'
)
_WAITED = '%s: {"waited": %d}'
_TEXTS: dict[str, str] = {}  # op, sync and clock names as JSON text (a handful)


def _text(name: str) -> str:
    text = _TEXTS.get(name)
    if text is None:
        text = _TEXTS[name] = fastjson.dumps(name).decode()
    return text


def frames_reply(
    request_id: int | str,
    op: str,
    frames: Sequence[str],
    timing: tuple[int, int, int, int, int],
    waited: Sequence[tuple[str, int]],
    t_request: int | None = None,
    skew_ns: int | None = None,
    sync: str | None = None,
) -> bytes:
    """``encode_reply(request_id, body)[0]`` for the body {"op", "t_request" (if given),
    "skew_ns" and "sync" (if given), "frames", "timing"}: ``frames`` each as
    ``CameraFrames.frame_json`` wrote it, ``timing`` (searched, received, waited, copied, sent),
    ``waited`` (a camera's name as JSON text, when it was ready) per camera, in order."""
    rid = str(request_id) if type(request_id) is int else fastjson.dumps(request_id).decode()
    text = _HEAD % (VERSION, rid, _text(timebase.wire_name()), _text(op))
    if t_request is not None:
        text += f', "t_request": {t_request:d}'
    if skew_ns is not None and sync is not None:
        text += f', "skew_ns": {skew_ns:d}, "sync": {_text(sync)}'
    searched, received, ready, copied, sent = timing
    cameras = ", ".join([_WAITED % camera for camera in waited])
    text += _TAIL % (", ".join(frames), searched, received, ready, copied, cameras, sent)
    return text.encode()
