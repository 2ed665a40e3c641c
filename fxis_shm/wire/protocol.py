"""The wire codec (docs/protocol.md): a JSON header frame, then raw image buffers.

Pure: lists of byte frames in, validated dicts and arrays out (and back).
Every malformed message raises ``ProtocolError`` with a stable code and a
message that says what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias, cast

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import zmq

from fxis_shm.core import timebase
from fxis_shm.core.selection import SYNC_MODES
from fxis_shm.core.sequences import DIRECTIONS, KINDS as SEQUENCE_KINDS
from fxis_shm.core.waitpolicy import WAIT_MODES
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.wire import encoding as codec, fastjson, fieldchecks as checks
from fxis_shm.wire.fieldchecks import Check
from fxis_shm.wire.headers import FrameMeta, ReplyHeader, RequestId

VERSION = 1
CLOCK = "CLOCK_MONOTONIC"
MAX_HEADER_BYTES = 64 * 1024
RESERVED_TOPICS = ("frames/", "tuples", "settings/", "fxis.")  # stream topics the service publishes itself
DTYPES = ("uint8", "uint16", "float32")
_DTYPE_OF = {name: np.dtype(name) for name in DTYPES}  # (np.dtype(name) parses the name on every call)
# A validated request: every field of its op (wire.headers.RequestHeader names them), as the
# engine (fxis_shm.core.engine) takes it; its values are what the schema's checks returned.
Request: TypeAlias = dict[str, Any]
# A frame of a message: what pyzmq sends without a copy and what a received zmq.Frame's buffer is.
Buffer: TypeAlias = "bytes | memoryview | NDArray[Any] | zmq.Frame"
Received: TypeAlias = bytes | memoryview  # a received frame (a zmq.Frame's buffer, or its bytes)
LOCAL = "local"  # the delivery of a reply whose frames the client copies from the rings itself


_COMMON: dict[str, tuple[Check, object]] = {
    "v": (checks.integer, VERSION),
    "op": (checks.name, None),
    "id": (checks.optional(checks.request_id), None),
}


# How the pixels travel in a reply (the local fast path always leaves them raw in the rings).
_ENCODED: dict[str, tuple[Check, object]] = {
    "encoding": (checks.choice(codec.ENCODINGS), codec.RAW),
    "quality": (checks.optional(checks.quality), None),  # JPEG only; None: the codec's default
}
_WAITING: dict[str, tuple[Check, object]] = {
    "at": (checks.optional(checks.integer), None),
    # the moment the caller made a call without "at", in the service's clock: t* then (travel time)
    "t_call": (checks.optional(checks.integer), None),
    "wait": (checks.optional(checks.choice(WAIT_MODES)), None),  # None: the service's default
    "timeout_ms": (checks.optional(checks.timeout), None),
}
# with "at": trigger the cameras that can be triggered for a capture at that moment (docs/sync.md)
_CAPTURE: dict[str, tuple[Check, object]] = {"capture": (checks.optional(checks.boolean), None)}
# op -> {field: (check, default)}; a default of ... marks a required field
# "local": the client's kernel boot id; a service on the same kernel then replies
# with where the frames are instead of their pixels (the local fast path).
_LOCAL: dict[str, tuple[Check, object]] = {"local": (checks.optional(checks.boot_id), None)}
OPS: dict[str, dict[str, tuple[Check, object]]] = {
    "image": {"camera": (checks.name, ...), **_WAITING, **_CAPTURE, **_LOCAL, **_ENCODED},
    "tuple": {
        "cameras": (checks.optional(checks.names), None),
        "sync": (checks.optional(checks.choice(SYNC_MODES)), None),
        "max_skew_ms": (checks.optional(checks.number), None),
        "partial": (checks.optional(checks.boolean), None),
        **_WAITING,
        **_CAPTURE,
        **_LOCAL,
        **_ENCODED,
    },
    "latest": {"cameras": (checks.optional(checks.names), None), **_LOCAL, **_ENCODED},
    "sequence": {
        "camera": (checks.optional(checks.name), None),
        "cameras": (checks.optional(checks.names), None),
        "kind": (checks.choice(SEQUENCE_KINDS), ...),
        "count": (checks.optional(checks.count), None),
        "direction": (checks.choice(DIRECTIONS), "before"),
        "interval_ms": (checks.optional(checks.nonzero), None),
        "start": (checks.optional(checks.integer), None),
        "end": (checks.optional(checks.integer), None),
        "sync": (checks.optional(checks.choice(SYNC_MODES)), None),
        "at": (checks.optional(checks.integer), None),
        "t_call": (checks.optional(checks.integer), None),
        "timeout_ms": (checks.optional(checks.timeout), None),
        **_LOCAL,
        **_ENCODED,
    },
    "status": {},
    "time": {},
    "frames": {"cameras": (checks.optional(checks.names), None)},  # frame times without pixels
    # a camera's settings; with "set", a change applied all or none (docs/protocol.md 7.8)
    "settings": {
        "camera": (checks.name, ...),
        "set": (checks.optional(checks.setting_values), None),
        "features": (checks.optional(checks.boolean), None),
    },
}
EVENT_OPS = ("image", "tuple", "latest", "sequence", "time")
EVENT_TOPIC = b"fxis.request"  # the topic of request events published to the service


class _Schema(dict[str, tuple[Check, object]]):
    """An op's whole schema (field: (check, default); ``...``: required), with the request
    its defaults make written once: a request checks only the fields it has."""

    def __init__(self, fields: dict[str, tuple[Check, object]]):
        super().__init__(fields)
        self.defaults = {field: default for field, (_, default) in fields.items()}
        self.required = [field for field, (_, default) in fields.items() if default is ...]


def _with_common(schemas: dict[str, dict[str, tuple[Check, object]]]) -> dict[str, _Schema]:
    """Each op's whole schema: the fields every request has, then its own."""
    return {op: _Schema({**_COMMON, **fields}) for op, fields in schemas.items()}


