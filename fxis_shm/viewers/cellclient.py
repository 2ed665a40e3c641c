"""The services of a cell as the dashboard reads them while some may be down: a cell's viewer
is started exactly when something is wrong, so it must neither wait for every service nor
stop at one that goes away.

``CellProbe`` asks every service for its status at once, each through a client of its own
(a service that is down costs one timeout, in parallel), and says which answer. ``CellClient``
is ``Client([...])`` over the services that answer, made again whenever that set changes: a
service that comes (back) brings its cameras, one that goes leaves the others' requests
(pictures, partial tuples) unharmed. Each is used by one thread (a ZeroMQ socket is not shared).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from fxis_shm.client.client import Client
from fxis_shm.client.multiclient import MultiClient, joint_status
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import RequestTimeout
from fxis_shm.wire.security import ClientKeys


class CellProbe:
    """Every service's status, asked at once (``status``); the clocks of those that answered."""

    def __init__(self, endpoints: list[str], timeout: float, keys: ClientKeys | None):
        self.clients = [Client(e, timeout=timeout, keys=keys) for e in endpoints]
        self._pool = ThreadPoolExecutor(len(self.clients), thread_name_prefix="dashboard-probe")
        self.clock: Callable[[], int] = self.clients[0].clock
        self.up: tuple[str, ...] = ()  # the services that answered the last look

    def status(self) -> dict:
        """As ``Client([...]).status()``; RequestTimeout if no service answers."""
        try:
            status = joint_status(self.clients, self._pool, self.clock)
        except RequestTimeout:
            self.up = ()
            raise
        self.up = tuple(e for e, answer in status["services"].items() if answer.get("ok", True))
        return status

    @property
    def clocks(self) -> dict[str, ClockEstimate]:
        """The clock of each service that answered the last look (a gone one's is not known now)."""
        return {c.endpoint: c.clock_estimate() for c in self.clients if c.endpoint in self.up}

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        for client in self.clients:
            client.close()


class CellClient:
    """``Client([...])`` over the services ``up`` names, made again when they change."""

    def __init__(self, timeout: float, keys: ClientKeys | None):
        self.timeout, self.keys = timeout, keys
        self.client: MultiClient | None = None
        self.over: tuple[str, ...] = ()

    def over_services(self, up: tuple[str, ...]) -> MultiClient:
        if self.client is None or up != self.over:
            self.close()
            if not up:
                raise RequestTimeout("none of the cell's services answers")
            self.client = Client(list(up), timeout=self.timeout, keys=self.keys)
            self.over = up
        return self.client

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
