"""Keeps a client's estimate of a service's clock fresh (fxis_shm.core.clockmap), in the
background, on a socket of its own so that requests never wait for it.

The first estimate is made on demand (one burst of ``time`` exchanges, a few ms on a LAN);
after that a thread refreshes it every ``refresh_s`` and requests read whatever estimate
is current. A service that stops answering leaves the last estimate in place.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import zmq

from fxis_shm.client.sockets import poll_ms
from fxis_shm.core.clockmap import ClockEstimate, ClockEstimator, Exchange
from fxis_shm.errors import ProtocolError, RequestTimeout
from fxis_shm.wire import protocol

BURST = 8  # exchanges per refresh: the shortest of them counts
FIRST_BURST = 16
STOP_CHECK_S = 0.1  # while waiting for a silent service, look this often whether the tracker closes


class ClockTracker:
    def __init__(
        self,
        connect: Callable[[], zmq.Socket[bytes]],
        clock: Callable[[], int],
        endpoint: str,
        timeout: float = 2.0,
        refresh_s: float = 1.0,
    ):
        self._connect, self.clock, self.endpoint = connect, clock, endpoint
        self.timeout, self.refresh_s = timeout, refresh_s
        self._estimator = ClockEstimator()
        self._estimate: ClockEstimate | None = None
        self._lock = threading.Lock()  # one burst at a time on the one socket
        self._sock: zmq.Socket[bytes] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._ids = 0

    def estimate(self) -> ClockEstimate:
        """The current estimate; the first call measures one (RequestTimeout if the service is silent)."""
        estimate = self._estimate
        if estimate is not None:
            return estimate
        with self._lock:
            if self._estimate is None:
                self._burst(FIRST_BURST)
                self._thread = threading.Thread(target=self._refresh, name="fxis-clock", daemon=True)
                self._thread.start()
        assert self._estimate is not None
        return self._estimate

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self.timeout + 1)
        with self._lock:
            if self._sock is not None:
                self._sock.close()
                self._sock = None

    def _refresh(self) -> None:
        while not self._stop.wait(self.refresh_s):
            try:
                with self._lock:
                    if not self._stop.is_set():
                        self._burst(BURST)
            except (RequestTimeout, ProtocolError, zmq.ZMQError):
                pass  # the service is away: keep the last estimate, try again later

    def _burst(self, count: int) -> None:
        exchanges = [self._exchange() for _ in range(count)]
        self._estimator.add_burst(exchanges)
        self._estimate = self._estimator.estimate()

    def _exchange(self) -> Exchange:
        if self._sock is None:
            self._sock = self._connect()
        self._ids += 1
        request = [b""] + protocol.encode_request("time", id=f"clock-{self._ids}")
        sent = self.clock()
        if not self._poll(zmq.POLLOUT):
            raise self._silent()
        self._sock.send_multipart(request, zmq.NOBLOCK)
        while True:
            if not self._poll(zmq.POLLIN):
                self._sock.close()  # a late reply must not be taken for the next exchange's
                self._sock = None
                raise self._silent()
            frames = self._sock.recv_multipart()
            back = self.clock()
            header, _ = protocol.decode_reply(frames[1:] if frames and not frames[0] else frames)
            if header.get("id") == f"clock-{self._ids}":
                break
        try:
            return Exchange(sent, int(header["received"]), int(header["now"]), back)
        except (KeyError, TypeError, ValueError):
            raise ProtocolError(
                f"{self.endpoint} answered 'time' without its receive and send times (an older service?)"
            ) from None

    def _poll(self, event: int) -> bool:
        """Whether the socket is ready for ``event`` within the timeout; False at once when the
        tracker is closing (closing a client of a silent service does not wait out a timeout)."""
        assert self._sock is not None
        deadline = time.monotonic() + self.timeout
        while True:
            left = deadline - time.monotonic()
            if self._sock.poll(poll_ms(min(left, STOP_CHECK_S)), event):
                return True
            if left <= 0 or self._stop.is_set():
                return False

    def _silent(self) -> RequestTimeout:
        return RequestTimeout(
            f"{self.endpoint} did not answer 'time' within {self.timeout:.3g} s while this client estimated its clock"
        )
