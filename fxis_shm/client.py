"""The Python client: synchronized tuples and single frames as NumPy arrays.

It uses a DEALER socket and tags every request with an id, so a timed-out
request leaves the client usable (a reply that arrives late is recognised by
its id and discarded), and a restarted service is reconnected to by itself.

Two paths bring the pixels (``Frame.path`` says which one did): on the
service's own kernel, the service replies with where the chosen frames are and
the client copies them out of the shared-memory rings itself ("local", see
fxis_shm.localpath); elsewhere, or when the rings cannot be opened here, the
frames travel in the reply ("network").
"""
from __future__ import annotations

import itertools
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
import zmq

from . import protocol
from .bufferpool import release as release_buffer
from .errors import CameraDown, FxisError, InvalidArgument, LocalPathUnavailable, UnknownCamera, Overwritten, ProtocolError, RequestTimeout, service_error
from .localpath import LocalRings, LocalUnavailable, boot_id
from .localreads import LocalReads
from .security import ClientKeys

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
LOCAL, NETWORK = "local", "network"
LOCAL_MODES = ("auto", "off", "require")
_LOCAL_ATTEMPTS = 3  # requests re-asked after a torn local copy before giving up
_LOCAL_RETRY_S = 10.0  # after the rings could not be opened, the network path this long
_PERIODS_VALID_S = 10.0  # the cameras' periods learnt from the status, for sequences that wait


@dataclass
class Frame:
    """One image and what the service knows of it. Times are ns of the service's CLOCK_MONOTONIC."""

    image: np.ndarray
    camera: str
    frame_id: int
    t_capture: int
    t_stored: int
    generation: int
    timing: dict = field(default_factory=dict, repr=False)
    t_available: int | None = None  # when the worker had the whole frame (before any processing hook)
    path: str = NETWORK  # how the pixels came: "local" (copied from the ring here) or "network"
    _still_valid: Callable[[], bool] | None = field(default=None, repr=False)

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
            self.image = ReleasedImage(f"the image of frame {self.frame_id} of {self.camera!r}")

    def __enter__(self) -> "Frame":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class ReleasedImage:
    """What ``Frame.image`` is after ``release()``: any use says so."""

    __slots__ = ("what",)

    def __init__(self, what: str):
        self.what = what

    def _fail(self, *args, **kwargs):
        raise FxisError(f"{self.what} was released: its buffer may hold another frame now")

    __getattr__ = __array__ = __getitem__ = __len__ = __iter__ = _fail

    def __repr__(self) -> str:
        return f"<{self.what}, released>"


class FrameTuple(Mapping):
    """One frame per camera, chosen together for the request time ``t_request``."""

    def __init__(self, frames: dict[str, Frame], t_request: int | None, timing: dict,
                 missing: list[str] = ()):
        self._frames = frames
        self.t_request = t_request
        self.timing = timing
        self.missing = list(missing)  # cameras left out of a partial tuple (they were down)

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

    def __enter__(self) -> "FrameTuple":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __getitem__(self, camera: str) -> Frame:
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
        return f"FrameTuple({ids}, skew_ns={self.skew_ns})"


def connected_socket(context: zmq.Context | None, kind: int, endpoint: str,
                     keys: ClientKeys | None = None) -> zmq.Socket:
    """A client socket: LINGER 0 (closing never blocks), CURVE if keys are given."""
    sock = (context or zmq.Context.instance()).socket(kind)
    sock.setsockopt(zmq.LINGER, 0)
    if keys is not None:
        keys.apply(sock)
    sock.connect(endpoint)
    return sock


