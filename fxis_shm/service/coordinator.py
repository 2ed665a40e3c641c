"""The coordinator: one thread, one poll loop around the request engine.

The loop waits on the ROUTER socket (requests from REQ and DEALER clients), the SUB socket
(request events), the XPUB socket (streams and event answers), the frame notifications of
FrameWatch and the replies of the camera workers (fxis_shm.service.serversockets). A request
goes receive -> dispatch (fxis_shm.service.dispatch) -> engine (fxis_shm.core.engine: wait or
answer, and with which frames) -> copy (fxis_shm.shm.copyout) -> reply (fxis_shm.service.outbox).
A request that must wait stays in the engine and is evaluated again when frames arrive or its
wake-up time passes, so it never delays other clients.
"""

from __future__ import annotations

import ctypes
import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any

import zmq
from numpy.typing import NDArray

from fxis_shm.core import timebase
from fxis_shm.core.engine import RequestEngine
from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.dispatch import Received, RequestDispatch
from fxis_shm.service.fastanswers import FastAnswers
from fxis_shm.service.logtally import LogTally
from fxis_shm.service.outbox import Outbox
from fxis_shm.service.serversockets import Access, ServerSockets
from fxis_shm.service.settingsdesk import SettingsDesk
from fxis_shm.service.statusreport import ServiceReports
from fxis_shm.service.streams import Streams
from fxis_shm.shm import fastpick
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.copyout import CopyOut

log = logging.getLogger("coordinator")

# plain ints: their arithmetic is far cheaper than that of pyzmq's enums
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
# glibc's mallopt parameters, and what the coordinator sets them to (see keep_message_memory)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # the largest glibc takes (64-bit): below, from the heap; larger frames: the pool
_TRIM_THRESHOLD = 256 << 20  # freed memory kept for the next messages, as the buffer pool keeps
_IDLE_POLL_MS = 200  # the longest the loop sleeps with nothing due


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


def as_message(data: NDArray[Any]) -> zmq.Frame:
    """A ZeroMQ message holding a copy of ``data`` (the copy out of a ring, made once)."""
    return zmq.Frame(data, copy=True)


class Coordinator:
    """Builds the coordinator's parts (its sockets, the settings desk, the streams, the service's
    reports, the dispatch of requests) around one request engine, and runs the poll loop that
    hands each what arrived for it, until told to stop."""

    def __init__(self, spec: CoordinatorSpec, clock: timebase.Clock = timebase.REAL):
        self.spec = spec
        self.clock = clock  # the loop's "now" (tests/virtualtime drive its engine and streams on a virtual one)
        self.access = Access(spec)
        self.cameras = {
            name: CameraHandle(spec.service, name, kind, spec.history.get(name)) for name, kind in spec.cameras.items()
        }
        self.engine = RequestEngine(self.cameras, spec.settings)
        self.copyout = CopyOut(self.cameras, self.engine.settings)
        self.tally = LogTally()  # what a client does wrong again and again: logged once an interval

    def serve(self, stop: threading.Event, on_ready: Callable[[], None] = lambda: None) -> None:
        """Bind the endpoints (ConfigError if one cannot be), call ``on_ready``, and answer until
        ``stop`` is set; everything opened is closed on the way out."""
        fast = self._fast_answers()
        ctx: zmq.Context[zmq.Socket[bytes]] = zmq.Context()
        try:
            with ServerSockets(ctx, self.spec, self.access) as sockets:
                loop = self._wire(sockets, fast)
                on_ready()
                log.info(
                    "serving %s on %s, publishing on %s, events on %s",
                    sorted(self.cameras),
                    self.spec.endpoint,
                    self.spec.pub,
                    self.spec.events or "-",
                )
                while not stop.is_set():
                    loop.turn()
        finally:
            for cam in self.cameras.values():
                cam.close()
            ctx.term()

    def _fast_answers(self) -> FastAnswers | None:
        """Frames copied out of the rings straight into their messages, and the common requests
        answered by the compiled reader, where malloc keeps the memory of messages sent."""
        if not keep_message_memory():  # a copy into fresh memory would page-fault: into the pool's buffers
            log.info("malloc cannot be told to keep freed memory: frames are sent from pooled buffers")
            return None
        self.copyout.message, self.copyout.message_max = as_message, _MMAP_THRESHOLD
        if not fastpick.AVAILABLE:
            return None
        return FastAnswers(self.cameras, self.engine, self.copyout, as_message, _MMAP_THRESHOLD)

    def _wire(self, sockets: ServerSockets, fast: FastAnswers | None) -> PollLoop:
        """The parts, each given the sockets and the others it uses."""
        outbox = Outbox(sockets.router, sockets.pub, self.tally, self.clock)
        desk = SettingsDesk(self.cameras, outbox.reply, outbox.publish, self.tally, self.clock)
        desk.links = sockets.links
        streams = Streams(self.copyout, outbox.publish)
        reports = ServiceReports(self.spec, self.clock, self.engine, self.copyout, desk, streams, fast)
        dispatch = RequestDispatch(
            self.engine, self.copyout, fast, desk, reports, outbox, sockets.links, self.access, self.tally, self.clock
        )
        # each camera's settings are asked when its worker's link is up (PollLoop: desk.linked)
        return PollLoop(sockets, dispatch, streams, self.engine, self.tally, self.clock)


