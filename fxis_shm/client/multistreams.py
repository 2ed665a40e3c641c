"""Streams and events over several services (``Client([a, b]).subscribe()``, ``.events()``),
every time in the caller's clock.

``MultiSubscriber`` holds one Subscriber per service, each bound to the caller's estimate of
its service's clock, and reads them as one: ``frames(camera)`` subscribes at the camera's
service, ``topic(t)`` at every service (event answers), and ``tuples(rate_hz)`` starts a
stream of joint tuples across the services (fxis_shm.client.tuplestream). ``MultiEventPublisher``
sends each event request to the service of the cameras it names.
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

import zmq

from fxis_shm.client.pubsub import EventPublisher, Message, Receiver, Subscriber, stream_topic
from fxis_shm.client.single import SingleClient
from fxis_shm.client.sockets import Closable
from fxis_shm.client.tuplestream import TupleStream
from fxis_shm.errors import InvalidArgument, RequestTimeout
from fxis_shm.wire.encoding import RAW
from fxis_shm.wire.multipart import slice_ms


class MultiSubscriber(Receiver, Closable):
    """A subscriber of several services' streams; iterate it or call ``receive``, as a Subscriber."""

    def __init__(
        self,
        clients: list[SingleClient],
        owner: dict[str, SingleClient],
        options: dict[str, Any],
        timeout: float,
        queue: int,
    ):
        self.timeout, self._queue = timeout, queue
        self._owner = {name: client.endpoint for name, client in owner.items()}
        self._options = options
        self.subscribers: dict[str, Subscriber] = {}
        self._streams: dict[str, TupleStream] = {}
        self._made: collections.deque[Message] = collections.deque(maxlen=queue)  # from the tuple streams
        self._made_lock = threading.Lock()
        self._held: collections.deque[Message] = collections.deque()
        self._bell: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.PULL)  # rung by a tuple stream
        self._bell.setsockopt(zmq.LINGER, 0)
        self._bell_address = f"inproc://fxis-tuples-{id(self)}"
        self._bell.bind(self._bell_address)
        try:
            for client in clients:
                self.subscribers[client.endpoint] = client.subscribe(timeout, queue)
        except BaseException:
            self.close()
            raise

    # ---- subscriptions ----

    def frames(
        self, camera: str, rate_hz: float | None = None, *, encoding: str = RAW, quality: int | None = None
    ) -> str:
        """Every frame of ``camera`` (or ``rate_hz`` of them per second), from its service."""
        if camera not in self._owner:
            raise InvalidArgument(f"unknown camera {camera!r}; the services have {sorted(self._owner)}")
        return self.subscribers[self._owner[camera]].frames(camera, rate_hz, encoding=encoding, quality=quality)

    def tuples(
        self, rate_hz: float | None = None, *, encoding: str = RAW, quality: int | None = None, partial: bool = False
    ) -> str:
        """Joint tuples of every camera of every service, ``rate_hz`` per second (default: one
        per frame of the slowest camera). With ``partial``, cameras of a service that is down
        are left out (``tuple.missing``); without, such a tuple is a message with the error."""
        stream = stream_topic("tuples", None, rate_hz, encoding, quality)
        topic = str(stream)
        if topic not in self._streams:
            self._streams[topic] = TupleStream(
                topic, stream, self._owner, self._options, self._keep, self._bell_address, partial
            )
        return topic

    def topic(self, topic: str) -> str:
        """Subscribe to exactly ``topic`` at every service (e.g. an event reply topic)."""
        for subscriber in self.subscribers.values():
            subscriber.topic(topic)
        return topic

    def unsubscribe(self, topic: str) -> None:
        stream = self._streams.pop(topic, None)
        if stream is not None:
            stream.close()
        for subscriber in self.subscribers.values():
            subscriber.unsubscribe(topic)

    # ---- receiving ----

    def _keep(self, message: Message) -> None:
        """From a tuple stream's thread (which then rings the bell): keep the message, the
        oldest going when the queue is full."""
        with self._made_lock:
            self._made.append(message)

    def receive(self, timeout: float | None = None, latest: bool = False) -> Message:
        """The next message of any service or tuple stream; with ``latest``, the newest queued."""
        if self._held and not latest:
            return self._held.popleft()
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        poller = zmq.Poller()
        poller.register(self._bell, zmq.POLLIN)
        for subscriber in self.subscribers.values():
            poller.register(subscriber.socket, zmq.POLLIN)
        found: Message | None = None
        while True:
            wait_ms = 0 if found is not None else slice_ms(deadline)
            ready = dict(poller.poll(wait_ms))
            newest = self._take(ready, latest)
            if newest is not None:
                found = newest
                if not latest:
                    return found
            elif found is not None:
                return found
            elif time.monotonic() >= deadline:
                raise RequestTimeout(f"no message from {sorted(self.subscribers)} within {timeout:.3g} s")

    def _take(self, ready: dict[Any, int], latest: bool) -> Message | None:
        """The first message of those ready (with ``latest``, the last); the others are held."""
        if self._bell in ready:
            while self._bell.poll(0):
                self._bell.recv()
        with self._made_lock:
            taken = list(self._made)
            self._made.clear()
        for subscriber in self.subscribers.values():
            if subscriber.socket in ready:
                try:
                    taken.append(subscriber.receive(timeout=0, latest=latest))
                except RequestTimeout:  # only messages of topics not asked for
                    pass
        if not taken:
            return None
        if latest:
            return taken[-1]
        self._held.extend(taken[1:])
        return taken[0]

    def close(self) -> None:
        for stream in self._streams.values():
            stream.close()
        self._streams.clear()
        for subscriber in self.subscribers.values():
            subscriber.close()
        self._bell.close()


class MultiEventPublisher(Closable):
    """Event requests to several services, each to the service of the cameras it names (an
    event is answered by one service: for a tuple across services, ask ``Client([...]).tuple``
    or subscribe to ``tuples``). ``at``, ``start`` and ``end`` are in the caller's clock."""

    def __init__(self, clients: list[SingleClient], owner: dict[str, SingleClient]):
        self._owner = {name: client.endpoint for name, client in owner.items()}
        self.publishers: dict[str, EventPublisher] = {}
        try:
            for client in clients:
                self.publishers[client.endpoint] = client.events()
        except BaseException:
            self.close()
            raise

    def request(self, op: str, reply_topic: str, *, service: str | None = None, **fields: Any) -> str:
        """Publish one request event to the service of its cameras (or to ``service``, an
        endpoint); returns its id, which the answer's ``header["id"]`` repeats."""
        return self.publishers[self._service_of(op, service, fields)].request(op, reply_topic, **fields)

    def _service_of(self, op: str, service: str | None, fields: dict[str, Any]) -> str:
        if service is not None:
            if service not in self.publishers:
                raise InvalidArgument(f"unknown service {service!r}; the services are {sorted(self.publishers)}")
            return service
        names = fields.get("cameras") or ([fields["camera"]] if fields.get("camera") else [])
        unknown = [n for n in names if n not in self._owner]
        if unknown:
            raise InvalidArgument(f"unknown camera(s) {unknown}; the services have {sorted(self._owner)}")
        services = {self._owner[n] for n in names} or set(self.publishers)
        if len(services) != 1:
            raise InvalidArgument(
                f"an event {op!r} is answered by one service: name cameras of one service (or service=...); "
                f"these span {sorted(services)}. For a tuple across services use Client([...]).tuple() "
                "or subscribe().tuples()"
            )
        return services.pop()

    def close(self) -> None:
        for publisher in self.publishers.values():
            publisher.close()
