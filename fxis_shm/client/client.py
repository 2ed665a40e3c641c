"""``Client``: the one name a caller needs. ``Client(endpoint)`` is a client of one service
(fxis_shm.client.single); ``Client([endpoint_a, endpoint_b])`` one over several
(fxis_shm.client.multiclient), which is made of single-service clients. The choice is made
here, above both, so that neither imports the other's module back."""

from __future__ import annotations

from typing import Any, overload

from fxis_shm.client.multiclient import MultiClient
from fxis_shm.client.single import DEFAULT_ENDPOINT, SingleClient
from fxis_shm.errors import InvalidArgument


class Client(SingleClient):
    """``Client(endpoint, timeout)``: every call raises RequestTimeout after ``timeout`` seconds.

    ``Client([endpoint_a, endpoint_b], timeout=...)``: one client over several services (a
    MultiClient), its options given by keyword."""

    # The checker is told what a call makes: a Client, or for a list of endpoints a MultiClient.
    # Python lets __new__ return another class's instance; mypy's check of __new__ does not (misc).
    # The options are SingleClient's or MultiClient's keywords, passed on as they are.
    @overload
    def __new__(cls, endpoint: str = DEFAULT_ENDPOINT, *args: Any, **kwargs: Any) -> Client: ...
    @overload
    def __new__(cls, endpoint: list[str], *args: Any, **kwargs: Any) -> MultiClient: ...  # type: ignore[misc]

    def __new__(cls, endpoint: str | list[str] = DEFAULT_ENDPOINT, *args: Any, **kwargs: Any) -> Any:
        if cls is Client and isinstance(endpoint, (list, tuple)):
            if args:  # they would be dropped silently: timeout, keys, ... are keywords there
                raise InvalidArgument("Client([endpoint, ...]) takes its options by keyword (timeout=..., keys=...)")
            return MultiClient(endpoint, **kwargs)
        return super().__new__(cls)