_REQUESTS = _with_common(OPS)
# Event answers go to many subscribers, so they always carry the pixels: no "local".
_EVENTS = _with_common(
    {
        op: {
            **{k: v for k, v in OPS[op].items() if k not in _LOCAL},
            "reply_topic": (checks.topic(RESERVED_TOPICS), ...),
        }
        for op in EVENT_OPS
    }
)


def _check_sequence(req: Request) -> None:
    if req["camera"] is not None and req["cameras"] is not None:
        raise ProtocolError("give either 'camera' (a list of frames) or 'cameras' (a list of tuples), not both")
    needs = {"consecutive": ("count",), "interval": ("count", "interval_ms"), "range": ("start", "end")}
    for field in needs[req["kind"]]:
        if req[field] is None:
            raise ProtocolError(f"a {req['kind']} sequence needs field {field!r}")
    if req["kind"] == "range" and req["start"] > req["end"]:
        raise ProtocolError(f"'start' ({req['start']}) is after 'end' ({req['end']})")


def _check_capture(req: Request) -> None:
    if req.get("capture") and req["at"] is None:
        raise ProtocolError("'capture' needs 'at': the moment the cameras are to capture at")


CROSS_CHECKS: dict[str, Callable[[Request], None]] = {
    "sequence": _check_sequence,
    "image": _check_capture,
    "tuple": _check_capture,
}


def decode_request(frames: Sequence[bytes], max_header_bytes: int = MAX_HEADER_BYTES) -> Request:
    """Validate a request (the frames after the routing envelope) and fill in defaults."""
    if len(frames) != 1:
        raise ProtocolError(f"a request is exactly one frame (a JSON header), got {len(frames)}")
    return _decode_header(frames[0], max_header_bytes, _REQUESTS)


def decode_event(frames: Sequence[bytes], max_header_bytes: int = MAX_HEADER_BYTES) -> Request:
    """Validate a request event ([EVENT_TOPIC, header]): a request plus its ``reply_topic``."""
    if len(frames) != 2 or bytes(frames[0]) != EVENT_TOPIC:
        raise ProtocolError(f"a request event is two frames: {EVENT_TOPIC!r} and a JSON header")
    return _decode_header(frames[1], max_header_bytes, _EVENTS)


