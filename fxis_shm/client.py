"""The Python client: synchronized tuples and single frames as NumPy arrays.

It uses a DEALER socket and tags every request with an id, so a timed-out
request leaves the client usable (a reply that arrives late is recognised by
its id and discarded), and a restarted service is reconnected to by itself.
"""
from __future__ import annotations

import itertools
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np
import zmq

from . import protocol
from .errors import ProtocolError, RequestTimeout, service_error
from .security import ClientKeys

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"


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


class FrameTuple(Mapping):
    """One frame per camera, chosen together for the request time ``t_request``."""

    def __init__(self, frames: dict[str, Frame], t_request: int | None, timing: dict,
                 missing: list[str] = ()):
        self._frames = frames
        self.t_request = t_request
        self.timing = timing
        self.missing = list(missing)  # cameras left out of a partial tuple (they were down)

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

    def __init__(self, endpoint: str = DEFAULT_ENDPOINT, timeout: float = 2.0,
                 context: zmq.Context | None = None, keys: ClientKeys | None = None):
        """``keys``: for a service with CurveZMQ, its public key and this client's pair
        (``ClientKeys.from_files("server.key", "me.key_secret")``)."""
        self.endpoint = endpoint
        self.timeout = timeout
        self._ids = itertools.count(1)
        self._sock = connected_socket(context, zmq.DEALER, endpoint, keys)
        self._clock_offset: int | None = None  # service clock minus local clock
        self._periods: float | None = None  # longest frame period, for sequences that wait

    # ---- operations ----

    def image(self, camera: str, at: int | None = None, wait: str | None = None,
              timeout_ms: float | None = None) -> Frame:
        """The frame of ``camera`` nearest to ``at`` (default: the moment the request arrives)."""
        header, images = self._call("image", self._extra_wait(at, timeout_ms), camera=camera, at=at,
                                    wait=wait, timeout_ms=timeout_ms)
        return frames_of(header, images)[0]

    def tuple(self, cameras: list[str] | None = None, at: int | None = None,
              sync: str | None = None, wait: str | None = None,
              max_skew_ms: float | None = None, timeout_ms: float | None = None,
              partial: bool = False) -> FrameTuple:
        """One frame per camera (default: all), nearest to ``at`` and to each other.
        With ``partial``, cameras that are down are left out (``.missing`` names
        them) instead of failing the request with CameraDown."""
        header, images = self._call("tuple", self._extra_wait(at, timeout_ms), cameras=cameras, at=at,
                                    sync=sync, wait=wait, max_skew_ms=max_skew_ms,
                                    timeout_ms=timeout_ms, partial=partial or None)
        return tuple_of(header, images)

    def latest(self, cameras: list[str] | None = None) -> FrameTuple:
        """The newest stored frame of each camera, without waiting."""
        return tuple_of(*self._call("latest", 0.0, cameras=cameras))

    def sequence(self, kind: str, *, camera: str | None = None, cameras: list[str] | None = None,
                 count: int | None = None, direction: str = "before",
                 interval_ms: float | None = None, start: int | None = None, end: int | None = None,
                 at: int | None = None, sync: str | None = None,
                 timeout_ms: float | None = None) -> list:
        """Several frames of one ``camera`` (a list of Frame) or tuples of ``cameras``
        (default all; a list of FrameTuple):

        - ``kind="consecutive"``: ``count`` frames ``before``, ``after`` or ``around`` t*;
        - ``kind="interval"``: the frames nearest to t* + i*interval_ms, i = 0..count-1;
        - ``kind="range"``: every frame captured in [start, end] (ns).
        """
        fields = dict(camera=camera, cameras=cameras, kind=kind, count=count, direction=direction,
                      interval_ms=interval_ms, start=start, end=end, at=at, sync=sync,
                      timeout_ms=timeout_ms)
        last = end if kind == "range" else at
        if kind == "interval" and at is not None and count and interval_ms and interval_ms > 0:
            last = at + int((count - 1) * interval_ms * 1e6)
        extra = self._extra_wait(last, timeout_ms)
        if kind == "consecutive" and direction != "before" and count:
            extra += count * self._longest_period_s()
        header, images = self._call("sequence", extra, **fields)
        return sequence_of(header, images, single=camera is not None)

    def _longest_period_s(self) -> float:
        if self._periods is None:
            cams = self.status()["cameras"].values()
            self._periods = max((1 / c["fps"] for c in cams if c.get("fps")), default=1.0)
        return self._periods

    def status(self) -> dict:
        return self._call("status", 0.0)[0]

    def time(self) -> int:
        """The service's clock now (ns of its CLOCK_MONOTONIC)."""
        return self._call("time", 0.0)[0]["now"]

    # ---- plumbing ----

    def _extra_wait(self, at: int | None, timeout_ms: float | None = None) -> float:
        """Seconds the service may legitimately spend on a request beyond the client's
        own timeout: waiting for a future ``at``, and a ``timeout_ms`` longer than ours."""
        extra = max(0.0, (timeout_ms or 0) / 1000 - self.timeout / 2)
        if at is None:
            return extra
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

def frames_of(header: dict, images: list[np.ndarray]) -> list[Frame]:
    timing = header.get("timing", {})
    try:
        return [
            Frame(img, m["camera"], m["frame_id"], m["t_capture"], m["t_stored"],
                  m["generation"], timing, m.get("t_available"))
            for m, img in zip(header["frames"], images)
        ]
    except KeyError as exc:
        raise ProtocolError(f"frame metadata lacks {exc}") from None


def tuple_of(header: dict, images: list[np.ndarray]) -> FrameTuple:
    frames = frames_of(header, images)
    return FrameTuple({f.camera: f for f in frames}, header.get("t_request"), header.get("timing", {}),
                      header.get("missing", ()))


def sequence_of(header: dict, images: list[np.ndarray], single: bool) -> list:
    frames = frames_of(header, images)
    groups = header.get("groups", [])
    timing = header.get("timing", {})
    if single:
        return [frames[g[0]] for g in groups]
    return [FrameTuple({frames[i].camera: frames[i] for i in g}, t, timing)
            for g, t in zip(groups, header.get("targets", [None] * len(groups)))]
