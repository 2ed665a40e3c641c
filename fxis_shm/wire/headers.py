"""The shapes of the JSON headers the codec reads and writes (docs/protocol.md sections 5, 6,
7.6 and 9), as ``TypedDict``s the type checker follows from the socket to the caller.

Types only: a header is still the plain dict ``json`` makes, so nothing here costs a call.
A field that only some ops or replies carry is optional (``total=False``); the codec's checks
(fxis_shm.wire.protocol) are what make a header from the wire one of these.
"""

from __future__ import annotations

from typing import Literal, TypeAlias, TypedDict

RequestId: TypeAlias = int | str | None  # echoed in the reply as sent; not a float, not a boolean
SettingValue: TypeAlias = str | int | float | bool


class _RequestBase(TypedDict):
    v: int  # the protocol version
    op: str
    id: RequestId


class RequestHeader(_RequestBase, total=False):
    """A request as the codec returns it (section 5): every field of its op, defaults filled in.
    Which fields an op has is the schema's business (``protocol.OPS``); each is here once."""

    camera: str | None
    cameras: list[str] | None
    at: int | None
    t_call: int | None
    wait: str | None
    timeout_ms: float | None
    sync: str | None
    max_skew_ms: float | None
    partial: bool | None
    capture: bool | None
    local: str | None  # the client's kernel boot id: ask for a local reply (section 16)
    encoding: str
    quality: int | None
    kind: str  # sequence: "consecutive", "interval" or "range"
    count: int | None
    direction: str
    interval_ms: float | None
    start: int | None
    end: int | None
    set: dict[str, SettingValue] | None  # settings: the values to change
    features: bool | None
    reply_topic: str  # a request event's (section 15)


class RingPlace(TypedDict):
    """Where a frame of a local reply is: ``slot`` of the ring segment ``ring``, whose header
    carries ``instance`` (a uint64 as a decimal string), while the slot shows ``seq``."""

    ring: str
    instance: str
    slot: int
    seq: int


class _FrameMetaBase(TypedDict):
    camera: str
    frame_id: int
    t_capture: int
    t_available: int
    t_stored: int
    generation: int
    capture: str  # "free", "scheduled", "late" or "lockstep"
    t_target: int | None


class FrameMeta(_FrameMetaBase, total=False):
    """One entry of a reply's ``frames`` (section 7.6): what the frame is, when it was captured
    and stored, and where its pixels are (a ``buffer`` of the reply, or a ring place). A reply
    of the service always has ``shape`` and ``dtype``; one the client answers itself from the
    rings (fxis_shm.client.localreads) has its images as arrays already, and not them."""

    shape: list[int]
    dtype: str
    buffer: int
    encoding: str  # only when the buffer is compressed
    bytes: int  # with ``encoding``: the buffer's length
    ring: str
    instance: str
    slot: int
    seq: int
    # the client's own additions when it moves the times into the caller's clock
    service_t_capture: int
    service_t_available: int | None  # None: a frame without t_available (Frame.t_available)
    service_t_stored: int
    service_t_target: int


class CameraTiming(TypedDict):
    waited: int


class TimingRecord(TypedDict, total=False):
    """A reply's ``timing`` (section 9): service-clock moments of answering it. A service's reply
    has every field; what a client makes of its own has fewer (a stream message's frames none,
    the multi-service client's reply ``received`` and ``waited``: fxis_shm.client.jointrequests)."""

    received: int
    waited: int
    searched: int
    copied: int
    sent: int
    cameras: dict[str, CameraTiming]


class ErrorBody(TypedDict):
    code: str  # one of fxis_shm.errors.Code
    message: str


Delivery = Literal["local"]


class _ReplyBase(TypedDict):
    v: int
    id: RequestId
    ok: bool


class ReplyHeader(_ReplyBase, total=False):
    """A reply's header (section 6): ``error`` when not ``ok``, else ``clock``, ``op`` and the
    op's body (section 7). The ``status`` and ``settings`` bodies are documents of their own and
    stay open here; the fields the client reads of the others are typed."""

    error: ErrorBody
    clock: str
    op: str
    t_request: int
    frames: list[FrameMeta]
    timing: TimingRecord
    skew_ns: int
    sync: str
    missing: list[str]
    grid_mismatch: dict[str, int] | list[dict[str, int] | None]  # a tuple's; a sequence's: one per tuple
    delivery: Delivery
    targets: list[int]  # sequence: the moments its groups are for
    groups: list[list[int]]  # sequence: each group's indices into ``frames``
    received: int  # time
    now: int  # time, status, frames
    boot_id: str | None
    # a published stream message's (section 9): its stream, its number, and in a decimated
    # stream's first message the rate note (asked_hz, camera_fps, every_frame, message)
    stream: str
    seq: int
    rate: dict[str, object]
    # the client's own additions: t* in the service's clock when it moves the times into the
    # caller's, and the path the frames took ("local" or "network", fxis_shm.client.requestpaths)
    service_t_request: int
    path: str
