"""One client over several services: whatever ``Client(endpoint)`` does, over the cameras of
all of them as one set, every time in the caller's clock.

Requests are answered by fxis_shm.client.jointrequests (one engine over every service's
frame times); streams and events by fxis_shm.client.multistreams, joint tuple streams by
fxis_shm.client.tuplestream. Status, time and clocks are asked of every service at once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fxis_shm.client.api import ClientApi
from fxis_shm.client.frames import Answer
from fxis_shm.client.jointrequests import JointRequests
from fxis_shm.client.multistreams import MultiEventPublisher, MultiSubscriber
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.client.single import SingleClient
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import ConfigError, FxisError, InvalidArgument, RequestTimeout
from fxis_shm.wire import ranges
from fxis_shm.wire.endpoints import check_endpoint


class MultiClient(ClientApi):
    """``MultiClient(["tcp://hostA:5555", "tcp://hostB:5555"])`` (what ``Client([...])``
    makes): the methods of ``Client`` over the cameras of every service. Camera names must be
    unique across the services. Times are in the caller's clock (``clock``); the other
    options are ``Client``'s, the same for every service."""

    def __init__(
        self,
        endpoints: Sequence[str],
        *,
        timeout: float = 2.0,
        clock: Callable[[], int] | str | None = None,
        **client_options: Any,  # SingleClient's keywords, the same for every service
    ):
        ranges.TIMEOUT_S.check(timeout, "timeout")
        if not endpoints:
            raise ConfigError("a client over several services needs at least one endpoint")
        for endpoint in endpoints:  # all checked before any socket is made
            check_endpoint(endpoint)
        self.endpoints = list(endpoints)
        self.timeout = timeout
        self._options = {"timeout": timeout, "clock": clock, **client_options}
        self.clients = [SingleClient(e, timeout=timeout, clock=clock, **client_options) for e in endpoints]
        self.clock = self.clients[0].clock
        self._clock_name = self.clients[0]._clock_name
        self._pool = ThreadPoolExecutor(max_workers=len(self.clients), thread_name_prefix="fxis-multi-status")
        self._requests: JointRequests | None = None
        try:
            self.owner: dict[str, SingleClient] = {}
            for client in self.clients:
                self._learn(client)
            self._requests = JointRequests(self.owner, self.clock, timeout)
        except BaseException:
            self.close()
            raise
        self.cameras = self._requests.cameras
        self.engine = self._requests.engine

    def _learn(self, client: SingleClient) -> None:
        status = client.status()
        for name in status["cameras"]:
            if name in self.owner:
                raise ConfigError(
                    f"camera {name!r} is served by both {self.owner[name].endpoint} and "
                    f"{client.endpoint}: camera names must be unique across services"
                )
            self.owner[name] = client
        client.clock_estimate()  # the first estimate now, not in the first request

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        if self._requests is not None:
            self._requests.close()
        for client in self.clients:
            client.close()

    # ---- the services ----

    def status(self) -> dict[str, Any]:
        """Every service's status and the cameras of all as one set: ``services`` maps each
        endpoint to its status (or ``{"ok": False, "error": ...}`` for one that does not
        answer; it is left out of the rest), ``cameras`` each camera's status with its
        ``service``, ``now`` the caller's clock. Raises only when no service answers."""
        return joint_status(self.clients, self._pool, self.clock)

    def time(self) -> dict[str, int]:
        """Each service's clock now (int ns of the clock its status names), by endpoint;
        RequestTimeout naming a service that does not answer."""
        return _each(dict(zip(self.endpoints, self._pool.map(_or_error, [c.time for c in self.clients]))))

    @property
    def clocks(self) -> dict[str, ClockEstimate]:
        """Each service's clock against the caller's (see ``Client.clocks``), by endpoint."""
        return {c.endpoint: c.clock_estimate() for c in self.clients}

    def clock_estimate(self, service: str | None = None) -> ClockEstimate:
        """The mapping of the caller's clock onto ``service``'s (an endpoint; may be left out
        when there is one service). ``clocks`` has them all."""
        if service is None and len(self.clients) == 1:
            return self.clients[0].clock_estimate()
        for client in self.clients:
            if client.endpoint == service:
                return client.clock_estimate()
        raise InvalidArgument(f"clock_estimate(service) needs one of {self.endpoints}, got {service!r}; or see clocks")

    def settings(self, camera: str, *, features: bool = False) -> dict[str, Any]:
        """As ``Client.settings``, asked of the service that has ``camera``."""
        return self.owner[self._known([camera])[0]].settings(camera, features=features)

    def configure(self, camera: str, **values: object) -> dict[str, Any]:
        """As ``Client.configure``, on the service that has ``camera``."""
        return self.owner[self._known([camera])[0]].configure(camera, **values)

    def _frame_times(self, cameras: list[str] | None) -> dict[str, Any]:
        """Every service's answer together, each camera named with its ``service``."""
        names = self._known(cameras or list(self.owner))
        merged: dict[str, Any] = {"cameras": {}, "columns": None}
        for client in self.clients:
            mine = [n for n in names if self.owner[n] is client]
            if mine:
                times = client.frame_times(mine)
                merged["columns"] = times["columns"]
                merged["cameras"].update(
                    {n: {**info, "service": client.endpoint} for n, info in times["cameras"].items()}
                )
        return merged

    @property
    def local_unavailable(self) -> str | None:
        """Why the last requests could not use the local path, per service (None: they could)."""
        reasons = [f"{c.endpoint}: {c.local_unavailable}" for c in self.clients if c.local_unavailable]
        return "; ".join(reasons) or None

    # ---- what ClientApi's operations ask of several services ----

    def _answer(self, op: str, options: RequestOptions, **fields: Any) -> Answer:
        """Answered by one engine over every service's frame times (fxis_shm.client.jointrequests)."""
        assert self._requests is not None
        return self._requests.answer(op, options, **fields)

    def _owners(self, cameras: list[str] | None) -> dict[str, SingleClient]:
        return {name: self.owner[name] for name in self._known(cameras or list(self.owner))}

    def _subscriber(self, timeout: float, queue: int) -> MultiSubscriber:
        """Every service's streams: ``frames(camera)`` of any camera, and ``tuples(rate_hz)``,
        joint tuples across the services (fxis_shm.client.tuplestream)."""
        return MultiSubscriber(self.clients, self.owner, self._options, timeout, queue)

    def events(self) -> MultiEventPublisher:
        """Event requests in the caller's clock, each to the service of the cameras it names;
        answers arrive on ``subscribe()``'s subscriber, ``topic(reply_topic)``."""
        return MultiEventPublisher(self.clients, self.owner)

    # ---- helpers ----

    def _known(self, names: list[str]) -> list[str]:
        unknown = [n for n in names if n not in self.owner]
        if unknown:
            raise ConfigError(f"unknown camera(s) {unknown}; the services have {sorted(self.owner)}")
        return names


