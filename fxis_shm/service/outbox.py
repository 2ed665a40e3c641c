"""What the coordinator sends: replies to the clients of its request endpoint and messages on
its publish endpoint (streams, settings events, answers to request events). Nothing sent ever
waits: a client that does not read its replies, or a subscriber whose queue is full, loses the
message, and the log says so (once an interval: fxis_shm.service.logtally)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import TypeAlias

import zmq

from fxis_shm.core import timebase
from fxis_shm.service.logtally import LogTally
from fxis_shm.wire import protocol
from fxis_shm.wire.multipart import send_parts

log = logging.getLogger("coordinator")

Request: TypeAlias = protocol.Request  # a request as the codec decodes it and the engine takes it
Part: TypeAlias = protocol.Buffer  # a part of a message sent
Respond: TypeAlias = Callable[[Sequence[Part]], None]  # sends a reply's parts where its request came from


class Outbox:
    """Sends replies on the ``router`` socket and publications on the ``pub`` socket, and
    counts the requests answered (``requests_served``)."""

    def __init__(self, router: zmq.Socket[bytes], pub: zmq.Socket[bytes], tally: LogTally, clock: timebase.Clock):
        self.router, self.pub, self.tally, self.clock = router, pub, tally, clock
        self.requests_served = 0

    def reply(self, respond: Respond, request: Request, body: Request, images: Sequence[Part] = ()) -> None:
        """Answer ``request`` with ``body`` (its timing stamped "sent") through ``respond``."""
        if "timing" in body:
            body["timing"]["sent"] = self.clock.now_ns()
        self.requests_served += 1
        respond(protocol.encode_reply(request["id"], body, images))

    def send(self, envelope: Sequence[Part], frames: Sequence[Part]) -> None:
        """Send ``frames`` to the client whose routing ``envelope`` it is."""
        try:
            send_parts(self.router, [*envelope, *frames])
        except zmq.Again:
            dropped = "dropped a reply: the client is not reading its replies"
            for line in self.tally.note("dropped replies", dropped, self.clock.now_ns()):
                log.warning("%s", line)
        except zmq.ZMQError as exc:  # EHOSTUNREACH: the client went away
            log.info("could not send a reply: %s", exc)

    def publish(self, topic: str, frames: Sequence[Part]) -> None:
        """Publish ``frames`` on ``topic`` to whoever subscribes."""
        try:  # a subscriber whose queue is full loses this message; nobody waits
            send_parts(self.pub, [topic.encode(), *frames])
        except zmq.ZMQError as exc:
            log.debug("could not publish on %s: %s", topic, exc)
