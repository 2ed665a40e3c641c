"""The Python client: synchronized tuples and single frames as NumPy arrays.

It uses a DEALER socket and tags every request with an id, so a timed-out
request leaves the client usable (a reply that arrives late is recognised by
its id and discarded), and a restarted service is reconnected to by itself.

Two paths bring the pixels (``Frame.path`` says which one did): on the
service's own kernel, the service replies with where the chosen frames are and
the client copies them out of the shared-memory rings itself ("local", see
fxis_shm.shm.localpath); elsewhere, or when the rings cannot be opened here, the
frames travel in the reply ("network"), raw or compressed (``encoding``).

Every time the client takes or returns is in the caller's clock (``clock``): it
keeps an estimate of each service's clock against it (fxis_shm.core.clockmap, kept fresh
in the background by fxis_shm.client.clocktracker), exactly 0 where the service provably
reads the same clock.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from typing import Any, cast

import zmq

from fxis_shm.client import arguments
from fxis_shm.client.api import ClientApi
from fxis_shm.client.clocktracker import ClockTracker
from fxis_shm.client.fastreads import FastReads
from fxis_shm.client.frames import LOCAL, NETWORK, Answer, Images, in_caller_clock
from fxis_shm.client.handshake import HandshakeWatch
from fxis_shm.client.localreads import LocalReads
from fxis_shm.client.pubsub import EventPublisher, Subscriber
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.client.requestpaths import RequestPaths
from fxis_shm.client.requesttimes import fixed_mapping, last_needed
from fxis_shm.client.sockets import SocketOwner, checked_encoding, connected_socket, reachable, writable
from fxis_shm.core import timebase
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import InvalidArgument, RequestTimeout, service_error
from fxis_shm.shm.localpath import LocalRings, boot_id
from fxis_shm.wire import commands, defaults, encoding as codec, protocol, ranges
from fxis_shm.wire.endpoints import check_endpoint, unknown_host
from fxis_shm.wire.headers import ReplyHeader
from fxis_shm.wire.multipart import recv_parts, send_parts
from fxis_shm.wire.security import ClientKeys

DEFAULT_ENDPOINT = defaults.ENDPOINT
LOCAL_MODES = ("auto", "off", "require")
_PERIODS_VALID_S = 10.0  # the cameras' periods learnt from the status, for sequences that wait
# plain ints: their arithmetic is far cheaper than that of pyzmq's enums
_EVENTS, _POLLOUT = int(zmq.EVENTS), int(zmq.POLLOUT)


class SingleClient(RequestPaths, SocketOwner, ClientApi):
    """A client of one service (what ``Client(endpoint)`` makes): every call raises
    RequestTimeout after ``timeout`` seconds."""

    def __init__(
        self,
        endpoint: str = DEFAULT_ENDPOINT,
        timeout: float = 2.0,
        context: zmq.Context[Any] | None = None,  # any context: the sockets are made by connected_socket
        keys: ClientKeys | None = None,
        local: str = "auto",
        *,
        clock: Callable[[], int] | str | None = None,
        encoding: str = codec.RAW,
        quality: int | None = None,
    ):
        """``keys``: for a service with CurveZMQ, its public key and this client's pair
        (``ClientKeys.from_files("server.key", "me.key_secret")``).

        ``local``: "auto" copies frames straight from the service's shared-memory rings
        when the service runs on this kernel and its rings can be opened (same user, same
        /dev/shm), else takes them from the reply; "off" always takes them from the
        reply; "require" raises LocalPathUnavailable rather than use the network path.

        ``clock``: the caller's clock, in which every time is given and returned:
        "monotonic" (default, ``time.monotonic_ns``), "realtime" (``time.time_ns``), "tai",
        or any function returning int ns. ``client.clocks`` shows its relation to the
        service's clock.

        ``encoding``: how frames travel over the network ("raw", "jpeg" with ``quality``
        1-100, default 90, or "png"); each request may say otherwise. The local path is raw."""
        if local not in LOCAL_MODES:
            raise InvalidArgument(f"local must be one of {LOCAL_MODES}, got {local!r}")
        if not (callable(clock) or clock is None or isinstance(clock, str)):
            raise InvalidArgument(f"clock must be a clock's name or a function returning int ns, got {clock!r}")
        self.endpoint = check_endpoint(endpoint)
        self.timeout = ranges.TIMEOUT_S.check(timeout, "timeout")
        self.local = local
        self.encoding, self.quality = checked_encoding(encoding, quality)
        self._clock_name = timebase.name_of(clock)
        self.clock: Callable[[], int] = clock if callable(clock) else timebase.reader(self._clock_name or "")
        self._ids = itertools.count(1)
        self._context, self._keys = context, keys
        watches: list[HandshakeWatch] = []  # says why, when a request times out
        self._sock = connected_socket(context, zmq.DEALER, endpoint, keys, lambda s: watches.append(HandshakeWatch(s)))
        self._handshake = watches[0]
        self._heard = False  # the service has answered a request of this client
        self._identity: dict[str, Any] | None = None  # the service's kernel, time namespace and clock, from its status
        self._mapping: ClockEstimate | None = None  # fixed: the service reads our clock (or one shared)
        self._tracker: ClockTracker | None = None  # else: estimated
        self._periods: tuple[float, float] | None = None  # (longest frame period, when learnt)
        self._boot_id = boot_id()
        self._rings = LocalRings()
        self._reads: LocalReads | None = None  # answers from the rings without the coordinator
        self._fast: FastReads | None = None  # the compiled read of the common requests (over _reads)
        self._reads_off: tuple[str, float] | None = None  # why not, since when
        self._local_off: tuple[str, float] | None = None  # why the local path is not used, since when
        self.paths = {LOCAL: 0, NETWORK: 0, "torn": 0, "compiled": 0}  # replies by path; local copies found torn;
        # "compiled": the local replies the compiled read made (fxis_shm.client.fastreads)

    def close(self) -> None:
        if self._tracker is not None:
            self._tracker.close()
        self._drop_reads()
        self._rings.close()
        self._handshake.close()
        super().close()

    @property
    def local_unavailable(self) -> str | None:
        """Why the last request could not use the local path (None: it could, or was not asked to)."""
        return self._local_off[0] if self._local_off else None

    # ---- what ClientApi's operations ask of one service ----

    def _subscriber(self, timeout: float, queue: int) -> Subscriber:
        """A Subscriber of this service's streams (its publisher, learnt from the status)."""
        pub = reachable(self.status()["pub"], self.endpoint)
        return Subscriber(pub, timeout, queue, self._context, self._keys, estimate=self.clock_estimate)

    def events(self) -> EventPublisher:
        """An EventPublisher to this service's events endpoint (learnt from the status) whose
        ``at``, ``start`` and ``end`` are in this client's clock, t* the moment of the call
        without ``at``. Answers arrive on ``subscribe()``'s Subscriber, ``topic(reply_topic)``."""
        events = reachable(self.status()["events"], self.endpoint)
        return EventPublisher(events, self._context, self._keys, estimate=self.clock_estimate, now=self.clock)

    def _owners(self, cameras: list[str] | None) -> dict[str, SingleClient]:
        return dict.fromkeys(cameras or list(self.status()["cameras"]), self)

    @property
    def clocks(self) -> dict[str, ClockEstimate]:
        """The service's clock against the caller's: offset (service minus caller), drift,
        uncertainty and how it is known ("same clock", "shared", "estimated")."""
        return {self.endpoint: self.clock_estimate()}

    def clock_estimate(self) -> ClockEstimate:
        """The current mapping of the caller's clock onto the service's (see ``clocks``)."""
        if self._mapping is None and self._tracker is None:
            self._mapping = fixed_mapping(self._clock_name, self._service_identity())
            if self._mapping is None:
                self._tracker = ClockTracker(
                    lambda: connected_socket(self._context, zmq.DEALER, self.endpoint, self._keys),
                    self.clock,
                    self.endpoint,
                    self.timeout,
                )
        if self._mapping is not None:
            return self._mapping
        assert self._tracker is not None  # (made just above when there is no mapping)
        return self._tracker.estimate()

    def _longest_period_s(self) -> float:
        """The slowest camera's frame period: from the rings when they are read here (no
        request), else from the service's status, looked at again after a while."""
        reads = self._local_reads()
        if reads is not None:
            periods = [h.period_ns for h in reads.cameras.values() if h.period_ns > 0]
            return max(periods, default=1e9) / 1e9
        if self._periods is None or time.monotonic() - self._periods[1] > _PERIODS_VALID_S:
            cams = self.status()["cameras"].values()
            self._periods = (max((1 / c["fps"] for c in cams if c.get("fps")), default=1.0), time.monotonic())
        return self._periods[0]

    def status(self) -> dict[str, Any]:
        status = self._document("status", 0.0)
        self._identity = {k: status.get(k) for k in ("boot_id", "time_namespace", "clock")}
        return status

    def time(self) -> int:
        """The service's clock now (int ns of the clock its status names; CLOCK_MONOTONIC by default)."""
        return self._call("time", 0.0)[0]["now"]

    def settings(self, camera: str, *, features: bool = False) -> dict[str, Any]:
        """The camera's settings, as its worker last reported them.

        Parameters
        ----------
        camera
            The camera's name.
        features
            True: also ``features``, every node-map feature (Aravis and GenTL cameras).

        Returns
        -------
        dict
            ``values`` (key: value), ``limits`` (key: type, access, cost ``"live"`` or
            ``"restart"``, min/max/inc or choices, unit, a note where a key does not apply in the
            camera's mode) and ``generation``.

        Raises
        ------
        UnknownCamera, CameraDown, RequestTimeout, ServiceError
            As for ``image``.
        """
        return self._settings(camera=arguments.camera_name(camera), features=features or None)

    def configure(self, camera: str, **values: object) -> dict[str, Any]:
        """Change settings of ``camera``, all or none: ``client.configure("left", exposure_us=2000, gain=6)``.

        Parameters
        ----------
        camera
            The camera's name.
        **values
            Setting name to new value (``client.settings(camera)["limits"]`` lists them).

        Returns
        -------
        dict
            ``changed`` (the values the camera took: it may round), ``cost`` (``"none"``: it had
            them already; ``"live"``: applied between two frames; ``"restart"``: a new ring, the
            generation + 1), ``values``, ``limits`` and ``generation``.

        Raises
        ------
        SettingRejected
            A key the camera lacks, a read-only one (``fps`` on the lockstep grid) or a value out
            of range, named with its limits; the camera keeps its settings.
        Forbidden
            Under ``--curve-operators``, a client whose key is not an operator's.
        Busy
            Too many changes of this camera are waiting; ask again later.
        InvalidArgument, UnknownCamera, CameraDown, RequestTimeout
            As for ``image``.
        """
        return self._settings(camera=arguments.camera_name(camera), set=arguments.setting_values(values))

    def _settings(self, **fields: object) -> dict[str, Any]:
        """A settings request: the camera may take SETTINGS_TIMEOUT_S more than the client's
        timeout to answer (a stream restarting), once the service has answered at all: a
        service that does not answer is said within the timeout, as for every other request."""
        if not self._heard:
            self._call("time", 0.0)
        return self._document("settings", commands.SETTINGS_TIMEOUT_S, **fields)

    def _service_identity(self) -> dict[str, Any]:
        if self._identity is None:
            self.status()
        assert self._identity is not None
        return self._identity

    def _answer(self, op: str, options: RequestOptions, **fields: Any) -> Answer:
        """A frame request with the caller's times moved into the service's clock, and the
        reply's moved back. Without ``at``, t* is the moment of the call (the request's
        travel time does not count)."""
        called = self.clock()
        waits_ms = options.timeout_ms
        encoding, quality = options.encoding, options.quality
        mapping = self.clock_estimate()
        last = last_needed(op, fields)  # in the caller's clock
        extra = max(0.0, (waits_ms or 0) / 1000 - self.timeout / 2)
        if last is not None:
            extra += max(0.0, (last - called) / 1e9)
        if op == "sequence" and fields["kind"] == "consecutive" and fields["direction"] != "before" and fields["count"]:
            extra += fields["count"] * self._longest_period_s()
        for key in ("at", "start", "end"):
            if fields.get(key) is not None:
                fields[key] = mapping.to_service(fields[key])
        if op != "latest" and fields.get("at") is None:
            fields["t_call"] = mapping.to_service(called)
        if encoding is not None or quality is not None:
            encoding, quality = checked_encoding(encoding or self.encoding, quality)
        else:
            encoding, quality = self.encoding, self.quality
        if encoding != codec.RAW:
            fields.update(encoding=encoding, quality=quality)
        header, images, check = self._fetch(op, extra, options.copy, timeout_ms=waits_ms, **fields)
        return in_caller_clock(header, mapping), images, check

    def _frame_times(self, cameras: list[str] | None) -> dict[str, Any]:
        return self._document("frames", 0.0, cameras=cameras)

    # ---- plumbing ----

    def _document(self, op: str, extra_wait: float, **fields: object) -> dict[str, Any]:
        """The reply of an op whose body is a document of its own (status, settings, frames: the
        JSON object docs/protocol.md 7 shows, beyond ReplyHeader's fields)."""
        return cast("dict[str, Any]", self._call(op, extra_wait, **fields)[0])

    def _call(self, op: str, extra_wait: float, **fields: object) -> tuple[ReplyHeader, Images]:
        request_id = next(self._ids)
        deadline = time.monotonic() + self.timeout + extra_wait
        sock = self._sock
        # A DEALER with no connected peer (service down, or our keys refused) would
        # block in send: wait for it to become writable within our own deadline.
        # (EVENTS is an int option: pyzmq types every option's value as int | bytes)
        if not cast(int, sock.getsockopt(_EVENTS)) & _POLLOUT and not writable(sock, time.monotonic() + self.timeout):
            raise RequestTimeout(self._handshake.problem(self.endpoint, self._keys is not None) or self._unsendable(op))
        try:
            send_parts(sock, [b"", *protocol.encode_request(op, id=request_id, **fields)])
        except zmq.Again:  # the peer went away between the poll and the send
            raise RequestTimeout(self._unsendable(op)) from None
        while True:
            remaining = deadline - time.monotonic()
            frames = recv_parts(sock, remaining) if remaining > 0 else None
            if frames is None:
                raise RequestTimeout(
                    self._handshake.problem(self.endpoint, self._keys is not None)
                    or unknown_host(self.endpoint)
                    or f"no reply to {op!r} from {self.endpoint} within {self.timeout + extra_wait:.3g} s "
                    "(is the service running?)"
                )
            if frames and len(frames[0]) == 0:
                frames = frames[1:]
            header, images = protocol.decode_reply([f.buffer for f in frames])
            if header.get("id") != request_id:
                continue  # the late reply to an earlier request that timed out
            if not header["ok"]:
                error = header.get("error")
                code, message = (error.get("code", "UNKNOWN"), error.get("message", "")) if error else ("UNKNOWN", "")
                raise service_error(code, message)
            self._heard = True
            return header, images

    def _unsendable(self, op: str) -> str:
        return unknown_host(self.endpoint) or (
            f"could not send {op!r} to {self.endpoint} within "
            f"{self.timeout:.3g} s (is the service running, and are our keys accepted?)"
        )
