"""Publish/subscribe: receive streams and event answers, publish request events.

with Subscriber("tcp://127.0.0.1:5556") as sub:
    sub.tuples(rate_hz=5)               # synchronized tuples, 5 per second
    for message in sub:                 # raises RequestTimeout after ``timeout``
        print(message.seq, message.tuple.skew_ns)

with EventPublisher("tcp://127.0.0.1:5557") as events, Subscriber() as answers:
    answers.topic("robot1/pairs")
    handshake(events, answers, "robot1/pairs")   # PUB/SUB connect asynchronously
    events.request("tuple", "robot1/pairs", at=t_star)
    pair = answers.receive().tuple
"""

from __future__ import annotations

import collections
import itertools
import secrets
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import zmq
from numpy.typing import NDArray

from fxis_shm.client.clocktracker import ClockTracker
from fxis_shm.client.frames import Frame, FrameTuple, frames_of, in_caller_clock, sequence_of, tuple_of
from fxis_shm.client.sockets import SocketOwner, checked_encoding, connected_socket
from fxis_shm.core import timebase
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import InvalidArgument, ProtocolError, RequestTimeout, service_error
from fxis_shm.wire import defaults, protocol
from fxis_shm.wire.encoding import JPEG, RAW
from fxis_shm.wire.endpoints import check_endpoint
from fxis_shm.wire.headers import ReplyHeader
from fxis_shm.wire.multipart import slice_ms
from fxis_shm.wire.protocol import StreamTopic
from fxis_shm.wire.security import ClientKeys

DEFAULT_PUB = defaults.PUB
DEFAULT_EVENTS = defaults.EVENTS


Estimate = Callable[[], ClockEstimate]  # the caller's clock against the service's, now


@dataclass
class Message:
    """One published message: a stream item or the answer to a request event. Its frames'
    times are in the caller's clock when the subscriber has one (``Client.subscribe()``,
    ``Subscriber(clock=...)``), the service's own kept as ``service_t_*``."""

    topic: str
    header: ReplyHeader
    images: list[NDArray[Any]]
    estimate: Estimate | None = field(default=None, repr=False)
    _moved: bool = field(default=False, repr=False, compare=False)  # its times are the caller's

    def _in_caller_clock(self) -> ReplyHeader:
        if self.estimate is None or self._moved:
            return self.header
        self.header = in_caller_clock(self.header, self.estimate())
        self._moved = True  # moved once, however often it is read
        return self.header

    @property
    def seq(self) -> int | None:
        """Per-stream message number; a gap means messages were lost."""
        return self.header.get("seq")

    @property
    def rate(self) -> dict[str, object] | None:
        """In a decimated stream's first message: the rate asked, the camera's, and whether
        every frame is sent (the camera is no faster than the rate asked)."""
        return self.header.get("rate")

    @property
    def ok(self) -> bool:
        return bool(self.header.get("ok"))

    def raise_for_error(self) -> None:
        if not self.ok:
            err = self.header.get("error")  # a published header is not checked field by field
            code, message = (err.get("code", "UNKNOWN"), err.get("message", "")) if err else ("UNKNOWN", "")
            raise service_error(code, message)

    @property
    def frames(self) -> list[Frame]:
        self.raise_for_error()
        return frames_of(self._in_caller_clock(), self.images)

    @property
    def tuple(self) -> FrameTuple:
        self.raise_for_error()
        return tuple_of(self._in_caller_clock(), self.images)

    def sequence(self, single: bool = False) -> list[Frame] | list[FrameTuple[Frame]]:
        self.raise_for_error()
        return sequence_of(self._in_caller_clock(), self.images, single=single)


def stream_topic(
    kind: str, camera: str | None, rate_hz: float | None, encoding: str, quality: int | None
) -> StreamTopic:
    checked_encoding(encoding, quality)
    return StreamTopic(kind, camera, rate_hz, encoding, quality if encoding == JPEG else None)


