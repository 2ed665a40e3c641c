"""The coordinator: the sockets and the poll loop around the request engine.

One thread runs one poll loop over the ROUTER socket (requests from REQ and
DEALER clients), the SUB socket (request events), the XPUB socket (streams
and event answers) and the frame notifications of FrameWatch. A request goes
receive -> engine (fxis_shm.core.engine: wait or answer, and with which frames) ->
copy (fxis_shm.shm.copyout) -> reply. A request that must wait stays in the engine
and is evaluated again when frames arrive or its wake-up time passes, so it
never delays other clients.
"""

from __future__ import annotations

import ctypes
import json
import logging
import threading
from collections.abc import Callable

import zmq
import zmq.auth
from zmq.auth.certs import load_certificates
from zmq.auth.thread import ThreadAuthenticator

from fxis_shm.core import timebase
from fxis_shm.core.engine import FRAME_OPS, Action, Failure, Pending, Reply, RequestEngine, Schedule, Trigger
from fxis_shm.errors import Code, ConfigError, ProtocolError
from fxis_shm.service import realtime
from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.fastanswers import FastAnswers
from fxis_shm.service.framewatch import FrameWatch
from fxis_shm.service.logtally import LogTally
from fxis_shm.service.settingsdesk import SettingsDesk
from fxis_shm.service.streams import Streams
from fxis_shm.service.workerlink import WorkerLinks
from fxis_shm.shm import fastpick, naming, ordering
from fxis_shm.shm.cameras import FRAME_FIELDS, CameraHandle
from fxis_shm.shm.copyout import MESSAGES, REFS, CopyOut
from fxis_shm.shm.localpath import boot_id, time_namespace
from fxis_shm.shm.ring import Overwritten
from fxis_shm.wire import commands, protocol
from fxis_shm.wire.multipart import send_parts
from fxis_shm.wire.security import load_pair, make_server

log = logging.getLogger("coordinator")

_PUB_QUEUE = 16  # messages queued per subscriber; beyond, that subscriber loses messages
MAX_MESSAGE_BYTES = 1 << 20  # a peer sending more is disconnected by ZeroMQ
# plain ints: their arithmetic is far cheaper than that of pyzmq's enums
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
# glibc's mallopt parameters, and what the coordinator sets them to (see keep_message_memory)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # the largest glibc takes (64-bit): below, from the heap; larger frames: the pool
_TRIM_THRESHOLD = 256 << 20  # freed memory kept for the next messages, as the buffer pool keeps


FORBIDDEN_TEXT = (
    "this client may read settings but not change them: the service lets only the keys in its "
    "--curve-operators folder change them; ask its operator to add this client's public key (.key) "
    "there and restart the service, or use a key that is there"
)