def _decode_header(frame: bytes, max_header_bytes: int, schemas: dict[str, _Schema]) -> Request:
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


def request_of(op: str, **fields: object) -> Request:
    """The request a client would send, validated and with defaults filled in as the
    service does, without encoding it (for requests a client answers itself)."""
    header = {"v": VERSION, "op": op, **{k: v for k, v in fields.items() if v is not None}}
    return _validate(header, _REQUESTS)


def _validate(header: dict[str, object], schemas: dict[str, _Schema]) -> Request:
    """``header`` checked against its op's whole schema in ``schemas`` (see ``_with_common``)."""
    if "v" not in header:
        raise ProtocolError("request header has no 'v' (protocol version)")
    if header["v"] != VERSION:
        raise ProtocolError(
            f"protocol version {header['v']!r} is not supported; this service speaks {VERSION}",
            Code.UNSUPPORTED_VERSION,
        )
    op = checks.name("op", header.get("op"))
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


def _checked_in_order(header: dict[str, object], schema: _Schema, op: str) -> Request:
    """``header`` checked field by field in the schema's order: raises at the first problem."""
    request: Request = {}
    for field, (check, default) in schema.items():
        if field in header:
            request[field] = check(field, header[field])
        elif default is ...:
            raise ProtocolError(f"op {op!r} needs field {field!r}")
        else:
            request[field] = default
    return request


def encode_request(op: str, **fields: object) -> list[bytes]:
    header = {"v": VERSION, "op": op, **{k: v for k, v in fields.items() if v is not None}}
    return [fastjson.dumps(header)]


def encode_event(op: str, reply_topic: str, **fields: object) -> list[bytes]:
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


def encode_reply(request_id: RequestId, body: Mapping[str, object], buffers: Sequence[Buffer] = ()) -> list[Buffer]:
    """A success reply: the header frame, then one frame per buffer (sent as is, not copied)."""
    header = {"v": VERSION, "id": request_id, "ok": True, "clock": timebase.wire_name(), **body}
    return [fastjson.dumps(header), *buffers]


def encode_error(request_id: RequestId, code: str, message: str) -> list[bytes]:
    header = {"v": VERSION, "id": request_id, "ok": False, "error": {"code": code, "message": message}}
    return [fastjson.dumps(header)]


def decode_reply(frames: Sequence[Received]) -> tuple[ReplyHeader, list[NDArray[Any]]]:
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
    images: list[NDArray[Any]] = []
    if not isinstance(header.get("frames", []), list):
        raise ProtocolError("reply field 'frames' must be a list")
    # A reply of version 1 from here on; each frame's fields are checked where _image reads them.
    reply = cast(ReplyHeader, header)
    if reply.get("delivery") == LOCAL:
        return reply, images  # the frames stay in the rings (see fxis_shm.shm.localpath)
    for meta in reply.get("frames", ()):
        images.append(_image(meta, buffers))
    return reply, images


def _image(meta: FrameMeta, buffers: Sequence[Received]) -> NDArray[Any]:
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
                    image: NDArray[Any] = np.ndarray(shape, dtype, buf)
                except (TypeError, ValueError):  # too big, or the buffer too short: worded below
                    pass
                else:
                    if image.nbytes == nbytes:
                        return image
    return _checked_image(meta, buffers)


def _checked_image(meta: FrameMeta, buffers: Sequence[Received]) -> NDArray[Any]:
    try:
        index, listed = meta["buffer"], meta["shape"]
        if type(index) is not int or index < 0:
            raise IndexError(f"buffer index {index!r}")
        if not isinstance(listed, list) or any(type(s) is not int or s < 0 for s in listed):
            raise ValueError(f"shape {listed!r}")
        buf = buffers[index]
        dtype = _DTYPE_OF.get(meta["dtype"]) or np.dtype(meta["dtype"])  # (raises for a name numpy lacks)
        shape = tuple(listed)
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
