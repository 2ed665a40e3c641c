"""The wire codec (docs/protocol.md): a JSON header frame, then raw image buffers.

Pure: lists of byte frames in, validated dicts and arrays out (and back).
Every malformed message raises ``ProtocolError`` with a stable code and a
message that says what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fxis_shm.core import timebase
from fxis_shm.core.selection import SYNC_MODES
from fxis_shm.core.sequences import DIRECTIONS, KINDS as SEQUENCE_KINDS
from fxis_shm.core.waitpolicy import WAIT_MODES
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.wire import encoding as codec, fastjson
from fxis_shm.wire.framemeta import described, encoded_meta, frame_meta, frame_ref  # noqa: F401 (names of the codec)

VERSION = 1
CLOCK = "CLOCK_MONOTONIC"
MAX_HEADER_BYTES = 64 * 1024
RESERVED_TOPICS = ("frames/", "tuples", "settings/", "fxis.")  # stream topics the service publishes itself
DTYPES = ("uint8", "uint16", "float32")
_DTYPE_OF = {name: np.dtype(name) for name in DTYPES}  # (np.dtype(name) parses the name on every call)
LOCAL = "local"  # the delivery of a reply whose frames the client copies from the rings itself


# ---- field checks: each returns the value or raises ProtocolError ----


def _fail(field: str, what: str):
    raise ProtocolError(f"field {field!r} {what}")


INT64_MAX = 2**63 - 1
MAX_TIMEOUT_MS = 3_600_000.0  # one hour: longer waits are surely a mistake


def _int(field, v, minimum=None):
    if isinstance(v, bool) or not isinstance(v, int):
        _fail(field, f"must be an integer, got {type(v).__name__}")
    if not -INT64_MAX <= v <= INT64_MAX:
        _fail(field, "must fit in a signed 64-bit integer")
    if minimum is not None and v < minimum:
        _fail(field, f"must be >= {minimum}, got {v}")
    return v


def _number(field, v, positive=True):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v:
        _fail(field, f"must be a number, got {type(v).__name__}")
    if v in (math.inf, -math.inf):
        _fail(field, f"must be finite, got {v}")
    if positive and v <= 0:
        _fail(field, f"must be > 0, got {v}")
    return v


def _timeout(field, v):
    _number(field, v)
    if v > MAX_TIMEOUT_MS:
        _fail(field, f"must be at most {MAX_TIMEOUT_MS:.0f} ms, got {v}")
    return v


def _boolean(field, v):
    if not isinstance(v, bool):
        _fail(field, f"must be true or false, got {type(v).__name__}")
    return v


def _count(field, v):
    return _int(field, v, minimum=1)


def _nonzero(field, v):
    _number(field, v, positive=False)
    if v == 0:
        _fail(field, "must not be 0")
    return v


def _topic(field, v):
    if not isinstance(v, str) or not v or len(v) > 256:
        _fail(field, "must be a non-empty string of at most 256 characters")
    if v.startswith(RESERVED_TOPICS):
        _fail(field, f"must not start with a reserved prefix {RESERVED_TOPICS}")
    return v


def _name(field, v):
    if not isinstance(v, str) or not v:
        _fail(field, "must be a non-empty string")
    return v


def _names(field, v):
    if not isinstance(v, list) or not v:
        _fail(field, "must be a non-empty list of camera names")
    for item in v:
        _name(field, item)
    if len(set(v)) != len(v):
        _fail(field, "names a camera twice")
    return v


def _choice(options):
    def check(field, v):
        if v not in options:
            _fail(field, f"must be one of {list(options)}, got {v!r}")
        return v

    return check


def _optional(check):
    def wrapped(field, v):
        return None if v is None else check(field, v)

    return wrapped


MAX_SETTINGS = 64  # keys in one settings request


def _setting_values(field, v):
    if not isinstance(v, dict) or not v:
        _fail(field, "must be a non-empty object of setting names and values")
    if len(v) > MAX_SETTINGS:
        _fail(field, f"may set at most {MAX_SETTINGS} keys at once, got {len(v)}")
    for key, value in v.items():
        if not key or not isinstance(value, (str, int, float, bool)):
            _fail(field, f"must map each setting name to a number, string or boolean, got {key!r}: {value!r}")
        if isinstance(value, float) and not math.isfinite(value):
            _fail(field, f"must hold finite numbers, got {key!r}: {value!r}")
    return v


def _boot_id(field, v):
    if not isinstance(v, str) or not 0 < len(v) <= 64:
        _fail(field, "must be the client's boot id, a string of 1 to 64 characters")
    return v


def _request_id(field, v):
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        _fail(field, "must be an integer or a string")
    return v


Check = Callable[[str, Any], Any]
_COMMON: dict[str, tuple[Check, Any]] = {
    "v": (_int, VERSION),
    "op": (_name, None),
    "id": (_optional(_request_id), None),
}


def _quality(field, v):
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 100:
        _fail(field, f"must be an integer from 1 to 100, got {v!r}")
    return v


# How the pixels travel in a reply (the local fast path always leaves them raw in the rings).
_ENCODED: dict[str, tuple[Check, Any]] = {
    "encoding": (_choice(codec.ENCODINGS), codec.RAW),
    "quality": (_optional(_quality), None),  # JPEG only; None: the codec's default
}
_WAITING: dict[str, tuple[Check, Any]] = {
    "at": (_optional(_int), None),
    # the moment the caller made a call without "at", in the service's clock: t* then (travel time)
    "t_call": (_optional(_int), None),
    "wait": (_optional(_choice(WAIT_MODES)), None),  # None: the service's default
    "timeout_ms": (_optional(_timeout), None),
}
# with "at": trigger the cameras that can be triggered for a capture at that moment (docs/sync.md)
_CAPTURE: dict[str, tuple[Check, Any]] = {"capture": (_optional(_boolean), None)}
# op -> {field: (check, default)}; a default of ... marks a required field
# "local": the client's kernel boot id; a service on the same kernel then replies
# with where the frames are instead of their pixels (the local fast path).
_LOCAL: dict[str, tuple[Check, Any]] = {"local": (_optional(_boot_id), None)}
OPS: dict[str, dict[str, tuple[Check, Any]]] = {
    "image": {"camera": (_name, ...), **_WAITING, **_CAPTURE, **_LOCAL, **_ENCODED},
    "tuple": {
        "cameras": (_optional(_names), None),
        "sync": (_optional(_choice(SYNC_MODES)), None),
        "max_skew_ms": (_optional(_number), None),
        "partial": (_optional(_boolean), None),
        **_WAITING,
        **_CAPTURE,
        **_LOCAL,
        **_ENCODED,
    },
    "latest": {"cameras": (_optional(_names), None), **_LOCAL, **_ENCODED},
    "sequence": {
        "camera": (_optional(_name), None),
        "cameras": (_optional(_names), None),
        "kind": (_choice(SEQUENCE_KINDS), ...),
        "count": (_optional(_count), None),
        "direction": (_choice(DIRECTIONS), "before"),
        "interval_ms": (_optional(_nonzero), None),
        "start": (_optional(_int), None),
        "end": (_optional(_int), None),
        "sync": (_optional(_choice(SYNC_MODES)), None),
        "at": (_optional(_int), None),
        "t_call": (_optional(_int), None),
        "timeout_ms": (_optional(_timeout), None),
        **_LOCAL,
        **_ENCODED,
    },
    "status": {},
    "time": {},
    "frames": {"cameras": (_optional(_names), None)},  # frame times without pixels
    # a camera's settings; with "set", a change applied all or none (docs/protocol.md 7.8)
    "settings": {
        "camera": (_name, ...),
        "set": (_optional(_setting_values), None),
        "features": (_optional(_boolean), None),
    },
}
EVENT_OPS = ("image", "tuple", "latest", "sequence", "time")
EVENT_TOPIC = b"fxis.request"  # the topic of request events published to the service


class _Schema(dict[str, tuple[Check, Any]]):
    """An op's whole schema (field: (check, default); ``...``: required), with the request
    its defaults make written once: a request checks only the fields it has."""

    def __init__(self, fields: dict[str, tuple[Check, Any]]):
        super().__init__(fields)
        self.defaults = {field: default for field, (_, default) in fields.items()}
        self.required = [field for field, (_, default) in fields.items() if default is ...]


def _with_common(schemas: dict[str, dict[str, tuple[Check, Any]]]) -> dict[str, _Schema]:
    """Each op's whole schema: the fields every request has, then its own."""
    return {op: _Schema({**_COMMON, **fields}) for op, fields in schemas.items()}


