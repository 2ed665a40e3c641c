"""A message of several parts sent and received by pyzmq's direct calls, as both ends of the
wire do it: the coordinator's replies and publications, the client's requests and replies."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

import zmq

if TYPE_CHECKING:
    from typing_extensions import Buffer

    from fxis_shm.wire.protocol import Buffer as Part  # what a message's parts may be

# plain ints: their arithmetic is far cheaper than that of pyzmq's enums
_MORE, _LAST, _RCVTIMEO = int(zmq.NOBLOCK | zmq.SNDMORE), int(zmq.NOBLOCK), int(zmq.RCVTIMEO)
WAIT_SLICE_S = 0.1  # how long a pending signal may wait for its handler in a receive


def slice_ms(deadline: float) -> int:
    """The next slice of a wait until ``deadline`` (time.monotonic()) in whole ms, rounded up
    (0 once it is past): at most WAIT_SLICE_S, so that a signal's handler runs between slices."""
    return math.ceil(max(0.0, min(deadline - time.monotonic(), WAIT_SLICE_S)) * 1000)


def send_parts(sock: zmq.Socket[bytes], parts: Sequence[Part]) -> None:
    """``parts`` as one message, without blocking (zmq.Again if it cannot go now): messages
    (zmq.Frame) and image buffers handed to ZeroMQ without a copy, small byte strings copied
    (cheaper than tracking them). (pyzmq's send_multipart checks each part's type in Python
    first; cold, as a request is when it comes long after the last, that costs more than the
    sends themselves.)"""
    last = len(parts) - 1
    for i, part in enumerate(parts):
        flags = _MORE if i < last else _LAST
        if isinstance(part, zmq.Frame):  # (a message is sent as it is; pyzmq's stubs type it apart from buffers)
            sock.send(part, flags)
        else:
            # (numpy's stubs give an array the buffer protocol only from Python 3.12 on)
            sock.send(cast("Buffer", part), flags, copy=isinstance(part, bytes))


def recv_parts(sock: zmq.Socket[bytes], timeout_s: float) -> list[zmq.Frame] | None:
    """The next message's parts (uncopied), waiting at most ``timeout_s``; None if none came.
    (A receive with a timeout of its own: pyzmq's poll makes a Poller in Python every call,
    a quarter of the cold cost of a small round trip's client side.)

    The wait is cut into slices of at most WAIT_SLICE_S: a signal that is not delivered into
    the wait itself (it lands just before it, or in another thread) only flags its handler,
    which Python runs between slices; in one long wait Ctrl-C or SIGTERM would be held for
    the whole timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        sock.setsockopt(_RCVTIMEO, max(1, slice_ms(deadline)))
        try:
            parts = [sock.recv(copy=False)]
            break
        except zmq.Again:
            if time.monotonic() >= deadline:
                return None
    while parts[-1].more:  # ZeroMQ delivers a message whole: the rest is there
        parts.append(sock.recv(copy=False))
    return parts