def keep_message_memory() -> bool:
    """Let malloc keep the memory of the messages sent for the next ones (True if it could be
    told). A frame is copied out of its ring straight into the ZeroMQ message that carries it,
    which libzmq allocates with malloc; glibc would serve each such block (above 128 KiB) with
    fresh pages from the kernel and return them when the message is freed, so every copy would
    page-fault on every page (a 1360x1024 frame: 340 faults, costing more than the copy). Told
    not to, it reuses the memory of the messages already sent, already mapped, as the buffer pool
    reuses its buffers. Elsewhere (another C library) nothing is changed."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


def as_message(data) -> zmq.Frame:
    """A ZeroMQ message holding a copy of ``data`` (the copy out of a ring, made once)."""
    return zmq.Frame(data, copy=True)


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


def _readable_field(frame: bytes, name: str, kinds: tuple):
    """A field of a header we could not decode, if it is there and readable."""
    try:
        value = json.loads(bytes(frame)).get(name)
        return value if isinstance(value, kinds) and not isinstance(value, bool) else None
    except Exception:
        return None


class AllowedKeys:
    """Who may connect under CurveZMQ: the clients whose public keys are in the folder, and the
    service itself, whose viewers (dashboard, Foxglove server, ROS 2 bridge) connect with its
    own pair (ViewerSpec.client_keys). Read once, at start."""

    def __init__(self, pair: tuple[bytes, bytes], folder: str, operators: set[bytes] = frozenset()):
        self.keys = set(load_certificates(folder)) | {pair[0]} | operators  # operators are let in too

    def callback(self, domain: str, key: bytes) -> bool:
        return key in self.keys


class Coordinator:
    def __init__(self, spec: CoordinatorSpec, clock: timebase.Clock = timebase.REAL):
        self.clock = clock  # the loop's "now" (tests/virtualtime drive its engine and streams on a virtual one)
        self.service = spec.service
        self.endpoint = spec.endpoint
        self.pub_endpoint = spec.pub
        self.events_endpoint = spec.events
        self.curve = None
        self.operators: set[str] | None = None  # the keys (Z85) that may change settings; None: every client
        if spec.curve_secret:
            self.curve = (load_pair(spec.curve_secret), spec.curve_clients)
            if spec.curve_operators:  # the service's own key too: its dashboard connects with it
                self.operators = {k.decode() for k in load_certificates(spec.curve_operators)}
                self.operators.add(self.curve[0][0].decode())
        self.cameras = {
            name: CameraHandle(self.service, name, kind, spec.history.get(name)) for name, kind in spec.cameras.items()
        }
        self.engine = RequestEngine(self.cameras, spec.settings)
        self.settings = self.engine.settings
        self.copyout = CopyOut(self.cameras, self.settings)
        self.fast: FastAnswers | None = None
        self.started_ns = self.clock.now_ns()
        self.requests_served = 0
        self.events_dropped = 0
        self.boot_id = boot_id()
        self.time_namespace = time_namespace()
        self.tally = LogTally()  # what a client does wrong again and again: logged once an interval
        self.desk = SettingsDesk(self.cameras, self._reply, self._publish, self.tally, self.clock)
        self.links: WorkerLinks | None = None

    # ---- the loop ----

    def serve(self, stop: threading.Event, on_ready: Callable[[], None] = lambda: None) -> None:
        ctx = zmq.Context()
        closing = []
        if keep_message_memory():  # frames are copied out of the rings straight into their messages
            self.copyout.message, self.copyout.message_max = as_message, _MMAP_THRESHOLD
            if fastpick.AVAILABLE:  # the common requests answered by the compiled reader
                self.fast = FastAnswers(self.cameras, self.engine, self.copyout, as_message, _MMAP_THRESHOLD)
        else:  # a copy into fresh memory would page-fault: into the pre-faulted buffers of the pool
            log.info("malloc cannot be told to keep freed memory: frames are sent from pooled buffers")
        try:
            if self.curve is not None:  # only clients whose public keys are in the folder
                auth = ThreadAuthenticator(ctx, log=logging.getLogger("auth"))
                auth.start()
                allowed = AllowedKeys(*self.curve, operators={k.encode() for k in self.operators or ()})
                auth.configure_curve_callback(domain="*", credentials_provider=allowed)
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
            self.links = self.desk.links = links = WorkerLinks(ctx, self.service, list(self.cameras))
            closing.append(links)
            self.streams = Streams(self.copyout, self._publish)
            poller = zmq.Poller()
            for sock in (self.router, self.pub, self.events, watch.pull, *links.sockets.values(), *links.monitors):
                if sock is not None:
                    poller.register(sock, zmq.POLLIN)
            on_ready()  # each camera's settings are asked when its link is up (desk.linked)
            log.info(
                "serving %s on %s, publishing on %s, events on %s",
                sorted(self.cameras),
                self.endpoint,
                self.pub_endpoint,
                self.events_endpoint or "-",
            )
            while not stop.is_set():
                events = dict(poller.poll(self._poll_timeout_ms()))
                updated = watch.drain() if watch.pull in events else set()
                if self.pub in events:
                    self._drain_subscriptions()
                if self.router in events:  # (as frames when each request's key must be known)
                    self._drain(self.router, self._on_request, copy=self.operators is None)
                if self.events is not None and self.events in events:
                    self._drain(self.events, self._on_event)
                for sock in links.sockets.values():
                    if sock in events:
                        links.drain(sock)
                for monitor in links.monitors:
                    if monitor in events:
                        for camera in links.drain_monitor(monitor):
                            self.desk.linked(camera)  # what reads and status answer with until a change
                links.expire(self.clock.now_ns())
                for line in self.tally.flush(self.clock.now_ns()):
                    log.info("%s", line)
                if updated or self._due():
                    self._carry_out(self.engine.on_frames(updated, self.clock.now_ns()))
                if updated:
                    self.streams.on_frames(updated, self.clock.now_ns())
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
            raise ConfigError(f"cannot bind the {what} {endpoint}: {exc}") from None
        return sock

    def _poll_timeout_ms(self) -> int:
        wakes = [t for t in (self.engine.next_wake(), self.links.next_deadline() if self.links else None) if t]
        wake = min(wakes, default=None)
        if wake is None:
            return 200
        return max(0, min(200, (wake - self.clock.now_ns()) // 1_000_000 + 1))

    def _due(self) -> bool:
        wake = self.engine.next_wake()
        return wake is not None and wake <= self.clock.now_ns()

    def _drain_subscriptions(self) -> None:
        while True:
            try:
                message = self.pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if message and message[0] in (0, 1):
                self.streams.subscription(message[1:].decode(errors="replace"), message[0] == 1)

    def _drain(self, sock, handle, budget: int = 256, copy: bool = True) -> None:
        for _ in range(budget):
            if not sock.getsockopt(_EVENTS) & _POLLIN:  # (cheaper than the exception of an empty recv)
                return
            try:
                frames = sock.recv_multipart(zmq.NOBLOCK, copy=copy)
            except zmq.Again:
                return
            try:
                handle(frames, self.clock.now_ns())
            except Exception:  # no message may take the service down
                log.exception("a message could not be handled; dropped")

    # ---- requests and events ----

    def _on_request(self, frames: list, t_received: int) -> None:
        envelope, body = split_envelope(frames)
        respond = lambda reply: self._send(envelope, reply)  # noqa: E731
        try:
            request = protocol.decode_request(body)
        except ProtocolError as exc:
            for line in self.tally.note("bad requests", f"bad request: {exc.message}", t_received):
                log.info("%s", line)
            rid = _readable_field(body[0], "id", (int, str)) if body else None
            respond(protocol.encode_error(rid, exc.code, exc.message))
            return
        if request["op"] == "settings" and request["set"] and not self._may_change(body[0]):
            respond(protocol.encode_error(request["id"], Code.FORBIDDEN, FORBIDDEN_TEXT))
            return
        self._start(request, respond, t_received, client=bytes(envelope[0]))

    def _may_change(self, frame) -> bool:
        """May the client that sent ``frame`` change camera settings? Everyone, unless the service
        names its operators: then only their keys (CurveZMQ's User-Id of the message)."""
        return self.operators is None or (isinstance(frame, zmq.Frame) and frame.get("User-Id") in self.operators)

    def _on_event(self, frames: list, t_received: int) -> None:
        try:
            request = protocol.decode_event(frames)
        except ProtocolError as exc:
            topic = _readable_field(frames[-1], "reply_topic", (str,)) if frames else None
            if topic and not topic.startswith(protocol.RESERVED_TOPICS):
                self._publish(
                    topic, protocol.encode_error(_readable_field(frames[-1], "id", (int, str)), exc.code, exc.message)
                )
            else:
                self.events_dropped += 1
            dropped = f"dropped a malformed request event: {exc.message}"
            for line in self.tally.note("malformed events", dropped, t_received):
                log.warning("%s", line)
            return
        topic = request["reply_topic"]
        self._start(request, lambda reply: self._publish(topic, reply), t_received)

    def _start(
        self, request: dict, respond: Callable[[list], None], t_received: int, client: bytes | None = None
    ) -> None:
        op = request["op"]
        try:
            if op == "settings":  # a read at once, a change when the camera's worker has applied it
                self.desk.request(request, respond)
                return
            if op not in FRAME_OPS:
                self._reply(respond, request, getattr(self, f"_op_{op}")(request, t_received))
                return
            local = self.boot_id is not None and request.get("local") == self.boot_id
            answer = self.fast.answer(request, t_received, client) if self.fast is not None and not local else None
            if answer is not None:  # (already encoded, "sent" stamped)
                self.requests_served += 1
                respond(answer)
                return
            self._carry_out(self.engine.submit(request, t_received, respond, client=client, local=local))
        except ProtocolError as exc:  # a request that cannot be answered as asked
            respond(protocol.encode_error(request["id"], exc.code, exc.message))
        except Exception as exc:  # a bug must not take the service down
            log.exception("internal error on %s", op)
            respond(protocol.encode_error(request["id"], Code.INTERNAL, repr(exc)))

    def _carry_out(self, actions: list[Action]) -> None:
        """Do what the engine decided: fire triggers, copy frames out and reply, or fail."""
        for action in actions:
            if isinstance(action, Trigger):
                for cam in action.cameras:
                    self.cameras[cam].fire_trigger()
            elif isinstance(action, Schedule):
                self._schedule(action)
            elif isinstance(action, Failure):
                action.pending.ticket(protocol.encode_error(action.pending.id, action.code, action.message))
            else:
                self._answer(action)

    def _schedule(self, action: Schedule) -> None:
        """Have each camera's worker trigger it for a capture at ``action.t``; the first refusal
        fails the request (the engine waits for the frames captured for T meanwhile)."""
        assert self.links is not None
        for cam in action.cameras:
            self.links.send(
                cam, commands.TRIGGER_AT, commands.TRIGGER_TIMEOUT_S, self._scheduled(action.pending, cam), t=action.t
            )

    def _scheduled(self, pending: Pending, camera: str):
        def done(result: dict | None, code: str | None, message: str | None) -> None:
            if result is None:
                self._carry_out(self.engine.fail(pending, code or Code.INTERNAL, f"camera {camera!r}: {message}"))

        return done

    def _answer(self, reply: Reply) -> None:
        try:
            body, images = self.copyout.reply(reply, REFS if reply.pending.local else MESSAGES)
        except Overwritten:  # the ring came round during the copy: the engine plans again
            self._carry_out(self.engine.retry(reply, self.clock.now_ns()))
            return
        self._reply(reply.pending.ticket, reply.pending.request, body, images)

    def _op_status(self, request: dict, t_received: int) -> dict:
        now, supervisor = self.clock.now_ns(), realtime.with_scheduling(self._state_of("supervisor"))
        return {
            "op": "status",
            "service": self.service,
            "now": now,
            "boot_id": self.boot_id,
            "time_namespace": self.time_namespace,
            "clock": timebase.wire_name(),  # the header's spelling (issue 43)
            "encoded": self.copyout.encoded.status(),
            "ring_ordering": ordering.MODE,
            "uptime_s": round((now - self.started_ns) / 1e9, 3),
            "endpoint": self.endpoint,
            "pub": self.pub_endpoint,
            "events": self.events_endpoint,
            "pending": len(self.engine.pending),
            "requests_served": self.requests_served,
            "requests_compiled": self.fast.answered if self.fast is not None else 0,
            "events_dropped": self.events_dropped,
            "streams": self.streams.status(),
            "supervisor": supervisor,
            "ros2": self._state_of("ros2"),
            "settings": self.settings,
            "cameras": self._camera_status(now, (supervisor or {}).get("processes", {})),
        }

    def _camera_status(self, now: int, processes: dict) -> dict:
        cameras = {name: cam.status(now) for name, cam in self.cameras.items()}
        for name, info in cameras.items():
            process = processes.get(f"camera:{name}", {})
            info["restarts"], info["sched"] = process.get("restarts"), process.get("sched")
            info["settings"] = self.desk.values(name, info.get("generation"))
            if info.get("trigger") == "software" and info.get("fps") is None:  # captures on request: its set rate
                info["fps"] = (info["settings"] or {}).get("fps")
            info["ptp"] = self.desk.ptp(name)  # None: the camera cannot say (or not yet asked)
        return cameras

    def _state_of(self, process: str) -> dict | None:
        """What the supervisor or the ROS 2 bridge last reported (None: nothing)."""
        try:
            with open(naming.state_path(self.service, process)) as f:
                return json.load(f)
        except (OSError, ValueError):
            return None

    def _op_time(self, request: dict, t_received: int) -> dict:
        """The clock now, and when the request was received: a caller estimating our clock
        against its own takes both (an NTP-style exchange of four timestamps)."""
        return {"op": "time", "received": t_received, "now": self.clock.now_ns(), "boot_id": self.boot_id}

    def _op_frames(self, request: dict, t_received: int) -> dict:
        """Every camera's frame times without pixels, for callers that choose frames
        themselves (a client over several services)."""
        names = request["cameras"] or list(self.cameras)
        unknown = [n for n in names if n not in self.cameras]
        if unknown:
            raise ProtocolError(f"unknown camera(s) {unknown}; known: {sorted(self.cameras)}", Code.UNKNOWN_CAMERA)
        now = self.clock.now_ns()
        return {
            "op": "frames",
            "now": now,
            "columns": list(FRAME_FIELDS),
            "cameras": {n: self.cameras[n].timeline(now) for n in names},
        }

    # ---- replies ----

    def _reply(self, respond, request: dict, body: dict, images: list = ()) -> None:
        if "timing" in body:
            body["timing"]["sent"] = self.clock.now_ns()
        self.requests_served += 1
        respond(protocol.encode_reply(request["id"], body, images))

    def _send(self, envelope: list, frames: list) -> None:
        try:
            send_parts(self.router, envelope + frames)
        except zmq.Again:
            dropped = "dropped a reply: the client is not reading its replies"
            for line in self.tally.note("dropped replies", dropped, self.clock.now_ns()):
                log.warning("%s", line)
        except zmq.ZMQError as exc:  # EHOSTUNREACH: the client went away
            log.info("could not send a reply: %s", exc)

    def _publish(self, topic: str, frames: list) -> None:
        try:  # a subscriber whose queue is full loses this message; nobody waits
            send_parts(self.pub, [topic.encode(), *frames])
        except zmq.ZMQError as exc:
            log.debug("could not publish on %s: %s", topic, exc)
