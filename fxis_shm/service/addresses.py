"""Every address ``fxis run`` will listen on, checked before anything starts: every port
(ZeroMQ, the dashboard, the Foxglove server) is bound once here and let go, so that a port in
use stops the start with one line naming the address and the option to change (or
``--port-base``, fxis_shm.service.config), instead of a traceback after the camera workers
have started.
"""

from __future__ import annotations

import errno
import os
import socket
from dataclasses import replace

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import HTTP_OFF, ServiceConfig, http_address
from fxis_shm.wire import defaults
from fxis_shm.wire.endpoints import tcp_host_port

OPTIONS = {
    "endpoint": "--endpoint",
    "pub": "--pub",
    "events": "--events",
    "http": "--http",
    "foxglove": "--foxglove",
}


def check_free(config: ServiceConfig) -> tuple[ServiceConfig, list[str]]:
    """The config with every port checked free to bind; ConfigError for one in use. The
    dashboard on its default address when nobody asked for it is a convenience, not a
    requirement: if that port is taken, the service starts without it, with a warning."""
    warnings = []
    for setting in ("endpoint", "pub", "events"):
        address = tcp_host_port(getattr(config, setting), setting)
        if address is not None and address[1] != 0:  # 0: the system chooses, nothing to clash with
            _probe(*address, setting, getattr(config, setting))
        else:
            _check_ipc(getattr(config, setting), setting)
    for setting in ("http", "foxglove"):
        value = getattr(config, setting)
        if value == HTTP_OFF:
            continue
        try:
            _probe(*http_address(value, setting), setting, value)
        except ConfigError:
            if setting == "http" and not config.http_given and value == defaults.HTTP:
                warnings.append(f"the dashboard's default address {value} is in use: starting without it (give --http)")
                config = replace(config, http=HTTP_OFF)
                continue
            raise
    return config, warnings


def _probe(host: str, port: int, setting: str, shown: str) -> None:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        why = f"{host!r} is not an address of this host ({exc.strerror})"
        raise ConfigError(f"{OPTIONS[setting]} {shown}: {why}") from None
    family, kind, proto, _, sockaddr = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as ZeroMQ and aiohttp bind
        try:
            probe.bind(sockaddr)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise ConfigError(
                    f"{OPTIONS[setting]} {shown}: port {port} is in use (another service?): give "
                    f"{OPTIONS[setting]} another port, or --port-base N to move every port of this service"
                ) from None
            if exc.errno == errno.EADDRNOTAVAIL:
                raise ConfigError(f"{OPTIONS[setting]} {shown}: {host} is not an address of this host") from None
            raise ConfigError(f"{OPTIONS[setting]} {shown}: cannot listen there ({exc.strerror})") from None


def _check_ipc(endpoint: str, setting: str) -> None:
    folder = os.path.dirname(endpoint[len("ipc://") :]) or "."
    if not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        raise ConfigError(f"{OPTIONS[setting]} {endpoint}: {folder} is not a folder this user can write to")


def remove_stale_ipc_files(config: ServiceConfig) -> list[str]:
    """Unlink the socket files of the service's ``ipc://`` endpoints that nothing listens on any
    more (its coordinator has stopped: ZeroMQ leaves them when a process ends without closing its
    sockets); the paths removed."""
    removed = []
    for endpoint in (config.endpoint, config.pub, config.events):
        path = endpoint[len("ipc://") :] if endpoint.startswith("ipc://") else None
        if path is None or not os.path.exists(path):
            continue
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
            try:
                probe.connect(path)
            except ConnectionRefusedError:  # a socket file no one listens on: ours, left
                os.unlink(path)
                removed.append(path)
            except OSError:  # not a socket, or not ours to judge: left as it is
                pass
    return removed