_REQUESTS = _with_common(OPS)
# Event answers go to many subscribers, so they always carry the pixels: no "local".
_EVENTS = _with_common(
    {op: {**{k: v for k, v in OPS[op].items() if k not in _LOCAL}, "reply_topic": (_topic, ...)} for op in EVENT_OPS}
)


def _check_sequence(req: dict) -> None:
    if req["camera"] is not None and req["cameras"] is not None:
        raise ProtocolError("give either 'camera' (a list of frames) or 'cameras' (a list of tuples), not both")
    needs = {"consecutive": ("count",), "interval": ("count", "interval_ms"), "range": ("start", "end")}
    for field in needs[req["kind"]]:
        if req[field] is None:
            raise ProtocolError(f"a {req['kind']} sequence needs field {field!r}")
    if req["kind"] == "range" and req["start"] > req["end"]:
        raise ProtocolError(f"'start' ({req['start']}) is after 'end' ({req['end']})")


def _check_capture(req: dict) -> None:
    if req.get("capture") and req["at"] is None:
        raise ProtocolError("'capture' needs 'at': the moment the cameras are to capture at")


CROSS_CHECKS = {"sequence": _check_sequence, "image": _check_capture, "tuple": _check_capture}


def decode_request(frames: Sequence[bytes], max_header_bytes: int = MAX_HEADER_BYTES) -> dict:
    """Validate a request (the frames after the routing envelope) and fill in defaults."""
    if len(frames) != 1:
        raise ProtocolError(f"a request is exactly one frame (a JSON header), got {len(frames)}")
    return _decode_header(frames[0], max_header_bytes, _REQUESTS)


