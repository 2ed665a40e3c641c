"""What every socket of the client side shares: the frame encoding checked before a request
leaves, a connected socket that never blocks on close, closing as a context manager, a
request's own timeout as the wire carries it, and a message sent and received by pyzmq's
direct calls."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence

import zmq

from fxis_shm.errors import InvalidArgument, ProtocolError
from fxis_shm.wire import encoding as codec
from fxis_shm.wire.endpoints import check_endpoint
from fxis_shm.wire.security import ClientKeys


def checked_encoding(encoding: str, quality: int | None) -> tuple[str, int | None]:
    """``encoding`` and ``quality`` if a service can send frames so, else InvalidArgument."""
    try:
        codec.check(encoding, codec.DEFAULT_JPEG_QUALITY if quality is None else quality)
    except ProtocolError as exc:
        raise InvalidArgument(exc.message) from None
    return encoding, quality


# plain ints: their arithmetic is far cheaper than that of pyzmq's enums
_MORE, _LAST, _RCVTIMEO = int(zmq.NOBLOCK | zmq.SNDMORE), int(zmq.NOBLOCK), int(zmq.RCVTIMEO)


def send_parts(sock: zmq.Socket, parts: Sequence) -> None:
    """``parts`` as one message, without blocking (zmq.Again if it cannot go now): messages
    (zmq.Frame) and image buffers handed to ZeroMQ without a copy, small byte strings copied
    (cheaper than tracking them). (pyzmq's send_multipart checks each part's type in Python
    first; cold, as a request is when it comes long after the last, that costs more than the
    sends themselves.)"""
    last = len(parts) - 1
    for i, part in enumerate(parts):
        sock.send(part, _MORE if i < last else _LAST, copy=isinstance(part, (bytes, zmq.Frame)))


def recv_parts(sock: zmq.Socket, timeout_s: float) -> list[zmq.Frame] | None:
    """The next message's parts (uncopied), waiting at most ``timeout_s``; None if none came.
    (A receive with a timeout of its own: pyzmq's poll makes a Poller in Python every call,
    a quarter of the cold cost of a small round trip's client side.)"""
    sock.setsockopt(_RCVTIMEO, max(1, math.ceil(timeout_s * 1000)))
    try:
        parts = [sock.recv(copy=False)]
    except zmq.Again:
        return None
    while parts[-1].more:  # ZeroMQ delivers a message whole: the rest is there
        parts.append(sock.recv(copy=False))
    return parts


def connected_socket(
    context: zmq.Context | None,
    kind: int,
    endpoint: str,
    keys: ClientKeys | None = None,
    before_connect: Callable[[zmq.Socket], object] | None = None,
) -> zmq.Socket:
    """A client socket: LINGER 0 (closing never blocks), CURVE if keys are given; BadEndpoint
    for an endpoint ZeroMQ would refuse only as "Invalid argument", or never."""
    check_endpoint(endpoint)
    sock = (context or zmq.Context.instance()).socket(kind)
    sock.setsockopt(zmq.LINGER, 0)
    if keys is not None:
        keys.apply(sock)
    if before_connect is not None:  # e.g. a monitor, which must see the first handshake too
        before_connect(sock)
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


def wire_timeout_ms(timeout: float | None, timeout_ms: float | None) -> float | None:
    """A request's own timeout for the wire (ms), from ``timeout`` in seconds as everywhere in
    this API; ``timeout_ms``, the old name, still works but warns."""
    if timeout_ms is not None:
        warnings.warn("timeout_ms= is deprecated: give timeout= in seconds", DeprecationWarning, stacklevel=3)
        if timeout is None:
            return timeout_ms
    return None if timeout is None else timeout * 1000


def reachable(endpoint: str, via: str) -> str:
    """``endpoint`` as a status reports it (a service bound to ``*`` or ``0.0.0.0`` reports
    that), with such a wildcard host replaced by the host the caller reaches it by (``via``)."""
    scheme, _, rest = endpoint.partition("://")
    host, sep, port = rest.rpartition(":")
    if scheme != "tcp" or not sep or host not in ("*", "0.0.0.0", "[::]", "::"):
        return endpoint
    via_host = via.partition("://")[2].rpartition(":")[0]
    return f"tcp://{via_host}:{port}"