class CallerClock:
    """The caller's clock against one service's, for a subscriber or an event publisher:
    the estimate of a client of that service (``Client.subscribe()``, ``Client.events()``),
    or one kept here from exchanges with the service's request ``service`` endpoint."""

    def __init__(
        self,
        clock: Callable[[], int] | str | None,
        service: str | None,
        keys: ClientKeys | None,
        estimate: Estimate | None,
    ):
        self._tracker: ClockTracker | None = None
        self.now: Callable[[], int] | None = None
        if estimate is None and clock is not None:
            if service is None:
                raise InvalidArgument(
                    "clock= needs the service's request endpoint (service=...) to estimate the clocks "
                    "from; or use Client(endpoint, clock=...).subscribe() / .events()"
                )
            self.now = clock if callable(clock) else timebase.reader(clock)
            self._tracker = ClockTracker(lambda: connected_socket(None, zmq.DEALER, service, keys), self.now, service)
            estimate = self._tracker.estimate
        self.estimate = estimate

    def close(self) -> None:
        if self._tracker is not None:
            self._tracker.close()


class Receiver:
    """What every subscriber does with the messages its ``receive`` gives: iterate them, and
    put one back."""

    _held: collections.deque[Message]

    def receive(self, timeout: float | None = None, latest: bool = False) -> Message:
        raise NotImplementedError

    def hold(self, message: Message) -> None:
        """Put back a message read too early: the next ``receive`` returns it first."""
        self._held.append(message)

    def __iter__(self) -> Iterator[Message]:
        while True:
            yield self.receive()


class Subscriber(Receiver, SocketOwner):
    """A SUB socket with a bounded queue; iterate it or call ``receive``.

    ``clock`` (with ``service``, the service's request endpoint): every time a message
    holds is in that clock, as ``Client(clock=...)`` gives them; ``Client.subscribe()``
    makes one bound to its client's clock and the service's publisher."""

    def __init__(
        self,
        endpoint: str = DEFAULT_PUB,
        timeout: float = 2.0,
        queue: int = 16,
        context: zmq.Context[Any] | None = None,
        keys: ClientKeys | None = None,
        *,
        clock: Callable[[], int] | str | None = None,
        service: str | None = None,
        estimate: Estimate | None = None,
    ):
        self.endpoint = check_endpoint(endpoint)
        self.timeout = timeout
        self._clock = CallerClock(clock, service, keys, estimate)
        self._sock: zmq.Socket[bytes] = (context or zmq.Context.instance()).socket(zmq.SUB)
        self._sock.setsockopt(zmq.LINGER, 0)
        self._sock.setsockopt(zmq.RCVHWM, queue)  # set before connecting, so it applies
        if keys is not None:
            keys.apply(self._sock)
        self._sock.connect(endpoint)
        self._topics: set[str] = set()
        self._held: collections.deque[Message] = collections.deque()

    @property
    def socket(self) -> zmq.Socket[bytes]:
        """The SUB socket, to poll it together with others (fxis_shm.client.multistreams)."""
        return self._sock

    def topic(self, topic: str) -> str:
        """Subscribe to exactly ``topic`` (ZeroMQ matches prefixes; messages on
        longer topics that merely start with it are skipped here)."""
        self._sock.setsockopt(zmq.SUBSCRIBE, topic.encode())
        self._topics.add(topic)
        return topic

    def frames(
        self, camera: str, rate_hz: float | None = None, *, encoding: str = RAW, quality: int | None = None
    ) -> str:
        """Subscribe to every frame of ``camera`` (or ``rate_hz`` of them per second), its
        pixels raw or compressed (``encoding="jpeg"`` with ``quality``, or ``"png"``)."""
        return self.topic(str(stream_topic("frames", camera, rate_hz, encoding, quality)))

    def tuples(self, rate_hz: float | None = None, *, encoding: str = RAW, quality: int | None = None) -> str:
        """Subscribe to synchronized tuples of all cameras as they complete."""
        return self.topic(str(stream_topic("tuples", None, rate_hz, encoding, quality)))

    def settings(self, camera: str) -> str:
        """Subscribe to the changes of ``camera``'s settings (docs/protocol.md 7.8): each message's
        header holds ``camera``, ``changed``, ``cost``, ``values`` and ``generation``."""
        return self.topic(f"settings/{camera}|")

    def unsubscribe(self, topic: str) -> None:
        self._sock.setsockopt(zmq.UNSUBSCRIBE, topic.encode())
        self._topics.discard(topic)

    def receive(self, timeout: float | None = None, latest: bool = False) -> Message:
        """The next message on a subscribed topic; with ``latest``, the newest one queued."""
        if self._held and not latest:
            return self._held.popleft()
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        found: list[zmq.Frame] | None = None
        while found is None or (latest and self._sock.poll(0, zmq.POLLIN)):
            if found is None and not self._sock.poll(slice_ms(deadline), zmq.POLLIN):
                if time.monotonic() < deadline:
                    continue
                raise RequestTimeout(f"no message from {self.endpoint} within {timeout:.3g} s")
            frames = self._sock.recv_multipart(copy=False)
            if frames and frames[0].bytes.decode(errors="replace") in self._topics:
                found = frames
        if len(found) < 2:
            raise ProtocolError("a published message needs a topic and a header")
        header, images = protocol.decode_reply([f.buffer for f in found[1:]])
        return Message(found[0].bytes.decode(errors="replace"), header, images, self._clock.estimate)

    def close(self) -> None:
        self._clock.close()
        super().close()


