"""The coordinator: reads every camera's ring and answers requests.

One thread runs one poll loop over the ROUTER socket (requests from REQ and
DEALER clients), the PUB socket, and the frame notifications of FrameWatch.
A request that must wait for frames is parked and re-evaluated when frames
arrive or its next deadline passes, so it never delays other clients.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import zmq

from . import protocol
from .cameras import CameraHandle
from .errors import Code, ProtocolError
from .framewatch import FrameWatch
from .ring import Overwritten
from .selection import INDEPENDENT, select
from .waitpolicy import waiting_for

log = logging.getLogger("coordinator")

DEFAULTS = {
    "sync": "joint",
    "wait": "auto",
    "timeout_ms": 1000.0,
    "max_skew_ms": None,
    "horizon_ms": 10_000.0,
    "sync_tolerance_ms": 1.0,
    "max_pending": 1000,
}
_LIVENESS_CHECK_NS = 100_000_000  # waiting requests notice a dead camera this fast
_COPY_ATTEMPTS = 3


class Reject(Exception):
    """Ends a request with an error reply."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code, self.message = code, message


@dataclass
class Pending:
    envelope: list
    request: dict
    cameras: list[str]
    t_received: int
    t_star: int
    deadline: int
    baseline: dict[str, int]
    ready_at: dict[str, int] = field(default_factory=dict)
    wake_at: int = 0


def split_envelope(frames: list) -> tuple[list, list]:
    """ROUTER frames -> (routing envelope incl. the empty delimiter, body)."""
    for i in range(1, len(frames)):
        if len(frames[i]) == 0:
            return frames[: i + 1], frames[i + 1 :]
    return frames[:1], frames[1:]


def _request_id_of(body: list):
    """The id of a request we could not decode, if it has a readable one."""
    try:
        rid = json.loads(bytes(body[0])).get("id")
        return rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
    except Exception:
        return None