def decode_event(frames: Sequence[bytes], max_header_bytes: int = MAX_HEADER_BYTES) -> dict:
    """Validate a request event ([EVENT_TOPIC, header]): a request plus its ``reply_topic``."""
    if len(frames) != 2 or bytes(frames[0]) != EVENT_TOPIC:
        raise ProtocolError(f"a request event is two frames: {EVENT_TOPIC!r} and a JSON header")
    return _decode_header(frames[1], max_header_bytes, _EVENTS)


def _decode_header(frame: bytes, max_header_bytes: int, schemas: dict) -> dict:
    raw = bytes(frame)
    if len(raw) > max_header_bytes:
        raise ProtocolError(
            f"request header of {len(raw)} bytes exceeds the limit of {max_header_bytes}",
            Code.TOO_LARGE,
        )
    try:
        header = fastjson.loads(raw)
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"request header is not valid JSON: {exc}") from None
    except RecursionError:
        raise ProtocolError("request header is nested too deeply") from None
    if not isinstance(header, dict):
        raise ProtocolError(f"request header must be a JSON object, got {type(header).__name__}")
    return _validate(header, schemas)


def request_of(op: str, **fields) -> dict:
    """The request a client would send, validated and with defaults filled in as the
    service does, without encoding it (for requests a client answers itself)."""
    header = {"v": VERSION, "op": op, **{k: v for k, v in fields.items() if v is not None}}
    return _validate(header, _REQUESTS)


