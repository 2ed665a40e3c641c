"""What every command that talks to a service takes: its endpoint, a timeout, and the
CurveZMQ keys of a service that requires them, from flags, the environment or a config file
(the one ``fxis run --config`` reads, with a ``[client]`` table), in that order.

    [client]
    server_key = "keys/server.key"          # the service's public key
    client_key = "keys/robot1.key_secret"   # this client's pair
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from typing import TYPE_CHECKING

from fxis_shm.cli import exitcodes
from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.service.config import load_toml
from fxis_shm.wire import defaults, ranges
from fxis_shm.wire.endpoints import check_endpoint, check_host_known
from fxis_shm.wire.ranges import Range
from fxis_shm.wire.security import ClientKeys

if TYPE_CHECKING:
    from fxis_shm.client.client import Client

EXIT_USAGE = exitcodes.USAGE
ENV_SERVER_KEY, ENV_CLIENT_KEY = "FXIS_SERVER_KEY", "FXIS_CLIENT_KEY"


def ranged(limits: Range) -> Callable[[str], float]:
    """argparse's ``type`` for a number of ``limits`` (fxis_shm.wire.ranges): out of it,
    ArgumentTypeError, which makes it a usage error (exit code 2) naming the flag."""

    def parse(text: str) -> float:
        try:
            return limits.parse(text, "it")
        except InvalidArgument:
            raise argparse.ArgumentTypeError(f"must be {limits.words}, got {text!r}") from None

    parse.__name__ = limits.noun  # argparse names the type by it in a few messages
    return parse


seconds = ranged(ranges.WINDOW_S)  # a snapshot's --before and --after
timeout_seconds = ranged(ranges.TIMEOUT_S)  # every --timeout
duration_seconds = ranged(ranges.DURATION_S)  # how long a command runs
rate_hz = ranged(ranges.RATE_HZ)
milliseconds = ranged(ranges.MILLISECONDS)
percent = ranged(ranges.PERCENT)
nanoseconds = ranged(ranges.AT_NS)  # a time in ns of a clock such as CLOCK_MONOTONIC (its count since boot)


def add_client_options(sp) -> None:
    sp.add_argument("--endpoint", help=f"service endpoint (default: the config file's, else {defaults.ENDPOINT})")
    sp.add_argument(
        "--timeout",
        type=timeout_seconds,
        default=3.0,
        help="seconds to wait for the service's answer, on every command (default 3; at most 3600)",
    )
    add_key_options(sp)


def add_key_options(sp) -> None:
    """--server-key, --client-key and --config: the CurveZMQ keys of ``client_keys_for``."""
    sp.add_argument(
        "--server-key", metavar="FILE", help=f"the service's public key (CurveZMQ; default ${ENV_SERVER_KEY})"
    )
    sp.add_argument(
        "--client-key", metavar="FILE", help=f"this client's .key_secret (CurveZMQ; default ${ENV_CLIENT_KEY})"
    )
    sp.add_argument(
        "--config", metavar="FILE", help="a config file: its endpoint, and server_key and client_key of its [client]"
    )


def client_for(args, endpoints: list[str] | None = None) -> Client:
    """A client as the command's options, the environment and the config file say; with
    ``endpoints`` (a command's ENDPOINT arguments), of those services (one client over them all)."""
    from fxis_shm.client.client import Client  # here: `fxis run` and --help need no client

    file_values = load_toml(args.config) if args.config else {}
    if endpoints:
        for endpoint in endpoints:
            check_host_known(check_endpoint(endpoint, "ENDPOINT"), "ENDPOINT")
        target = endpoints[0] if len(endpoints) == 1 else list(endpoints)
        return Client(target, timeout=args.timeout, keys=client_keys_for(args, file_values))
    endpoint = args.endpoint or file_values.get("endpoint") or defaults.ENDPOINT
    setting = "--endpoint" if args.endpoint else f"--config {args.config}: endpoint" if args.config else "endpoint"
    check_host_known(check_endpoint(endpoint, setting), setting)  # a mistyped one: a line now, not a time-out
    return Client(endpoint, timeout=args.timeout, keys=client_keys_for(args, file_values))


def client_keys_for(args, file_values: dict | None = None) -> ClientKeys | None:
    """The CurveZMQ keys the command's flags, the environment or its config file's [client] name."""
    if file_values is None:
        file_values = load_toml(args.config) if args.config else {}
    client_table = file_values.get("client", {})
    if not isinstance(client_table, dict):
        raise ConfigError(f"--config {args.config}: [client] must be a table (server_key, client_key)")
    server_key = args.server_key or os.environ.get(ENV_SERVER_KEY) or client_table.get("server_key")
    client_key = args.client_key or os.environ.get(ENV_CLIENT_KEY) or client_table.get("client_key")
    return client_keys(server_key, client_key)


def client_keys(server_key: str | None, client_key: str | None) -> ClientKeys | None:
    if not server_key and not client_key:
        return None
    if not (server_key and client_key):
        raise ConfigError(
            "CurveZMQ needs both the service's public key (--server-key) and this client's pair (--client-key)"
        )
    try:
        return ClientKeys.from_files(server_key, client_key)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"CurveZMQ keys {server_key}, {client_key}: {exc}") from None