class SocketOwner:
    """Closes its one ZeroMQ socket (``self._sock``) on ``close`` and on leaving a ``with``."""

    _sock: zmq.Socket

    def close(self) -> None:
        self._sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Client(SocketOwner):
    """``Client(endpoint, timeout)``: every call raises RequestTimeout after ``timeout`` seconds."""

    def __new__(cls, endpoint: str | list[str] = DEFAULT_ENDPOINT, *args, **kwargs):
        """``Client([endpoint_a, endpoint_b])``: one client over several services (MultiClient)."""
        if cls is Client and isinstance(endpoint, (list, tuple)):
            from .multiclient import MultiClient  # imports this module
            return MultiClient(endpoint, **kwargs)
        return super().__new__(cls)

    def __init__(self, endpoint: str = DEFAULT_ENDPOINT, timeout: float = 2.0,
                 context: zmq.Context | None = None, keys: ClientKeys | None = None,
                 local: str = "auto"):
        """``keys``: for a service with CurveZMQ, its public key and this client's pair
        (``ClientKeys.from_files("server.key", "me.key_secret")``).

        ``local``: "auto" copies frames straight from the service's shared-memory rings
        when the service runs on this kernel and its rings can be opened (same user, same
        /dev/shm), else takes them from the reply; "off" always takes them from the
        reply; "require" raises LocalPathUnavailable rather than use the network path."""
        if local not in LOCAL_MODES:
            raise InvalidArgument(f"local must be one of {LOCAL_MODES}, got {local!r}")
        self.endpoint = endpoint
        self.timeout = timeout
        self.local = local
        self._ids = itertools.count(1)
        self._sock = connected_socket(context, zmq.DEALER, endpoint, keys)
        self._clock_offset: int | None = None  # service clock minus local clock
        self._periods: tuple[float, float] | None = None  # (longest frame period, when learnt)
        self._boot_id = boot_id()
        self._rings = LocalRings()
        self._reads: LocalReads | None = None  # answers from the rings without the coordinator
        self._reads_off: tuple[str, float] | None = None  # why not, since when
        self._local_off: tuple[str, float] | None = None  # why the local path is not used, since when
        self.paths = {LOCAL: 0, NETWORK: 0, "torn": 0}  # replies by path; local copies found torn

    def close(self) -> None:
        self._drop_reads()
        self._rings.close()
        super().close()

    @property
    def local_unavailable(self) -> str | None:
        """Why the last request could not use the local path (None: it could, or was not asked to)."""
        return self._local_off[0] if self._local_off else None

    # ---- operations ----

    def image(self, camera: str, *, at: int | None = None, wait: str | None = None,
              timeout: float | None = None, copy: bool = True, timeout_ms: float | None = None) -> Frame:
        """The frame of ``camera`` nearest to ``at`` (ns of the service's clock; default: the
        moment the request arrives).

        ``timeout``: seconds the service may wait for frames (default: its setting).
        ``copy=False`` (local path only): the image is a read-only view of the ring slot,
        with no copy at all; check ``frame.still_valid()`` after using it."""
        waits_ms = _timeout_ms(timeout, timeout_ms)
        reply = self._fetch("image", self._extra_wait(at, waits_ms), copy, camera=camera, at=at,
                            wait=wait, timeout_ms=waits_ms)
        return frames_of(*reply)[0]

    def tuple(self, cameras: list[str] | None = None, *, at: int | None = None,
              sync: str | None = None, wait: str | None = None, max_skew_ms: float | None = None,
              timeout: float | None = None, partial: bool = False, copy: bool = True,
              timeout_ms: float | None = None) -> FrameTuple:
        """One frame per camera (default: all), nearest to ``at`` (ns) and to each other.
        With ``partial``, cameras that are down are left out (``.missing`` names
        them) instead of failing the request with CameraDown."""
        waits_ms = _timeout_ms(timeout, timeout_ms)
        reply = self._fetch("tuple", self._extra_wait(at, waits_ms), copy, cameras=cameras, at=at,
                            sync=sync, wait=wait, max_skew_ms=max_skew_ms,
                            timeout_ms=waits_ms, partial=partial or None)
        return tuple_of(*reply)

    def latest(self, cameras: list[str] | None = None, *, copy: bool = True) -> FrameTuple:
        """The newest stored frame of each camera, without waiting."""
        return tuple_of(*self._fetch("latest", 0.0, copy, cameras=cameras))

    def sequence(self, kind: str, *, camera: str | None = None, cameras: list[str] | None = None,
                 count: int | None = None, direction: str = "before",
                 interval_ms: float | None = None, start: int | None = None, end: int | None = None,
                 at: int | None = None, sync: str | None = None,
                 timeout: float | None = None, copy: bool = True, timeout_ms: float | None = None) -> list:
        """Several frames of one ``camera`` (a list of Frame) or tuples of ``cameras``
        (default all; a list of FrameTuple):

        - ``kind="consecutive"``: ``count`` frames ``before``, ``after`` or ``around`` t*;
        - ``kind="interval"``: the frames nearest to t* + i*interval_ms, i = 0..count-1;
        - ``kind="range"``: every frame captured in [start, end] (ns).
        """
        waits_ms = _timeout_ms(timeout, timeout_ms)
        fields = dict(camera=camera, cameras=cameras, kind=kind, count=count, direction=direction,
                      interval_ms=interval_ms, start=start, end=end, at=at, sync=sync,
                      timeout_ms=waits_ms)
        last = end if kind == "range" else at
        if kind == "interval" and at is not None and count and interval_ms and interval_ms > 0:
            last = at + int((count - 1) * interval_ms * 1e6)
        extra = self._extra_wait(last, waits_ms)
        if kind == "consecutive" and direction != "before" and count:
            extra += count * self._longest_period_s()
        return sequence_of(*self._fetch("sequence", extra, copy, **fields), single=camera is not None)

    def _longest_period_s(self) -> float:
        """The slowest camera's frame period: from the rings when they are read here (no
        request), else from the service's status, looked at again after a while."""
        reads = self._local_reads()
        if reads is not None:
            periods = [h.period_ns for h in reads.cameras.values() if h.period_ns > 0]
            return max(periods, default=1e9) / 1e9
        if self._periods is None or time.monotonic() - self._periods[1] > _PERIODS_VALID_S:
            cams = self.status()["cameras"].values()
            self._periods = (max((1 / c["fps"] for c in cams if c.get("fps")), default=1.0), time.monotonic())
        return self._periods[0]

    def status(self) -> dict:
        return self._call("status", 0.0)[0]

    def time(self) -> int:
        """The service's clock now (ns of its CLOCK_MONOTONIC)."""
        return self._call("time", 0.0)[0]["now"]

    def frame_times(self, cameras: list[str] | None = None) -> dict:
        """Each camera's frames without pixels (the ``frames`` op): liveness, period and a row
        per valid frame with the fields named in ``columns``, times in the service's clock."""
        return self._call("frames", 0.0, cameras=cameras)[0]

    # ---- the two paths ----

    def _fetch(self, op: str, extra_wait: float, copy: bool, **fields) -> tuple[dict, list, Callable | None]:
        """A request for frames, over the local path if it can be used: the reply header,
        the images (the header's ``path`` set) and a validity check for zero-copy views.
        Where the rings can be read with the service's own clock, the client answers
        itself (fxis_shm.localreads); otherwise the coordinator chooses the frames."""
        reads = self._local_reads()
        if reads is not None and reads.serves(op, fields):
            return self._read_locally(op, extra_wait, copy, fields)
        if self._local_usable():
            for _ in range(_LOCAL_ATTEMPTS):
                header, images = self._call(op, extra_wait, local=self._boot_id, **fields)
                if header.get("delivery") != protocol.LOCAL:  # the service is on another kernel
                    self._give_up_local("the service runs on another kernel")
                    return self._network_reply(header, images)
                try:
                    images = self._rings.images(header["frames"], copy)
                except Overwritten:  # we were too slow: the ring came round; ask again
                    self.paths["torn"] += 1
                    continue
                except LocalUnavailable as exc:  # the frames are there, just not here: same t*
                    self._give_up_local(str(exc))
                    fields = _same_moment(op, fields, header)
                    break
                self.paths[LOCAL] += 1
                self._local_off = None  # (again) usable
                header["path"] = LOCAL
                check = None if copy else (lambda metas=header["frames"]: all(map(self._rings.still_valid, metas)))
                return header, images, check
            else:
                raise Overwritten(f"the frames of {op!r} were overwritten in the rings {_LOCAL_ATTEMPTS} "
                                  "times before this client could copy them (is it starved of CPU, "
                                  "or are the rings too short?)")
        if self.local == "require":
            raise LocalPathUnavailable(f"the local fast path cannot be used: {self.local_unavailable}")
        return self._network_reply(*self._call(op, extra_wait, **fields))

    def _read_locally(self, op: str, extra_wait: float, copy: bool, fields: dict) -> tuple[dict, list, Callable | None]:
        deadline = time.monotonic_ns() + int((self.timeout + extra_wait) * 1e9)
        try:
            header, images, check = self._reads.answer(op, fields, deadline, copy)
        except (CameraDown, UnknownCamera):
            # The service may have been restarted with new rings or other cameras: learn them again, once.
            self._drop_reads()
            if self._local_reads() is None:
                raise
            header, images, check = self._reads.answer(op, fields, deadline, copy)
        self.paths[LOCAL] += 1
        header["path"] = LOCAL
        return header, images, check

    def _local_reads(self) -> LocalReads | None:
        """The client's own reads of the rings, learnt from the service's status once."""
        if self.local == "off":
            return None
        if self._reads is not None:
            return self._reads
        if self._reads_off is not None and time.monotonic() - self._reads_off[1] < _LOCAL_RETRY_S:
            return None
        try:
            self._reads = LocalReads(self.status(), self._boot_id)
            self._reads_off = None
        except LocalUnavailable as exc:
            self._reads_off = (str(exc), time.monotonic())
        return self._reads

    def _drop_reads(self) -> None:
        if self._reads is not None:
            self._reads.close()
            self._reads = None

    def _network_reply(self, header: dict, images: list) -> tuple[dict, list, None]:
        self.paths[NETWORK] += 1
        header["path"] = NETWORK
        return header, images, None

    def _local_usable(self) -> bool:
        if self.local == "off":
            return False
        if self._boot_id is None:
            self._local_off = ("this kernel has no boot id to compare", time.monotonic())
            return False
        if self._local_off is not None and time.monotonic() - self._local_off[1] < _LOCAL_RETRY_S:
            return False
        return True

    def _give_up_local(self, reason: str) -> None:
        """Take the network path for a while: the rings cannot be read here now."""
        self._local_off = (reason, time.monotonic())
        if self.local == "require":
            raise LocalPathUnavailable(f"the local fast path cannot be used: {reason}")

    # ---- plumbing ----

    def _extra_wait(self, at: int | None, timeout_ms: float | None = None) -> float:
        """Seconds the service may legitimately spend on a request beyond the client's
        own timeout: waiting for a future ``at``, and a ``timeout_ms`` longer than ours."""
        extra = max(0.0, (timeout_ms or 0) / 1000 - self.timeout / 2)
        if at is None:
            return extra
        if self._clock_offset is None and self._local_reads() is not None:
            self._clock_offset = 0  # the service's clock is ours (same kernel, same time namespace)
        if self._clock_offset is None:
            sent = time.monotonic_ns()
            now = self.time()
            self._clock_offset = now - (sent + time.monotonic_ns()) // 2
        return extra + max(0.0, (at - self._clock_offset - time.monotonic_ns()) / 1e9)

    def _call(self, op: str, extra_wait: float, **fields) -> tuple[dict, list[np.ndarray]]:
        request_id = next(self._ids)
        deadline = time.monotonic() + self.timeout + extra_wait
        # A DEALER with no connected peer (service down, or our keys refused) would
        # block in send: wait for it to become writable within our own deadline.
        unsendable = RequestTimeout(f"could not send {op!r} to {self.endpoint} within "
                                    f"{self.timeout:.3g} s (is the service running, and are our keys accepted?)")
        if not self._sock.poll(self.timeout * 1000, zmq.POLLOUT):
            raise unsendable
        try:
            self._sock.send_multipart([b""] + protocol.encode_request(op, id=request_id, **fields),
                                      flags=zmq.NOBLOCK)
        except zmq.Again:  # the peer went away between the poll and the send
            raise unsendable from None
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not self._sock.poll(remaining * 1000, zmq.POLLIN):
                raise RequestTimeout(
                    f"no reply to {op!r} from {self.endpoint} within {self.timeout + extra_wait:.3g} s "
                    "(is the service running?)"
                )
            frames = self._sock.recv_multipart(copy=False)
            if frames and len(frames[0].bytes) == 0:
                frames = frames[1:]
            header, images = protocol.decode_reply([f.buffer for f in frames])
            if header.get("id") != request_id:
                continue  # the late reply to an earlier request that timed out
            if not header["ok"]:
                err = header.get("error") or {}
                raise service_error(err.get("code", "UNKNOWN"), err.get("message", ""))
            return header, images