def _validate(header: dict, schemas: dict[str, _Schema]) -> dict:
    """``header`` checked against its op's whole schema in ``schemas`` (see ``_with_common``)."""
    if "v" not in header:
        raise ProtocolError("request header has no 'v' (protocol version)")
    if header["v"] != VERSION:
        raise ProtocolError(
            f"protocol version {header['v']!r} is not supported; this service speaks {VERSION}",
            Code.UNSUPPORTED_VERSION,
        )
    op = _name("op", header.get("op"))
    if op not in schemas:
        raise ProtocolError(f"unknown op {op!r}; known: {sorted(schemas)}", Code.UNKNOWN_OP)
    schema = schemas[op]
    if not header.keys() <= schema.keys():
        raise ProtocolError(f"unknown field(s) {sorted(header.keys() - schema.keys())} for op {op!r}")
    request = dict(schema.defaults)  # in the schema's order, as _checked_in_order makes it
    try:
        for field, value in header.items():
            request[field] = schema[field][0](field, value)
        complete = all(field in header for field in schema.required)
    except ProtocolError:
        complete = False
    if not complete:  # the first problem in the schema's order is the one to report
        request = _checked_in_order(header, schema, op)
    if op in CROSS_CHECKS:
        CROSS_CHECKS[op](request)
    return request


def _checked_in_order(header: dict, schema: _Schema, op: str) -> dict:
    """``header`` checked field by field in the schema's order: raises at the first problem."""
    request = {}
    for field, (check, default) in schema.items():
        if field in header:
            request[field] = check(field, header[field])
        elif default is ...:
            raise ProtocolError(f"op {op!r} needs field {field!r}")
        else:
            request[field] = default
    return request


def encode_request(op: str, **fields) -> list[bytes]:
    header = {"v": VERSION, "op": op, **{k: v for k, v in fields.items() if v is not None}}
    return [fastjson.dumps(header)]


def encode_event(op: str, reply_topic: str, **fields) -> list[bytes]:
    return [EVENT_TOPIC, *encode_request(op, reply_topic=reply_topic, **fields)]


# ---- stream topics ----
# "frames/<camera>|" and "tuples|", optionally decimated ("@<hz>") and compressed (":jpeg<quality>",
# ":png"): "frames/cam0@10:jpeg90|", "tuples:png|". The closing "|" keeps ZeroMQ's prefix
# matching from mixing a stream with its other forms.


@dataclass(frozen=True)
class StreamTopic:
    kind: str  # "frames" or "tuples"
    camera: str | None
    rate_hz: float | None
    encoding: str = codec.RAW
    quality: int | None = None  # JPEG only

    def __str__(self) -> str:
        base = "tuples" if self.kind == "tuples" else f"frames/{self.camera}"
        rate = f"@{self.rate_hz:g}" if self.rate_hz else ""
        coded = "" if self.encoding == codec.RAW else f":{self.encoding}"
        if self.encoding == codec.JPEG:
            coded += str(self.quality or codec.DEFAULT_JPEG_QUALITY)
        return f"{base}{rate}{coded}|"


def parse_stream_topic(topic: str) -> StreamTopic | None:
    """The stream a subscription names, or None if it names none."""
    if not topic.endswith("|"):
        return None
    rest, _, coded = topic[:-1].partition(":")
    base, _, rate = rest.partition("@")
    rate_hz = None
    if rate:
        try:
            rate_hz = float(rate)
        except ValueError:
            return None
        if not 0 < rate_hz < 1e6:
            return None
    encoding, quality = codec.RAW, None
    if coded:
        encoding = coded.rstrip("0123456789")
        digits = coded[len(encoding) :]
        if encoding not in (codec.JPEG, codec.PNG) or (digits and encoding != codec.JPEG):
            return None
        quality = int(digits) if digits else None
        if quality is not None and not 1 <= quality <= 100:
            return None
    if base == "tuples":
        return StreamTopic("tuples", None, rate_hz, encoding, quality)
    if base.startswith("frames/") and len(base) > len("frames/"):
        return StreamTopic("frames", base[len("frames/") :], rate_hz, encoding, quality)
    return None


