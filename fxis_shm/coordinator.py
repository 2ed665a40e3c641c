"""The coordinator: reads every camera's ring and answers requests.

One thread runs one poll loop over the ROUTER socket (requests from REQ and
DEALER clients), the SUB socket (request events), the XPUB socket (streams
and event answers) and the frame notifications of FrameWatch. A request that
must wait for frames is parked and re-evaluated when frames arrive or its next
deadline passes, so it never delays other clients.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from typing import Callable

import zmq
from zmq.auth.thread import ThreadAuthenticator

from . import naming, protocol, sequences
from .answers import Answers, NotReady, Pending, Reject
from .cameras import CameraHandle
from .errors import Code, ProtocolError
from .framewatch import FrameWatch
from .localpath import boot_id
from .security import load_pair, make_server
from .streams import Streams
from .waitpolicy import AUTO, NEXT, NONE, waiting_for, waiting_for_selection

log = logging.getLogger("coordinator")

DEFAULTS = {
    "sync": "joint",
    "wait": "auto",
    "timeout_ms": 1000.0,
    "max_skew_ms": None,
    "horizon_ms": 10_000.0,
    "sync_tolerance_ms": 2.0,  # above cameras' jitter range, far below a frame period
    "max_pending": 1000,
    "max_pending_per_client": 100,
    "max_sequence_frames": 500,
}
_LIVENESS_CHECK_NS = 100_000_000  # waiting requests notice a dead camera this fast
_PUB_QUEUE = 16  # messages queued per subscriber; beyond, that subscriber loses messages
MAX_MESSAGE_BYTES = 1 << 20  # a peer sending more is disconnected by ZeroMQ


class _Stopping:
    """Gives the authenticator thread the close() the shutdown loop calls."""

    def __init__(self, auth):
        self.auth = auth

    def close(self) -> None:
        self.auth.stop()


def split_envelope(frames: list) -> tuple[list, list]:
    """ROUTER frames -> (routing envelope incl. the empty delimiter, body)."""
    for i in range(1, len(frames)):
        if len(frames[i]) == 0:
            return frames[: i + 1], frames[i + 1 :]
    return frames[:1], frames[1:]


def send_parts(sock: zmq.Socket, parts: list) -> None:
    """One multipart message, without blocking: image buffers handed to ZeroMQ
    without a copy, small byte strings copied (cheaper than tracking them)."""
    last = len(parts) - 1
    for i, part in enumerate(parts):
        flags = zmq.NOBLOCK | (zmq.SNDMORE if i < last else 0)
        sock.send(part, flags, copy=isinstance(part, (bytes, zmq.Frame)))


def _readable_field(frame: bytes, name: str, kinds: tuple):
    """A field of a header we could not decode, if it is there and readable."""
    try:
        value = json.loads(bytes(frame)).get(name)
        return value if isinstance(value, kinds) and not isinstance(value, bool) else None
    except Exception:
        return None


class Coordinator:
    def __init__(self, spec: dict):
        self.service = spec["service"]
        self.endpoint = spec["endpoint"]
        self.pub_endpoint = spec["pub"]
        self.events_endpoint = spec.get("events")
        self.curve = None
        if spec.get("curve_secret"):
            self.curve = (load_pair(spec["curve_secret"]), spec["curve_clients"])
        self.settings = {**DEFAULTS, **spec.get("settings", {})}
        self.cameras = {
            name: CameraHandle(self.service, name, cam["kind"])
            for name, cam in spec["cameras"].items()
        }
        self.answers = Answers(self.cameras, self.settings)
        self.pending: list[Pending] = []
        self.started_ns = time.monotonic_ns()
        self.requests_served = 0
        self.events_dropped = 0
        self.boot_id = boot_id()

    # ---- the loop ----

    def serve(self, stop: threading.Event, on_ready: Callable[[], None] = lambda: None) -> None:
        ctx = zmq.Context()
        closing = []
        try:
            if self.curve is not None:  # only clients whose public keys are in the folder
                auth = ThreadAuthenticator(ctx, log=logging.getLogger("auth"))
                auth.start()
                auth.configure_curve(domain="*", location=self.curve[1])
                closing.append(_Stopping(auth))
            self.router = self._socket(ctx, zmq.ROUTER, self.endpoint, "request endpoint", closing)
            self.router.setsockopt(zmq.ROUTER_MANDATORY, 1)  # report unsendable replies
            self.pub = self._socket(ctx, zmq.XPUB, self.pub_endpoint, "publish endpoint", closing)
            self.events = None
            if self.events_endpoint:
                self.events = self._socket(ctx, zmq.SUB, self.events_endpoint, "events endpoint", closing)
                self.events.setsockopt(zmq.SUBSCRIBE, protocol.EVENT_TOPIC)
            watch = FrameWatch(ctx, self.service, list(self.cameras))
            closing.append(watch)
            self.streams = Streams(self.answers, self._publish)
            poller = zmq.Poller()
            for sock in (self.router, self.pub, self.events, watch.pull):
                if sock is not None:
                    poller.register(sock, zmq.POLLIN)
            on_ready()
            log.info("serving %s on %s, publishing on %s, events on %s", sorted(self.cameras),
                     self.endpoint, self.pub_endpoint, self.events_endpoint or "-")
            while not stop.is_set():
                events = dict(poller.poll(self._poll_timeout_ms()))
                updated = watch.drain() if watch.pull in events else set()
                if self.pub in events:
                    self._drain_subscriptions()
                if self.router in events:
                    self._drain(self.router, self._on_request)
                if self.events is not None and self.events in events:
                    self._drain(self.events, self._on_event)
                self._advance_pending(updated)
                if updated:
                    self.streams.on_frames(updated, time.monotonic_ns())
        finally:
            for sock in reversed(closing):
                sock.close()
            for cam in self.cameras.values():
                cam.close()
            ctx.term()

    def _socket(self, ctx, kind, endpoint: str, what: str, closing: list):
        sock = ctx.socket(kind)
        closing.append(sock)
        sock.setsockopt(zmq.LINGER, 0)
        if self.curve is not None:
            make_server(sock, *self.curve[0])
        sock.setsockopt(zmq.SNDHWM, _PUB_QUEUE if kind == zmq.XPUB else 100)
        sock.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        try:
            sock.bind(endpoint)
        except zmq.ZMQError as exc:
            raise RuntimeError(f"cannot bind the {what} {endpoint}: {exc}") from None
        return sock

    def _poll_timeout_ms(self) -> int:
        if not self.pending:
            return 200
        wake = min(p.wake_at for p in self.pending)
        return max(0, min(200, (wake - time.monotonic_ns()) // 1_000_000 + 1))

    def _drain_subscriptions(self) -> None:
        while True:
            try:
                message = self.pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if message and message[0] in (0, 1):
                self.streams.subscription(message[1:].decode(errors="replace"), message[0] == 1)

    @staticmethod
    def _drain(sock, handle, budget: int = 256) -> None:
        for _ in range(budget):
            try:
                frames = sock.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            try:
                handle(frames, time.monotonic_ns())
            except Exception:  # no message may take the service down
                log.exception("a message could not be handled; dropped")

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

    # ---- requests and events ----

    def _on_request(self, frames: list, t_received: int) -> None:
        envelope, body = split_envelope(frames)
        respond = lambda reply: self._send(envelope, reply)  # noqa: E731
        respond.client = bytes(envelope[0])  # for the per-client limit
        try:
            request = protocol.decode_request(body)
        except ProtocolError as exc:
            log.info("bad request: %s", exc.message)
            rid = _readable_field(body[0], "id", (int, str)) if body else None
            respond(protocol.encode_error(rid, exc.code, exc.message))
            return
        self._start(request, respond, t_received)

    def _on_event(self, frames: list, t_received: int) -> None:
        try:
            request = protocol.decode_event(frames)
        except ProtocolError as exc:
            topic = _readable_field(frames[-1], "reply_topic", (str,)) if frames else None
            if topic and not topic.startswith(protocol.RESERVED_TOPICS):
                self._publish(topic, protocol.encode_error(
                    _readable_field(frames[-1], "id", (int, str)), exc.code, exc.message))
            else:
                self.events_dropped += 1
            log.warning("dropped a malformed request event: %s", exc.message)
            return
        topic = request["reply_topic"]
        self._start(request, lambda reply: self._publish(topic, reply), t_received)

    def _start(self, request: dict, respond: Callable[[list], None], t_received: int) -> None:
        op = request["op"]
        try:
            if op in ("status", "time"):
                body = getattr(self, f"_op_{op}")()
                self._reply(respond, request, body)
                return
            p = self._pending(request, respond, t_received)
            # First evaluation at the arrival time: a request that need not wait records no wait.
            if not self._advance(p, t_received):
                self.pending.append(p)
        except Reject as exc:
            respond(protocol.encode_error(request["id"], exc.code, exc.message))
        except Exception as exc:  # a bug must not take the service down
            log.exception("internal error on %s", op)
            respond(protocol.encode_error(request["id"], Code.INTERNAL, repr(exc)))

    def _cameras_of(self, request: dict) -> list[str]:
        if request.get("camera") is not None:
            names = [request["camera"]]
        else:
            names = request.get("cameras") or list(self.cameras)
        unknown = [n for n in names if n not in self.cameras]
        if unknown:
            raise Reject(Code.UNKNOWN_CAMERA,
                         f"unknown camera(s) {unknown}; this service has {sorted(self.cameras)}")
        return names

    def _pending(self, request: dict, respond, t_received: int) -> Pending:
        cameras = self._cameras_of(request)
        if len(self.pending) >= self.settings["max_pending"]:
            raise Reject(Code.BUSY, f"{len(self.pending)} requests are waiting already; try again")
        client = getattr(respond, "client", None)
        limit = self.settings["max_pending_per_client"]
        if client is not None and sum(getattr(q.respond, "client", None) == client for q in self.pending) >= limit:
            raise Reject(Code.BUSY, f"this client has {limit} requests waiting already (the limit)")
        missing = []
        if request.get("partial"):  # leave out the cameras that are down, and say which
            now = time.monotonic_ns()
            missing = [c for c in cameras if self.cameras[c].down_reason(now)]
            cameras = [c for c in cameras if c not in missing]
            if not cameras:
                raise Reject(Code.CAMERA_DOWN, f"every requested camera is down: {missing}")
        t_star = request.get("at")
        t_star = t_received if t_star is None else t_star
        local = self.boot_id is not None and request.get("local") == self.boot_id
        p = Pending(respond, request, cameras, t_received, t_star, missing=missing, local=local)
        horizon = int(self.settings["horizon_ms"] * 1e6)
        if self._latest_needed(p, 0) - t_received > horizon:
            raise Reject(Code.OUT_OF_RANGE,
                         f"the request needs frames {(self._latest_needed(p, 0) - t_received) / 1e6:.1f} ms "
                         f"in the future; the horizon is {self.settings['horizon_ms']} ms")
        if p.op == "sequence":
            self._check_sequence(p)
        timeout = int(self.answers.setting(request, "timeout_ms") * 1e6)
        p.deadline = max(t_received, self._latest_needed(p, 0)) + timeout
        if p.op in ("image", "tuple") and request.get("at") is None:
            self._trigger(p)
        return p

    def _trigger(self, p: Pending) -> None:
        """Trigger the request's software-triggered cameras at once (t* = the trigger)."""
        triggered = [c for c in p.cameras if self.cameras[c].ring() is not None and self.cameras[c].triggered]
        if not triggered:
            return
        p.t_trigger = p.t_star = time.monotonic_ns()
        for cam in triggered:
            self.cameras[cam].fire_trigger()
        p.triggered = frozenset(triggered)

    def _check_sequence(self, p: Pending) -> None:
        r = p.request
        if r["count"] is not None:
            self.answers.check_size(r["count"] * len(p.cameras))
            slots = min((h.reader.slots for h in map(self.cameras.get, p.cameras) if h.ring()), default=None)
            if r["kind"] == "consecutive" and slots is not None and r["count"] >= slots:
                # the oldest slot is always the next one overwritten: one fewer is guaranteed
                raise Reject(Code.OUT_OF_RANGE,
                             f"asks for {r['count']} consecutive frames; rings of {slots} slots "
                             f"hold at most {slots - 1} consecutive frames that can always be read")

    def _latest_needed(self, p: Pending, period_ns: int) -> int:
        """The latest capture time the request needs frames up to."""
        if p.op != "sequence":
            return p.t_star
        return sequences.latest_needed(self.answers.sequence_spec(p), period_ns)

    def _advance(self, p: Pending, now: int) -> bool:
        """Answer ``p`` if it can be answered now; True once it got its reply."""
        try:
            waits, states, snaps = self._waits(p, now)
            for cam in p.cameras:
                if cam not in waits:  # ready now, or when a frame that raced the request landed
                    stored = states[cam].newest_stored if cam in states else None
                    p.ready_at.setdefault(cam, max(now, stored or now))
            if not waits:
                try:
                    self._answer(p, now, snaps)
                    return True
                except NotReady as exc:
                    waits = {c: None for c in p.cameras}
                    reason = str(exc)
            else:
                reason = f"the frames awaited from {sorted(waits)}"
            if now >= p.deadline:
                raise Reject(Code.TIMEOUT, f"{reason} did not arrive within "
                                           f"{(p.deadline - max(p.t_received, p.t_star)) / 1e6:.0f} ms")
            give_ups = [t for t in waits.values() if t is not None]
            p.wake_at = min([p.deadline, now + _LIVENESS_CHECK_NS, *give_ups])
            return False
        except Reject as exc:
            p.respond(protocol.encode_error(p.request["id"], exc.code, exc.message))
        except Exception as exc:
            log.exception("internal error on %s", p.op)
            p.respond(protocol.encode_error(p.request["id"], Code.INTERNAL, repr(exc)))
        return True

    def _waits(self, p: Pending, now: int) -> tuple[dict, dict, dict | None]:
        """Cameras still waited for (see waitpolicy), and the camera states and snapshots seen."""
        if p.op == "latest":
            return {}, {}, None
        snaps = self.answers.snapshots_allowing_empty(p.cameras, now)
        waits, states = self._waits_seen(p, now, snaps)
        return waits, states, snaps

    def _waits_seen(self, p: Pending, now: int, snaps: dict) -> tuple[dict, dict]:
        states = {c: self.cameras[c].state(snaps[c]) for c in p.cameras}
        if p.op == "sequence":
            waits = {}
            for cam, state in states.items():
                t_needed = self._latest_needed(p, state.period_ns)
                waits.update(waiting_for(AUTO, t_needed, now, {cam: state}))
            return waits, states
        mode = self.answers.setting(p.request, "wait")
        if p.triggered:  # the triggered frames, and the others' frames around the trigger
            free = {c: s for c, s in states.items() if c not in p.triggered}
            waits = waiting_for(AUTO, p.t_star, now, free)
            waits.update(waiting_for(NEXT, p.t_star, now,
                                     {c: states[c] for c in p.triggered}, t_arrival=p.t_trigger))
            return waits, states
        if mode == NEXT:
            waits = waiting_for(NEXT, p.t_star, now, states, t_arrival=p.t_received)
            if p.t_star > now:  # a future t*: also reach the frames around it
                waits.update(waiting_for(AUTO, p.t_star, now, states))
            return waits, states
        if mode == NONE:
            return {}, states
        sync = self.answers.sync_mode(p)
        return waiting_for_selection(
            p.t_star, now, {c: snaps[c].timeline for c in p.cameras}, states,
            lambda timelines: self.answers.select_frames(sync, timelines, p.t_star),
            self.answers.radius(p.cameras), self.answers.tolerance(p.cameras),
        ), states

    def _answer(self, p: Pending, t_waited: int, snaps: dict | None = None) -> None:
        build = {"image": self.answers.frames_near, "tuple": self.answers.frames_near,
                 "latest": self.answers.latest, "sequence": self.answers.sequence}[p.op]
        body, images = self.answers.with_retries(p.cameras, t_waited, lambda s: build(p, s), snaps)
        body["timing"].update(received=p.t_received, waited=t_waited, copied=time.monotonic_ns())
        if p.local:
            body["delivery"] = protocol.LOCAL
        body["timing"]["cameras"] = {c: {"waited": p.ready_at.get(c, t_waited)} for c in p.cameras}
        self._reply(p.respond, p.request, body, images)

    def _op_status(self) -> dict:
        now = time.monotonic_ns()
        return {
            "op": "status",
            "service": self.service,
            "now": now,
            "boot_id": self.boot_id,
            "uptime_s": round((now - self.started_ns) / 1e9, 3),
            "endpoint": self.endpoint,
            "pub": self.pub_endpoint,
            "events": self.events_endpoint,
            "pending": len(self.pending),
            "requests_served": self.requests_served,
            "events_dropped": self.events_dropped,
            "streams": self.streams.status(),
            "supervisor": self._supervisor_state(),
            "settings": self.settings,
            "cameras": self._camera_status(now),
        }

    def _camera_status(self, now: int) -> dict:
        processes = (self._supervisor_state() or {}).get("processes", {})
        cameras = {name: cam.status(now) for name, cam in self.cameras.items()}
        for name, info in cameras.items():
            info["restarts"] = processes.get(f"camera:{name}", {}).get("restarts")
        return cameras

    def _supervisor_state(self) -> dict | None:
        try:
            with open(naming.supervisor_state_path(self.service)) as f:
                return json.load(f)
        except (OSError, ValueError):
            return None

    def _op_time(self) -> dict:
        return {"op": "time", "now": time.monotonic_ns(), "boot_id": self.boot_id}

    # ---- replies ----

    def _reply(self, respond, request: dict, body: dict, images: list = ()) -> None:
        if "timing" in body:
            body["timing"]["sent"] = time.monotonic_ns()
        self.requests_served += 1
        respond(protocol.encode_reply(request["id"], body, images))

    def _send(self, envelope: list, frames: list) -> None:
        try:
            send_parts(self.router, envelope + frames)
        except zmq.Again:
            log.warning("dropped a reply: the client is not reading its replies")
        except zmq.ZMQError as exc:  # EHOSTUNREACH: the client went away
            log.info("could not send a reply: %s", exc)

    def _publish(self, topic: str, frames: list) -> None:
        try:  # a subscriber whose queue is full loses this message; nobody waits
            send_parts(self.pub, [topic.encode(), *frames])
        except zmq.ZMQError as exc:
            log.debug("could not publish on %s: %s", topic, exc)