# ---- decoding replies and stream messages into Frames ----

def frames_of(header: dict, images: list[np.ndarray], still_valid: Callable | None = None) -> list[Frame]:
    timing, path = header.get("timing", {}), header.get("path", NETWORK)
    try:
        return [
            Frame(img, m["camera"], m["frame_id"], m["t_capture"], m["t_stored"],
                  m["generation"], timing, m.get("t_available"), path, still_valid)
            for m, img in zip(header["frames"], images)
        ]
    except KeyError as exc:
        raise ProtocolError(f"frame metadata lacks {exc}") from None


def _timeout_ms(timeout: float | None, timeout_ms: float | None) -> float | None:
    """A request's own timeout for the wire (ms), from ``timeout`` in seconds as everywhere in
    this API; ``timeout_ms``, the old name, still works but warns."""
    if timeout_ms is not None:
        warnings.warn("timeout_ms= is deprecated: give timeout= in seconds", DeprecationWarning, stacklevel=3)
        if timeout is None:
            return timeout_ms
    return None if timeout is None else timeout * 1000


def tuple_of(header: dict, images: list[np.ndarray], still_valid: Callable | None = None) -> FrameTuple:
    frames = frames_of(header, images, still_valid)
    return FrameTuple({f.camera: f for f in frames}, header.get("t_request"), header.get("timing", {}),
                      header.get("missing", ()))


def sequence_of(header: dict, images: list[np.ndarray], still_valid: Callable | None = None,
                single: bool = False) -> list:
    frames = frames_of(header, images, still_valid)
    groups = header.get("groups", [])
    timing = header.get("timing", {})
    if single:
        return [frames[g[0]] for g in groups]
    return [FrameTuple({frames[i].camera: frames[i] for i in g}, t, timing)
            for g, t in zip(groups, header.get("targets", [None] * len(groups)))]


def _same_moment(op: str, fields: dict, header: dict) -> dict:
    """The fields of a request asked again: for the t* the service chose the first time."""
    if op == "latest" or fields.get("at") is not None or header.get("t_request") is None:
        return fields
    return {**fields, "at": header["t_request"]}