# ---- replies ----


def encode_reply(request_id, body: dict, buffers: Sequence = ()) -> list:
    """A success reply: the header frame, then one frame per buffer (sent as is, not copied)."""
    header = {"v": VERSION, "id": request_id, "ok": True, "clock": timebase.wire_name(), **body}
    return [fastjson.dumps(header), *buffers]


def encode_error(request_id, code: str, message: str) -> list[bytes]:
    header = {"v": VERSION, "id": request_id, "ok": False, "error": {"code": code, "message": message}}
    return [fastjson.dumps(header)]


def decode_reply(frames: Sequence) -> tuple[dict, list[np.ndarray]]:
    """Header and images of a reply; images are built on the received buffers without copying."""
    if not frames:
        raise ProtocolError("empty reply")
    try:
        header = fastjson.loads(bytes(frames[0]))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"reply header is not valid JSON: {exc!r}") from None
    if not isinstance(header, dict) or header.get("v") != VERSION or "ok" not in header:
        raise ProtocolError("reply header is not a version-1 reply")
    buffers = frames[1:]
    images: list[np.ndarray] = []
    if not isinstance(header.get("frames", []), list):
        raise ProtocolError("reply field 'frames' must be a list")
    if header.get("delivery") == LOCAL:
        return header, images  # the frames stay in the rings (see fxis_shm.shm.localpath)
    for meta in header.get("frames", ()):
        images.append(_image(meta, buffers))
    return header, images


def _image(meta: dict, buffers: Sequence) -> np.ndarray:
    """A frame's image: on its buffer without a copy (raw), or decoded. A well-formed raw frame
    takes the short way (its checks cost half a cold reply's decoding); anything else, the
    field-by-field checks, which say what is wrong."""
    if type(meta) is dict and meta.get("encoding", codec.RAW) == codec.RAW:
        name, index, shape = meta.get("dtype"), meta.get("buffer"), meta.get("shape")
        dtype = _DTYPE_OF.get(name) if type(name) is str else None
        if dtype is not None and type(index) is int and 0 <= index < len(buffers) and type(shape) is list:
            for size in shape:
                if type(size) is not int or size < 0:
                    break
            else:
                buf = buffers[index]
                nbytes = buf.nbytes if type(buf) is memoryview else len(buf) if type(buf) is bytes else -1
                try:
                    image: np.ndarray = np.ndarray(shape, dtype, buf)
                except (TypeError, ValueError):  # too big, or the buffer too short: worded below
                    pass
                else:
                    if image.nbytes == nbytes:
                        return image
    return _checked_image(meta, buffers)


def _checked_image(meta: dict, buffers: Sequence) -> np.ndarray:
    try:
        index, shape = meta["buffer"], meta["shape"]
        if type(index) is not int or index < 0:
            raise IndexError(f"buffer index {index!r}")
        if not isinstance(shape, list) or any(type(s) is not int or s < 0 for s in shape):
            raise ValueError(f"shape {shape!r}")
        buf = buffers[index]
        dtype = _DTYPE_OF.get(meta["dtype"]) or np.dtype(meta["dtype"])  # (raises for a name numpy lacks)
        shape = tuple(shape)
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise ProtocolError(f"frame metadata does not match the buffers: {exc!r}") from None
    if meta["dtype"] not in _DTYPE_OF:
        raise ProtocolError(f"unsupported dtype {meta['dtype']!r}")
    encoding = meta.get("encoding", codec.RAW)
    if encoding != codec.RAW:
        if encoding not in codec.ENCODINGS:
            raise ProtocolError(f"a frame in unknown encoding {encoding!r}")
        return codec.decode(buf, encoding, shape, dtype.name)
    expected = math.prod(shape) * dtype.itemsize
    view = memoryview(buf)
    if view.nbytes != expected:
        raise ProtocolError(f"buffer of {view.nbytes} bytes for shape {shape} {dtype.name}")
    return np.frombuffer(view, dtype=dtype).reshape(shape)