def joint_status(clients: list[SingleClient], pool: ThreadPoolExecutor, clock: Callable[[], int]) -> dict[str, Any]:
    """The status of several services asked at once, as ``MultiClient.status`` returns it."""
    answers = {c.endpoint: a for c, a in zip(clients, pool.map(_or_error, [c.status for c in clients]))}
    if all(isinstance(a, FxisError) for a in answers.values()):
        raise RequestTimeout(f"none of the services answers: {_errors(answers)}")
    cameras: dict[str, Any] = {}
    for endpoint, answer in answers.items():
        if not isinstance(answer, FxisError):
            cameras.update({name: {**cam, "service": endpoint} for name, cam in answer["cameras"].items()})
    return {
        "op": "status",
        "now": clock(),
        "ok": not any(isinstance(a, FxisError) for a in answers.values()),
        "services": {e: {"ok": False, "error": str(a)} if isinstance(a, FxisError) else a for e, a in answers.items()},
        "cameras": cameras,
    }


def _or_error(call: Callable[[], Any]) -> Any:
    """What ``call`` returns, or the FxisError it raises (one service's answer among several)."""
    try:
        return call()
    except FxisError as exc:
        return exc


def _errors(answers: dict[str, Any]) -> str:
    return "; ".join(f"{e}: {a}" for e, a in answers.items() if isinstance(a, FxisError))


def _each(answers: dict[str, Any]) -> dict[str, Any]:
    """The answers by endpoint, or RequestTimeout naming the first service that did not answer."""
    for endpoint, answer in answers.items():
        if isinstance(answer, FxisError):
            raise RequestTimeout(f"the service at {endpoint} does not answer: {answer}") from answer
    return answers
