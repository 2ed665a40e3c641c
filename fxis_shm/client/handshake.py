"""Why a service does not answer, when the ZeroMQ handshake says so: a client without keys
meets a service that speaks only CurveZMQ, or a key the service refuses. Without this, both
look like a service that is not running ("no reply ... within 2 s").

A monitor socket reports the client socket's handshake events; they are read only when a
request has timed out, so a served request costs nothing.
"""

from __future__ import annotations

import zmq
from zmq.utils.monitor import recv_monitor_message

_FAILED = zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL | zmq.EVENT_HANDSHAKE_FAILED_AUTH
GRACE_MS = 500  # after a time-out, how long to wait for a handshake event not yet reported
KEY_OPTIONS = "ClientKeys in Python, --server-key and --client-key on the command line (docs/security.md)"


class HandshakeWatch:
    def __init__(self, sock: zmq.Socket[bytes]):
        self._sock = sock
        self._monitor = sock.get_monitor_socket(_FAILED | zmq.EVENT_HANDSHAKE_SUCCEEDED)
        self._last: int | None = None  # the last handshake event seen

    def problem(self, endpoint: str, keyed: bool) -> str | None:
        """What the handshakes with ``endpoint`` say is wrong (None: nothing, or none seen)."""
        grace_ms = 0 if self._last is not None else GRACE_MS  # none seen yet: a busy host may be late
        while self._monitor.poll(grace_ms):
            self._last = int(recv_monitor_message(self._monitor)["event"])
            grace_ms = 0
        if self._last is None or not self._last & _FAILED:
            return None
        if not keyed:
            return (
                f"the service at {endpoint} answers only CurveZMQ handshakes and this client has no keys: "
                f"give the service's public key and this client's key pair ({KEY_OPTIONS})"
            )
        if self._last == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
            return (
                f"the service at {endpoint} refused this client's key: its public key is not among the allowed clients'"
            )
        return (
            f"the CurveZMQ handshake with {endpoint} failed: is the server key the service's public key, "
            "and does the service use CurveZMQ?"
        )

    def close(self) -> None:
        try:
            self._sock.disable_monitor()
        except zmq.ZMQError:
            pass  # the socket is closed already
        self._monitor.close()
