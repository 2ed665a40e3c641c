"""What a request returns: ``Frame`` (one image and what the service knows of it) and
``FrameTuple`` (one frame per camera), built from a reply's header and images.

Times in a Frame are in the caller's clock (``Client(clock=...)``; on the service's own
host and clock, the service's CLOCK_MONOTONIC): ``in_caller_clock`` moves a reply's times
there and keeps the service's own as ``service_t_*``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, Literal, NoReturn, cast

from numpy.typing import NDArray

from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import FxisError, ProtocolError
from fxis_shm.shm.bufferpool import release as release_buffer
from fxis_shm.wire.headers import ReplyHeader, TimingRecord

if TYPE_CHECKING:  # a TypeVar's default (PEP 696) is typing_extensions' before Python 3.13
    from typing_extensions import TypeVar
else:
    from typing import TypeVar

LOCAL, NETWORK = "local", "network"
_Time = Literal["t_capture", "t_stored", "t_available", "t_target"]
_ServiceTime = Literal["service_t_capture", "service_t_stored", "service_t_available", "service_t_target"]
# a frame's times, each with where the service's own value is kept once moved to the caller's clock
_TIMES: tuple[tuple[_Time, _ServiceTime], ...] = (
    ("t_capture", "service_t_capture"),
    ("t_stored", "service_t_stored"),
    ("t_available", "service_t_available"),
    ("t_target", "service_t_target"),
)
# how a frame came to be captured (Frame.capture): on its own (free-running, or triggered by a
# request for "now"), triggered for a moment a caller named, on the service's lockstep grid, or
# for a named moment and captured further from it than the camera's capture_tolerance_ms
FREE, SCHEDULED, LOCKSTEP, LATE = "free", "scheduled", "lockstep", "late"

Validity = Callable[[], bool]  # a zero-copy view's check: False once its slot was overwritten
# A frame request's reply as a path of the client answers it: the header (times in the caller's
# clock, its ``path`` set), the images, and the validity check of views (None: copies)
Answer = tuple[ReplyHeader, list[NDArray[Any]], Validity | None]


@dataclass(slots=True)
class Frame:
    """One image and what the service knows of it.

    Times (``t_*``) are int ns of the caller's clock; ``service_t_*`` are the same moments in
    the service's clock.

    Attributes
    ----------
    image : numpy.ndarray
        ``(h, w)`` for mono8, ``(h, w, 3)`` BGR for bgr8; a copy the caller may keep, or a
        read-only view of the ring slot with ``copy=False`` (check ``still_valid()``).
    camera : str
        The camera's name.
    frame_id : int
        The camera's frame counter (the synthetic camera stamps it into the pixels:
        ``read_stamp(image) == frame_id``).
    t_capture, t_stored, t_available : int
        When the sensor captured it, when the ring stored it, when the worker had it whole.
    generation : int
        Changes when the camera's worker restarts or its stream restarts at new settings.
    capture : str
        ``"free"``, ``"scheduled"`` (captured for ``t_target``), ``"late"`` (captured for
        ``t_target`` but further from it than the camera's ``capture_tolerance_ms``) or
        ``"lockstep"`` (on the service's grid point ``t_target``).
    t_target : int or None
        The moment it was captured for (None for a free frame); ``residual_ns`` is how far it missed.
    path : str
        ``"local"`` (copied from the ring on this host) or ``"network"``.
    encoding : str
        How the pixels travelled: ``"raw"``, ``"jpeg"`` or ``"png"``.
    timing : dict
        Where the request's time went (docs/protocol.md, the timing record).
    """

    image: NDArray[Any]
    camera: str
    frame_id: int
    t_capture: int
    t_stored: int
    generation: int
    timing: TimingRecord = field(default_factory=TimingRecord, repr=False)
    t_available: int | None = None  # when the worker had the whole frame (before any processing hook)
    path: str = NETWORK  # how the pixels came: "local" (copied from the ring here) or "network"
    _still_valid: Callable[[], bool] | None = field(default=None, repr=False)
    encoding: str = "raw"  # how the pixels travelled ("raw", "jpeg", "png")
    service_t_capture: int = field(default=0, repr=False)
    service_t_stored: int = field(default=0, repr=False)
    service_t_available: int | None = field(default=None, repr=False)
    capture: str = FREE  # FREE, SCHEDULED, LOCKSTEP or LATE
    t_target: int | None = None  # the moment a SCHEDULED, LATE or LOCKSTEP frame was to be captured at

    @property
    def residual_ns(self) -> int | None:
        """How far the capture missed its target (t_capture - t_target); None for a FREE frame."""
        return None if self.t_target is None else self.t_capture - self.t_target

    def still_valid(self) -> bool:
        """False once a zero-copy view's slot has been overwritten (then discard what you
        computed from it). A copied image (the default) stays valid for ever."""
        return self._still_valid is None or self._still_valid()

    def release(self) -> None:
        """Done with the image: its buffer goes back to the client's pool now (otherwise it
        does when the last reference to the image goes). Using ``image`` afterwards raises
        FxisError. ``with frame:`` releases on leaving the block."""
        if not isinstance(self.image, ReleasedImage):
            release_buffer(self.image)
            # it stands in for the array (every use of it raises), so the field keeps the array's type
            released = ReleasedImage(f"the image of frame {self.frame_id} of {self.camera!r}")
            self.image = cast("NDArray[Any]", released)

    def __enter__(self) -> Frame:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


@dataclass(slots=True)
class FrameView(Frame):
    """A Frame asked for with ``copy=False``: on the local path its ``image`` is a read-only
    view of the ring slot, no copy at all, valid only while ``still_valid()`` is true; check it
    after using the pixels, and discard what you computed if it is false. (Over the network the
    pixels are the reply's and stay valid.)"""


class ReleasedImage:
    """What ``Frame.image`` is after ``release()``: any use says so."""

    __slots__ = ("what",)

    def __init__(self, what: str):
        self.what = what

    def _fail(self, *args: object, **kwargs: object) -> NoReturn:
        raise FxisError(f"{self.what} was released: its buffer may hold another frame now")

    __getattr__ = __array__ = __getitem__ = __len__ = __iter__ = _fail

    def __repr__(self) -> str:
        return f"<{self.what}, released>"


if TYPE_CHECKING:
    AnyFrame = TypeVar("AnyFrame", bound=Frame, covariant=True, default=Frame)
else:
    AnyFrame = TypeVar("AnyFrame", bound=Frame, covariant=True)  # (the default is the checker's only)


class FrameTuple(Mapping[str, AnyFrame], Generic[AnyFrame]):
    """One frame per camera, chosen together for the request time ``t_request``.

    A mapping of camera name to ``Frame`` (``tuple_["left"]``, ``for name in tuple_``); a
    ``FrameTuple[FrameView]`` (asked for with ``copy=False``) maps to FrameViews.

    Attributes
    ----------
    t_request : int or None
        t*, int ns of the caller's clock (``service_t_request``: the same in the service's).
    skew_ns : int
        Max minus min ``t_capture`` of its frames.
    missing : list of str
        Cameras left out of a ``partial=True`` tuple because they were down.
    timing : dict
        Where the request's time went (docs/protocol.md, the timing record).
    path : str
        ``"local"`` or ``"network"``, as its frames say.
    """

    __slots__ = ("_frames", "t_request", "service_t_request", "timing", "missing", "_grid_mismatch")

    def __init__(
        self,
        frames: dict[str, AnyFrame],
        t_request: int | None,
        timing: TimingRecord,
        missing: Iterable[str] = (),
        service_t_request: int | None = None,
        grid_mismatch: dict[str, int] | None = None,
    ):
        self._frames = frames
        self.t_request = t_request  # t*, in the caller's clock
        self.service_t_request = t_request if service_t_request is None else service_t_request
        self.timing = timing
        self.missing = list(missing)  # cameras left out of a partial tuple (they were down)
        self._grid_mismatch = dict(grid_mismatch or {})

    @property
    def grid_mismatch(self) -> dict[str, int]:
        """Empty when the tuple's lockstep frames share one grid point (or it has fewer than two).
        Else no tuple of one point was stored near t*, and this names each lockstep camera's
        grid point (its frame's ``t_target``, in the caller's clock): the frames are of
        different triggers (docs/sync.md, "Tuples of one grid point")."""
        return dict(self._grid_mismatch)

    @property
    def path(self) -> str:
        """How the pixels came: "local" or "network" (the same for every frame of a reply)."""
        return next(iter(self._frames.values())).path if self._frames else NETWORK

    def still_valid(self) -> bool:
        return all(f.still_valid() for f in self._frames.values())

    def release(self) -> None:
        """Release every frame (see ``Frame.release``); ``with tuple_:`` does it on leaving."""
        for frame in self._frames.values():
            frame.release()

    def __enter__(self) -> FrameTuple[AnyFrame]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __getitem__(self, camera: str) -> AnyFrame:
        return self._frames[camera]

    def __iter__(self) -> Iterator[str]:
        return iter(self._frames)

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def skew_ns(self) -> int:
        """Max minus min capture time over the tuple."""
        times = [f.t_capture for f in self._frames.values()]
        return max(times) - min(times)

    def __repr__(self) -> str:
        ids = {c: f.frame_id for c, f in self._frames.items()}
        mismatch = f", grid_mismatch={self._grid_mismatch}" if self._grid_mismatch else ""
        return f"FrameTuple({ids}, skew_ns={self.skew_ns}{mismatch})"


# ---- decoding replies and stream messages into Frames ----

Images = list[NDArray[Any]]


def frames_of(
    header: ReplyHeader, images: Images, still_valid: Validity | None = None, view: bool = False
) -> list[Frame]:
    """The frames of a reply: FrameViews if asked for with ``copy=False`` (``view``; the client's
    operations type them apart, fxis_shm.client.framerequests)."""
    timing: TimingRecord = header.get("timing") or {}
    path = header.get("path", NETWORK)
    make = FrameView if view else Frame
    frames: list[Frame] = []
    try:  # (a loop, not a comprehension: cold, each comprehension is a function call more)
        for meta, image in zip(header["frames"], images):
            t_capture, t_stored, t_available = meta["t_capture"], meta["t_stored"], meta.get("t_available")
            frames.append(
                make(
                    image,
                    meta["camera"],
                    meta["frame_id"],
                    t_capture,
                    t_stored,
                    meta["generation"],
                    timing,
                    t_available,
                    path,
                    still_valid,
                    meta.get("encoding", "raw"),
                    meta.get("service_t_capture", t_capture),
                    meta.get("service_t_stored", t_stored),
                    meta.get("service_t_available", t_available),
                    meta.get("capture", FREE),
                    meta.get("t_target"),
                )
            )
    except KeyError as exc:
        raise ProtocolError(f"frame metadata lacks {exc}") from None
    return frames


def in_caller_clock(header: ReplyHeader, clock: ClockEstimate) -> ReplyHeader:
    """The reply ``header`` with its frames' times, t* and sequence targets in the caller's
    clock; the service's own values kept as ``service_*``. (``timing`` stays the service's.)"""
    if clock.offset_ns == 0 and clock.drift_ppm == 0:
        return header
    for meta in header.get("frames", ()):
        for key, service_key in _TIMES:
            value = meta.get(key)
            if value is not None:
                meta[service_key] = value
                meta[key] = clock.to_caller(value)
    t_request = header.get("t_request")
    if t_request is not None:
        header["service_t_request"] = t_request
        header["t_request"] = clock.to_caller(t_request)
    if header.get("targets"):
        header["targets"] = [clock.to_caller(t) for t in header["targets"]]
    mismatch = header.get("grid_mismatch")
    if isinstance(mismatch, dict):  # a tuple's
        header["grid_mismatch"] = _points_to_caller(mismatch, clock)
    elif mismatch:  # a sequence's: one per tuple
        header["grid_mismatch"] = [m and _points_to_caller(m, clock) for m in mismatch]
    return header


def _points_to_caller(points: dict[str, int], clock: ClockEstimate) -> dict[str, int]:
    return {c: clock.to_caller(t) for c, t in points.items()}


def tuple_of(
    header: ReplyHeader, images: Images, still_valid: Validity | None = None, view: bool = False
) -> FrameTuple[Frame]:
    by_camera: dict[str, Frame] = {}
    for frame in frames_of(header, images, still_valid, view):
        by_camera[frame.camera] = frame
    mismatch = header.get("grid_mismatch")  # a tuple's: camera -> grid point
    return FrameTuple(
        by_camera,
        header.get("t_request"),
        header.get("timing", {}),
        header.get("missing", ()),
        header.get("service_t_request"),
        mismatch if isinstance(mismatch, dict) else None,
    )


def sequence_of(
    header: ReplyHeader, images: Images, still_valid: Validity | None = None, single: bool = False, view: bool = False
) -> list[Frame] | list[FrameTuple[Frame]]:
    frames = frames_of(header, images, still_valid, view)
    groups = header.get("groups", [])
    timing: TimingRecord = header.get("timing", {})
    if single:
        return [frames[g[0]] for g in groups]
    targets: Sequence[int | None] = header.get("targets", [None] * len(groups))
    mismatch = header.get("grid_mismatch")  # a sequence's: one per tuple
    mismatches = (mismatch if isinstance(mismatch, list) else None) or [None] * len(groups)
    return [
        FrameTuple({frames[i].camera: frames[i] for i in g}, t, timing, grid_mismatch=m)
        for g, t, m in zip(groups, targets, mismatches)
    ]