class Coordinator:
    def __init__(self, spec: dict):
        self.service = spec["service"]
        self.endpoint = spec["endpoint"]
        self.pub_endpoint = spec["pub"]
        self.settings = {**DEFAULTS, **spec.get("settings", {})}
        self.cameras = {
            name: CameraHandle(self.service, name, cam["kind"])
            for name, cam in spec["cameras"].items()
        }
        self.pending: list[Pending] = []
        self.started_ns = time.monotonic_ns()
        self.requests_served = 0

    # ---- the loop ----

    def serve(self, stop: threading.Event, on_ready: Callable[[], None] = lambda: None) -> None:
        ctx = zmq.Context()
        sockets = []
        try:
            self.router = ctx.socket(zmq.ROUTER)
            self.pub = ctx.socket(zmq.XPUB)
            sockets += [self.router, self.pub]
            for sock in sockets:
                sock.setsockopt(zmq.LINGER, 0)
            self.router.setsockopt(zmq.SNDHWM, 100)
            self.router.setsockopt(zmq.ROUTER_MANDATORY, 1)  # report unsendable replies
            self._bind(self.router, self.endpoint, "request endpoint")
            self._bind(self.pub, self.pub_endpoint, "publish endpoint")
            watch = FrameWatch(ctx, self.service, list(self.cameras))
            sockets.append(watch)
            poller = zmq.Poller()
            poller.register(self.router, zmq.POLLIN)
            poller.register(self.pub, zmq.POLLIN)
            poller.register(watch.pull, zmq.POLLIN)
            on_ready()
            log.info("serving %s on %s, publishing on %s", sorted(self.cameras),
                     self.endpoint, self.pub_endpoint)
            while not stop.is_set():
                events = dict(poller.poll(self._poll_timeout_ms()))
                updated = watch.drain() if watch.pull in events else set()
                if self.pub in events:
                    self._drain_subscriptions()
                if self.router in events:
                    self._drain_requests()
                self._advance_pending(updated)
        finally:
            for sock in reversed(sockets):
                sock.close()
            for cam in self.cameras.values():
                cam.close()
            ctx.term()

    @staticmethod
    def _bind(sock, endpoint: str, what: str) -> None:
        try:
            sock.bind(endpoint)
        except zmq.ZMQError as exc:
            raise RuntimeError(f"cannot bind the {what} {endpoint}: {exc}") from None

    def _poll_timeout_ms(self) -> int:
        if not self.pending:
            return 200
        wake = min(p.wake_at for p in self.pending)
        return max(0, min(200, (wake - time.monotonic_ns()) // 1_000_000 + 1))

    def _drain_subscriptions(self) -> None:
        while True:  # subscriptions are used by the streams of a later issue
            try:
                self.pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return

    def _drain_requests(self, budget: int = 256) -> None:
        for _ in range(budget):
            try:
                frames = self.router.recv_multipart(zmq.NOBLOCK, copy=True)
            except zmq.Again:
                return
            self._handle(frames, time.monotonic_ns())

    def _advance_pending(self, updated: set[str]) -> None:
        if not self.pending:
            return
        now = time.monotonic_ns()
        still = []
        for p in self.pending:
            due = p.wake_at <= now or not updated.isdisjoint(p.cameras)
            if not (due and self._advance(p, now)):
                still.append(p)
        self.pending = still

    # ---- requests ----

    def _handle(self, frames: list, t_received: int) -> None:
        envelope, body = split_envelope(frames)
        try:
            request = protocol.decode_request(body)
        except ProtocolError as exc:
            log.info("bad request: %s", exc.message)
            self._send(envelope, protocol.encode_error(_request_id_of(body), exc.code, exc.message))
            return
        op = request["op"]
        try:
            if op in ("image", "tuple"):
                self._start_waiting_request(envelope, request, t_received)
                return
            body_ = getattr(self, f"_op_{op}")(request, t_received)
            self._reply(envelope, request, body_)
        except Reject as exc:
            self._send(envelope, protocol.encode_error(request["id"], exc.code, exc.message))
        except Exception as exc:  # a bug must not take the service down
            log.exception("internal error on %s", op)
            self._send(envelope, protocol.encode_error(request["id"], Code.INTERNAL, repr(exc)))

    def _cameras_of(self, request: dict) -> list[str]:
        if request["op"] == "image":
            names = [request["camera"]]
        else:
            names = request.get("cameras") or list(self.cameras)
        unknown = [n for n in names if n not in self.cameras]
        if unknown:
            raise Reject(Code.UNKNOWN_CAMERA,
                         f"unknown camera(s) {unknown}; this service has {sorted(self.cameras)}")
        return names

    def _setting(self, request: dict, key: str):
        value = request.get(key)
        return self.settings[key] if value is None else value

    def _start_waiting_request(self, envelope: list, request: dict, t_received: int) -> None:
        cameras = self._cameras_of(request)
        if len(self.pending) >= self.settings["max_pending"]:
            raise Reject(Code.BUSY, f"{len(self.pending)} requests are waiting already; try again")
        t_star = request["at"] if request["at"] is not None else t_received
        horizon = int(self.settings["horizon_ms"] * 1e6)
        if t_star - t_received > horizon:
            raise Reject(Code.OUT_OF_RANGE,
                         f"t* is {(t_star - t_received) / 1e6:.1f} ms in the future; "
                         f"the horizon is {self.settings['horizon_ms']} ms")
        timeout = int(self._setting(request, "timeout_ms") * 1e6)
        p = Pending(
            envelope, request, cameras, t_received, t_star,
            deadline=max(t_received, t_star) + timeout,
            baseline={c: self.cameras[c].write_count() for c in cameras},
        )
        # First evaluation at the arrival time: a request that need not wait records no wait.
        if not self._advance(p, t_received):
            self.pending.append(p)

    def _advance(self, p: Pending, now: int) -> bool:
        """Answer ``p`` if it can be answered now; True once it got its reply."""
        try:
            snaps = self._snapshots(p.cameras, now)
            states = {c: self.cameras[c].state(snaps[c], p.baseline[c]) for c in p.cameras}
            waits = waiting_for(self._setting(p.request, "wait"), p.t_star, now, states)
            for cam in p.cameras:
                if cam not in waits:
                    p.ready_at.setdefault(cam, now)
            if waits:
                if now >= p.deadline:
                    raise Reject(Code.TIMEOUT,
                                 f"the frames awaited from {sorted(waits)} did not arrive within "
                                 f"{(p.deadline - max(p.t_received, p.t_star)) / 1e6:.0f} ms")
                give_ups = [t for t in waits.values() if t is not None]
                p.wake_at = min([p.deadline, now + _LIVENESS_CHECK_NS, *give_ups])
                return False
            self._answer(p, snaps, now)
        except Reject as exc:
            self._send(p.envelope, protocol.encode_error(p.request["id"], exc.code, exc.message))
        except Exception as exc:
            log.exception("internal error on %s", p.request["op"])
            self._send(p.envelope, protocol.encode_error(p.request["id"], Code.INTERNAL, repr(exc)))
        return True

    def _snapshots(self, cameras: list[str], now: int) -> dict:
        snaps = {}
        for cam in cameras:
            handle = self.cameras[cam]
            reason = handle.down_reason(now)
            if reason:
                raise Reject(Code.CAMERA_DOWN, reason)
            snaps[cam] = handle.reader.snapshot()
        return snaps

    def _answer(self, p: Pending, snaps: dict, t_waited: int) -> None:
        mode = INDEPENDENT if p.request["op"] == "image" else self._setting(p.request, "sync")
        for attempt in range(_COPY_ATTEMPTS):
            if attempt:
                snaps = self._snapshots(p.cameras, time.monotonic_ns())
            self._check_history(p, snaps)
            sel = select(mode, {c: snaps[c].timeline for c in p.cameras}, p.t_star,
                         self._radius(p.cameras), int(self.settings["sync_tolerance_ms"] * 1e6))
            t_searched = time.monotonic_ns()
            max_skew = self._setting(p.request, "max_skew_ms")
            if p.request["op"] == "tuple" and max_skew is not None and sel.skew_ns > max_skew * 1e6:
                raise Reject(Code.SKEW_EXCEEDED,
                             f"the best tuple near t* has a skew of {sel.skew_ns / 1e6:.3f} ms, "
                             f"more than max_skew_ms={max_skew}")
            try:
                frames, images = self._copy(snaps, sel.index)
                break
            except Overwritten as exc:
                log.debug("retrying a request: %s", exc)
        else:
            raise Reject(Code.INTERNAL, f"frames were overwritten {_COPY_ATTEMPTS} times while being copied")
        timing = {
            "received": p.t_received, "waited": t_waited, "searched": t_searched,
            "copied": time.monotonic_ns(),
            "cameras": {c: {"waited": p.ready_at.get(c, t_waited)} for c in p.cameras},
        }
        body = {"op": p.request["op"], "t_request": p.t_star, "frames": frames, "timing": timing}
        if p.request["op"] == "tuple":
            body.update(skew_ns=sel.skew_ns, sync=mode)
        self._reply(p.envelope, p.request, body, images)

    def _check_history(self, p: Pending, snaps: dict) -> None:
        """NO_FRAMES for an empty ring; OUT_OF_RANGE for a t* older than a ring holds."""
        empty = [c for c in p.cameras if not len(snaps[c].timeline)]
        if empty:
            raise Reject(Code.NO_FRAMES, f"camera(s) {empty} have stored no frame yet")
        for cam in p.cameras:
            oldest = snaps[cam].timeline.at(0)
            period = self.cameras[cam].reader.field("period_ns")
            if p.t_star < oldest - period:
                held = len(snaps[cam].timeline)
                raise Reject(Code.OUT_OF_RANGE,
                             f"t* is {(oldest - p.t_star) / 1e6:.1f} ms older than the oldest frame of "
                             f"camera {cam!r}; its ring holds {held} frames, the oldest from "
                             f"{(p.t_received - oldest) / 1e6:.1f} ms before the request")

    def _radius(self, cameras: list[str]) -> int:
        periods = [self.cameras[c].reader.field("period_ns") for c in cameras]
        return max(periods + [0])

    def _copy(self, snaps: dict, index: dict) -> tuple[list, list]:
        frames, images = [], []
        for cam, i in index.items():
            handle = self.cameras[cam]
            try:
                image = handle.reader.copy(snaps[cam], i)
            except Overwritten:
                handle.torn_reads += 1
                raise
            meta = snaps[cam].frame_meta(i)
            frames.append(protocol.frame_meta(cam, meta.frame_id, meta.t_capture, meta.t_stored,
                                              meta.generation, image, len(images)))
            images.append(image)
        return frames, images

    def _op_latest(self, request: dict, t_received: int) -> dict:
        cameras = self._cameras_of(request)
        now = t_received
        for attempt in range(_COPY_ATTEMPTS):
            snaps = self._snapshots(cameras, now)
            empty = [c for c in cameras if not len(snaps[c].timeline)]
            if empty:
                raise Reject(Code.NO_FRAMES, f"camera(s) {empty} have stored no frame yet")
            try:
                frames, images = self._copy(snaps, {c: len(snaps[c].timeline) - 1 for c in cameras})
                break
            except Overwritten:
                continue
        else:
            raise Reject(Code.INTERNAL, "frames kept being overwritten while being copied")
        timing = {"received": now, "copied": time.monotonic_ns()}
        return {"op": "latest", "frames": frames, "timing": timing, "_images": images}

    def _op_status(self, request: dict, t_received: int) -> dict:
        now = time.monotonic_ns()
        return {
            "op": "status",
            "service": self.service,
            "now": now,
            "uptime_s": round((now - self.started_ns) / 1e9, 3),
            "endpoint": self.endpoint,
            "pub": self.pub_endpoint,
            "pending": len(self.pending),
            "requests_served": self.requests_served,
            "settings": self.settings,
            "cameras": {name: cam.status(now) for name, cam in self.cameras.items()},
        }

    def _op_time(self, request: dict, t_received: int) -> dict:
        return {"op": "time", "now": time.monotonic_ns()}

    # ---- replies ----

    def _reply(self, envelope: list, request: dict, body: dict, images: list = ()) -> None:
        images = body.pop("_images", images)
        if "timing" in body:
            body["timing"]["sent"] = time.monotonic_ns()
        self.requests_served += 1
        self._send(envelope, protocol.encode_reply(request["id"], body, images))

    def _send(self, envelope: list, frames: list) -> None:
        try:
            self.router.send_multipart(envelope + frames, copy=False, flags=zmq.NOBLOCK)
        except zmq.Again:
            log.warning("dropped a reply: the client is not reading its replies")
        except zmq.ZMQError as exc:  # EHOSTUNREACH: the client went away
            log.info("could not send a reply: %s", exc)