class PollLoop:
    """One turn of the coordinator's loop at a time: wait on every socket until something
    arrives or the engine or a worker command is due, then hand each socket's messages to
    what takes them, and let the engine and the streams act on new frames and passing time."""

    def __init__(
        self,
        sockets: ServerSockets,
        dispatch: RequestDispatch,
        streams: Streams,
        engine: RequestEngine,
        tally: LogTally,
        clock: timebase.Clock,
    ):
        self.sockets, self.dispatch, self.streams = sockets, dispatch, streams
        self.engine, self.tally, self.clock = engine, tally, clock
        self.poller = zmq.Poller()
        for sock in sockets.polled():
            self.poller.register(sock, zmq.POLLIN)
        # requests are received as frames when each one's key must be known (the operators')
        self._copy_requests = dispatch.access.operators is None

    def turn(self) -> None:
        """Wait for the next thing to do (at most a moment), and do it."""
        sockets, links, now = self.sockets, self.sockets.links, self.clock.now_ns
        events = dict(self.poller.poll(self._timeout_ms()))
        updated = sockets.watch.drain() if sockets.watch.pull in events else set()
        if sockets.pub in events:
            self._drain_subscriptions()
        if sockets.router in events:
            self._drain(sockets.router, self.dispatch.on_request, copy=self._copy_requests)
        if sockets.events is not None and sockets.events in events:
            self._drain(sockets.events, self.dispatch.on_event)
        for sock in links.sockets.values():
            if sock in events:
                links.drain(sock)
        for monitor in links.monitors:
            if monitor in events:
                for camera in links.drain_monitor(monitor):
                    self.dispatch.desk.linked(camera)  # what reads and status answer with until a change
        links.expire(now())
        for line in self.tally.flush(now()):
            log.info("%s", line)
        if updated or self._due():
            self.dispatch.carry_out(self.engine.on_frames(updated, now()))
        if updated:
            self.streams.on_frames(updated, now())

    def _timeout_ms(self) -> int:
        wakes = [t for t in (self.engine.next_wake(), self.sockets.links.next_deadline()) if t]
        wake = min(wakes, default=None)
        if wake is None:
            return _IDLE_POLL_MS
        return max(0, min(_IDLE_POLL_MS, (wake - self.clock.now_ns()) // 1_000_000 + 1))

    def _due(self) -> bool:
        wake = self.engine.next_wake()
        return wake is not None and wake <= self.clock.now_ns()

    def _drain_subscriptions(self) -> None:
        while True:
            try:
                message = self.sockets.pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if message and message[0] in (0, 1):
                self.streams.subscription(message[1:].decode(errors="replace"), message[0] == 1)

    def _drain(
        self,
        sock: zmq.Socket[bytes],
        handle: Callable[[Sequence[Received], int], None],
        budget: int = 256,
        copy: bool = True,
    ) -> None:
        for _ in range(budget):
            if not int(sock.getsockopt(_EVENTS)) & _POLLIN:  # (cheaper than the exception of an empty recv)
                return
            try:
                frames = sock.recv_multipart(zmq.NOBLOCK, copy=copy)
            except zmq.Again:
                return
            try:
                handle(frames, self.clock.now_ns())
            except Exception:  # no message may take the service down
                log.exception("a message could not be handled; dropped")
