"""What each kind of client says of its services (``ClientApi``'s other half): the status,
the service clock and how the caller's maps onto it, the events publisher, and closing. Unlike
the operations (fxis_shm.client.api, written once for every client), each kind of client answers
these itself: one service (fxis_shm.client.single) or several (fxis_shm.client.multiclient)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from fxis_shm.core.clockmap import ClockEstimate


class ServiceApi(ABC):
    """The services behind a client, declared with what each call returns and raises; a
    context manager that closes the client on leaving the block."""

    @abstractmethod
    def events(self) -> Any:
        """An event publisher whose ``at``, ``start`` and ``end`` are in this client's clock, t*
        the moment of the call without ``at``. Answers arrive on ``subscribe()``'s subscriber,
        ``topic(reply_topic)``.

        Returns
        -------
        EventPublisher
            Connected to the service's (or each service's) events endpoint.

        Raises
        ------
        RequestTimeout
            The service's status (which names its events endpoint) did not come in time.
        """

    @abstractmethod
    def status(self) -> dict[str, Any]:
        """The service's status: its cameras, endpoints and clock.

        Returns
        -------
        dict
            The ``status`` reply's body (docs/protocol.md 7.2); a MultiClient's, per endpoint.

        Raises
        ------
        RequestTimeout
            No reply within the client's ``timeout`` (the client stays usable).
        """

    @abstractmethod
    def time(self) -> Any:
        """The service's clock now.

        Returns
        -------
        int
            ns of the clock its status names (CLOCK_MONOTONIC by default); a MultiClient's, per
            endpoint.

        Raises
        ------
        RequestTimeout
            No reply within the client's ``timeout``.
        """

    @property
    @abstractmethod
    def clocks(self) -> dict[str, ClockEstimate]:
        """Each service's clock against the caller's, by endpoint: offset (service minus caller),
        drift, uncertainty and how it is known ("same clock", "shared", "estimated")."""

    @abstractmethod
    def clock_estimate(self) -> ClockEstimate:
        """The current mapping of the caller's clock onto the service's (see ``clocks``).

        Returns
        -------
        ClockEstimate
            Offset (service minus caller), drift and uncertainty, and how it is known.

        Raises
        ------
        RequestTimeout
            The first call asks the service (its status, then a burst of ``time`` requests when
            the clocks must be estimated) and it did not answer.
        """

    @property
    @abstractmethod
    def local_unavailable(self) -> str | None:
        """Why the last request could not use the local path (None: it could, or was not asked to)."""

    @abstractmethod
    def close(self) -> None:
        """Closes the client's sockets and stops its threads."""

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
