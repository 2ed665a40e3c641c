"""The coordinator's sockets and who may use them: the three endpoints it binds (requests,
publications, request events), the frame notifications and the links to its camera workers,
all under CurveZMQ when the service has keys (docs/security.md)."""

from __future__ import annotations

import logging

import zmq
from zmq.auth.certs import load_certificates
from zmq.auth.thread import ThreadAuthenticator

from fxis_shm.errors import ConfigError
from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.framewatch import FrameWatch
from fxis_shm.service.workerlink import WorkerLinks
from fxis_shm.wire import protocol
from fxis_shm.wire.security import load_pair, make_server

log = logging.getLogger("coordinator")

_PUB_QUEUE = 16  # messages queued per subscriber; beyond, that subscriber loses messages
_REQUEST_QUEUE = 100  # replies queued per client of the request endpoint
MAX_MESSAGE_BYTES = 1 << 20  # a peer sending more is disconnected by ZeroMQ


class AllowedKeys:
    """Who may connect under CurveZMQ: the clients whose public keys are in the folder, and the
    service itself, whose viewers (dashboard, Foxglove server, ROS 2 bridge) connect with its
    own pair (ViewerSpec.client_keys). Read once, at start."""

    def __init__(self, pair: tuple[bytes, bytes], folder: str, operators: set[bytes] | frozenset[bytes] = frozenset()):
        self.keys = set(load_certificates(folder)) | {pair[0]} | operators  # operators are let in too

    def callback(self, domain: str, key: bytes) -> bool:
        return key in self.keys


class Access:
    """The service's keys and who may do what: without keys every client may connect and
    change settings; with them only the clients in the folder connect, and only the operators
    (when the service names them) change settings."""

    def __init__(self, spec: CoordinatorSpec):
        self.pair: tuple[bytes, bytes] | None = None
        self.clients = spec.curve_clients or ""  # the folder of the clients' public keys
        self.operators: set[str] | None = None  # the keys (Z85) that may change settings; None: every client
        if spec.curve_secret:
            self.pair = load_pair(spec.curve_secret)
            if spec.curve_operators:  # the service's own key too: its dashboard connects with it
                self.operators = {k.decode() for k in load_certificates(spec.curve_operators)}
                self.operators.add(self.pair[0].decode())

    def may_change(self, frame: bytes | zmq.Frame) -> bool:
        """May the client that sent ``frame`` change camera settings? Everyone, unless the service
        names its operators: then only their keys (CurveZMQ's User-Id of the message)."""
        return self.operators is None or (isinstance(frame, zmq.Frame) and frame.get("User-Id") in self.operators)

    def authenticator(self, ctx: zmq.Context[zmq.Socket[bytes]]) -> ThreadAuthenticator | None:
        """The thread that lets in only the allowed keys (started), or None without keys."""
        if self.pair is None:
            return None
        auth = ThreadAuthenticator(ctx, log=logging.getLogger("auth"))
        auth.start()
        allowed = AllowedKeys(self.pair, self.clients, operators={k.encode() for k in self.operators or ()})
        auth.configure_curve_callback(domain="*", credentials_provider=allowed)
        return auth


class ServerSockets:
    """Opens the coordinator's sockets in ``ctx`` and closes them in the reverse order, when its
    ``with`` block ends (or at once, when an endpoint cannot be bound: ConfigError).
    ``router`` takes requests; ``pub`` publishes (and reports subscriptions); ``events`` takes
    request events (None without an events endpoint); ``watch`` wakes the loop on new frames;
    ``links`` carries commands to the camera workers."""

    def __init__(self, ctx: zmq.Context[zmq.Socket[bytes]], spec: CoordinatorSpec, access: Access):
        self._ctx, self._access = ctx, access
        self._opened: list[zmq.Socket[bytes] | FrameWatch | WorkerLinks] = []
        self._auth = access.authenticator(ctx)
        try:
            self.router = self._bind(zmq.ROUTER, spec.endpoint, "request endpoint", _REQUEST_QUEUE)
            self.router.setsockopt(zmq.ROUTER_MANDATORY, 1)  # report unsendable replies
            self.pub = self._bind(zmq.XPUB, spec.pub, "publish endpoint", _PUB_QUEUE)
            self.events: zmq.Socket[bytes] | None = None
            if spec.events:
                self.events = self._bind(zmq.SUB, spec.events, "events endpoint", _REQUEST_QUEUE)
                self.events.setsockopt(zmq.SUBSCRIBE, protocol.EVENT_TOPIC)
            self.watch = FrameWatch(ctx, spec.service, list(spec.cameras))
            self._opened.append(self.watch)
            self.links = WorkerLinks(ctx, spec.service, list(spec.cameras))
            self._opened.append(self.links)
        except BaseException:  # (a ConfigError) what was opened is closed: the caller has nothing to close
            self.close()
            raise

    def __enter__(self) -> ServerSockets:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def polled(self) -> list[zmq.Socket[bytes]]:
        """Every socket the loop waits on."""
        inputs = [
            self.router,
            self.pub,
            self.events,
            self.watch.pull,
            *self.links.sockets.values(),
            *self.links.monitors,
        ]
        return [sock for sock in inputs if sock is not None]

    def _bind(self, kind: int, endpoint: str, what: str, queue: int) -> zmq.Socket[bytes]:
        sock = self._ctx.socket(kind)
        self._opened.append(sock)
        sock.setsockopt(zmq.LINGER, 0)
        if self._access.pair is not None:
            make_server(sock, *self._access.pair)
        sock.setsockopt(zmq.SNDHWM, queue)
        sock.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        try:
            sock.bind(endpoint)
        except zmq.ZMQError as exc:
            raise ConfigError(f"cannot bind the {what} {endpoint}: {exc}") from None
        return sock

    def close(self) -> None:
        for opened in reversed(self._opened):
            opened.close()
        if self._auth is not None:
            self._auth.stop()
