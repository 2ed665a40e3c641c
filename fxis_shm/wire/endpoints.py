"""The one check of an endpoint's form, for every place that takes one: ``fxis run``'s
settings, ``Client(...)`` and every command's ``--endpoint``. ZeroMQ would refuse a wrong
one only as ``ZMQError: Invalid argument``, or never (a bad port, an unknown host: a
request that times out), so the mistake is named here, with the form to use."""

from __future__ import annotations

import socket

from fxis_shm.errors import BadEndpoint

FORM = "tcp://HOST:PORT or ipc://PATH"
IPC_PATH_MAX = 107  # bytes of a Unix socket's path the kernel takes (sun_path, less its closing NUL)


def check_endpoint(endpoint: object, setting: str = "endpoint", *, bind: bool = False) -> str:
    """``endpoint`` if it is ``tcp://HOST:PORT`` (a port 1-65535; 0 too where it is bound: any
    free port) or ``ipc://PATH``; else BadEndpoint naming ``setting`` and the form."""
    if not isinstance(endpoint, str) or not endpoint.startswith(("tcp://", "ipc://")):
        hint = f" (e.g. tcp://{endpoint})" if isinstance(endpoint, str) and endpoint and "://" not in endpoint else ""
        raise BadEndpoint(f"{setting} {endpoint!r}: expected {FORM}{hint}")
    tcp_host_port(endpoint, setting, bind=bind)
    return endpoint


def tcp_host_port(endpoint: str, setting: str, *, bind: bool = True) -> tuple[str, int] | None:
    """(host, port) of a ``tcp://HOST:PORT`` endpoint, None for ``ipc://``; BadEndpoint if the
    port is missing, not a number or out of range."""
    if endpoint.startswith("ipc://"):
        path = endpoint[len("ipc://") :]
        if not path or "\0" in path:
            raise BadEndpoint(f"{setting} {endpoint!r}: expected ipc://PATH with a path")
        size = len(path.encode(errors="surrogateescape"))
        if size > IPC_PATH_MAX:
            raise BadEndpoint(
                f"{setting} ipc://...{path[-40:]!r}: its path is {size} bytes, the kernel takes at most "
                f"{IPC_PATH_MAX}; give a shorter one (e.g. under /tmp)"
            )
        return None
    host, sep, port = endpoint[len("tcp://") :].rpartition(":")
    if ":" in host or host.startswith("["):  # ZeroMQ's sockets here are IPv4 (no IPV6 option set)
        raise BadEndpoint(
            f"{setting} {endpoint!r}: IPv6 addresses are not supported; give an IPv4 address or a host name "
            "(e.g. tcp://127.0.0.1:PORT)"
        )
    lowest = 0 if bind else 1
    if not sep or not host or not port.isdigit() or not lowest <= int(port) <= 65535:
        raise BadEndpoint(f"{setting} {endpoint!r}: expected tcp://HOST:PORT with a port from {lowest} to 65535")
    if not bind and host in ("*", "0.0.0.0"):
        raise BadEndpoint(
            f"{setting} {endpoint!r}: {host} is where a service listens; connect to tcp://HOST:PORT, HOST its "
            "name or address"
        )
    return ("0.0.0.0" if host == "*" else host), int(port)


def unknown_host(endpoint: str, setting: str = "endpoint") -> str | None:
    """What is wrong if the host of a ``tcp://`` endpoint has no address here (a mistyped
    name: ZeroMQ would only keep trying, and a request time out); None if it has one."""
    address = tcp_host_port(endpoint, setting, bind=False)
    if address is None:
        return None
    try:
        socket.getaddrinfo(address[0], address[1], socket.AF_INET, socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError):
        return (
            f"{setting} {endpoint!r}: the host {address[0]!r} is not known here (no IPv4 address: check its name, "
            "or give its address)"
        )
    return None


def check_host_known(endpoint: str, setting: str = "endpoint") -> None:
    """BadEndpoint if the host of a ``tcp://`` endpoint has no address here."""
    problem = unknown_host(endpoint, setting)
    if problem:
        raise BadEndpoint(problem)