class EventPublisher(SocketOwner):
    """Publishes request events; the service answers each on its ``reply_topic``.

    ``clock`` (with ``service``, the service's request endpoint): ``at``, ``start`` and
    ``end`` are in that clock and a request without ``at`` asks for the moment of the call,
    as with ``Client(clock=...)``; ``Client.events()`` makes one bound to its client."""

    def __init__(
        self,
        endpoint: str = DEFAULT_EVENTS,
        context: zmq.Context[Any] | None = None,
        keys: ClientKeys | None = None,
        *,
        clock: Callable[[], int] | str | None = None,
        service: str | None = None,
        estimate: Estimate | None = None,
        now: Callable[[], int] | None = None,
    ):
        self.endpoint = endpoint
        self._prefix = secrets.token_hex(4)  # ids stay unique across publishers sharing a topic
        self._ids = (f"{self._prefix}-{n}" for n in itertools.count(1))
        self._sock = connected_socket(context, zmq.PUB, endpoint, keys)
        self._clock = CallerClock(clock, service, keys, estimate)
        self._now = now or self._clock.now

    def request(self, op: str, reply_topic: str, **fields: Any) -> str:
        """Publish one request event (op image, tuple, latest, sequence or time); returns its
        id ("<publisher>-<n>"), which the answer's ``header["id"]`` repeats."""
        request_id = next(self._ids)
        if self._clock.estimate is not None and op != "time":
            mapping = self._clock.estimate()
            if op not in ("latest",) and fields.get("at") is None and self._now is not None:
                fields["t_call"] = mapping.to_service(self._now())  # t*: the moment of this call
            for key in ("at", "start", "end"):
                if fields.get(key) is not None:
                    fields[key] = mapping.to_service(fields[key])
        self._sock.send_multipart(protocol.encode_event(op, reply_topic, id=request_id, **fields))
        return request_id

    def close(self) -> None:
        self._clock.close()
        super().close()


def handshake(events: EventPublisher, answers: Subscriber, reply_topic: str, timeout: float = 5.0) -> None:
    """Wait until events reach the service and its answers reach ``answers``
    (subscribed to ``reply_topic``): PUB/SUB connections form asynchronously
    and drop what is sent before."""
    publishers = getattr(events, "publishers", None)  # a MultiEventPublisher: each service in turn
    if publishers:
        for publisher in publishers.values():
            handshake(publisher, answers, reply_topic, timeout)
        return
    deadline = time.monotonic() + timeout
    probes: set[str] = set()
    while time.monotonic() < deadline:
        probes.add(events.request("time", reply_topic))
        try:
            while True:
                message = answers.receive(timeout=0.1)
                if message.topic == reply_topic and message.header.get("id") in probes:
                    _drain_probe_answers(answers, probes)
                    return
        except RequestTimeout:
            continue
    raise RequestTimeout(
        f"no answer on {reply_topic!r} within {timeout} s: is the service "
        f"listening on {events.endpoint} and publishing to {answers.endpoint}?"
    )


def _drain_probe_answers(answers: Subscriber, probes: set[str], settle_s: float = 0.05) -> None:
    """Consume answers to earlier probes that are already on their way; anything
    else seen meanwhile is kept for the subscriber's next ``receive``."""
    while True:
        try:
            message = answers.receive(timeout=settle_s)
        except RequestTimeout:
            return
        if message.header.get("id") not in probes:
            answers.hold(message)
            return
