"""What every socket of the client side shares: the frame encoding checked before a request
leaves, a connected socket that never blocks on close, closing as a context manager, a
request's own timeout as the wire carries it (a message's parts are sent and received by
fxis_shm.wire.multipart, as the service sends them)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import zmq

from fxis_shm.errors import InvalidArgument, ProtocolError
from fxis_shm.wire import encoding as codec
from fxis_shm.wire.endpoints import check_endpoint
from fxis_shm.wire.multipart import slice_ms
from fxis_shm.wire.security import ClientKeys

if TYPE_CHECKING:
    from typing_extensions import Self  # typing's from 3.11 on


def checked_encoding(encoding: str, quality: int | None) -> tuple[str, int | None]:
    """``encoding`` and ``quality`` if a service can send frames so, else InvalidArgument."""
    try:
        codec.check(encoding, codec.DEFAULT_JPEG_QUALITY if quality is None else quality)
    except ProtocolError as exc:
        raise InvalidArgument(exc.message) from None
    return encoding, quality


def poll_ms(seconds: float) -> int:
    """A wait of ``seconds`` (none if negative) as ZeroMQ's poll takes it: whole milliseconds,
    rounded up, so that a wait for a deadline never ends before it."""
    return math.ceil(max(0.0, seconds) * 1000)


def writable(sock: zmq.Socket[bytes], deadline: float) -> bool:
    """Whether ``sock`` can send before ``deadline`` (time.monotonic()), waited for in slices
    (wire.multipart.slice_ms: Ctrl-C is not held for the whole wait)."""
    while not sock.poll(slice_ms(deadline), zmq.POLLOUT):
        if time.monotonic() >= deadline:
            return False
    return True


def connected_socket(
    context: zmq.Context[Any] | None,
    kind: int,
    endpoint: str,
    keys: ClientKeys | None = None,
    before_connect: Callable[[zmq.Socket[bytes]], object] | None = None,
) -> zmq.Socket[bytes]:
    """A client socket: LINGER 0 (closing never blocks), CURVE if keys are given; BadEndpoint
    for an endpoint ZeroMQ would refuse only as "Invalid argument", or never."""
    check_endpoint(endpoint)
    sock: zmq.Socket[bytes] = (context or zmq.Context.instance()).socket(kind)
    sock.setsockopt(zmq.LINGER, 0)
    if keys is not None:
        keys.apply(sock)
    if before_connect is not None:  # e.g. a monitor, which must see the first handshake too
        before_connect(sock)
    sock.connect(endpoint)
    return sock


class Closable:
    """Closed (``close``) on leaving a ``with`` block."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SocketOwner(Closable):
    """Closes its one ZeroMQ socket (``self._sock``) on ``close`` and on leaving a ``with``."""

    _sock: zmq.Socket[bytes]

    def close(self) -> None:
        self._sock.close()


def reachable(endpoint: str, via: str) -> str:
    """``endpoint`` as a status reports it (a service bound to ``*`` or ``0.0.0.0`` reports
    that), with such a wildcard host replaced by the host the caller reaches it by (``via``)."""
    scheme, _, rest = endpoint.partition("://")
    host, sep, port = rest.rpartition(":")
    if scheme != "tcp" or not sep or host not in ("*", "0.0.0.0", "[::]", "::"):
        return endpoint
    via_host = via.partition("://")[2].rpartition(":")[0]
    return f"tcp://{via_host}:{port}"
