"""The service configuration: defaults, a TOML file, and command-line flags.

Every problem raises ConfigError with a message that names the setting.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field, replace
from typing import Any

from fxis_shm.core.engine import REQUEST_DEFAULTS
from fxis_shm.errors import ConfigError
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.service.options import split_key_values
from fxis_shm.service.ros2config import KEYS as ROS2_KEYS, Ros2Settings, ros2_settings
from fxis_shm.shm.naming import check_name
from fxis_shm.wire import defaults

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

HTTP_OFF = defaults.HTTP_OFF  # of http and foxglove: none
DEFAULT_FOXGLOVE_RATE_HZ = 10.0  # pictures a second per camera to the Foxglove app
MAX_FOXGLOVE_RATE_HZ = 60.0
ZERO_ALLOWED = {"sync_tolerance_ms"}  # 0: always the least skew, however far from t*
# The request defaults a config may change, each of its default's type (max_skew_ms, None
# by default, takes a number of ms)
PORT_BASE_ORDER = ("endpoint", "pub", "events", "http")  # port_base + index
SERVICE_SETTINGS = {key: float if value is None else type(value) for key, value in REQUEST_DEFAULTS.items()}


@dataclass(frozen=True)
class CameraSpec:
    name: str
    kind: str
    options: dict[str, Any]


@dataclass(frozen=True)
class ServiceConfig:
    name: str = defaults.SERVICE
    endpoint: str = defaults.ENDPOINT
    pub: str = defaults.PUB
    events: str = defaults.EVENTS
    slots: int = defaults.SLOTS
    history: float | None = None  # seconds each ring holds, sized from its camera's rate (else slots)
    cameras: tuple[CameraSpec, ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)
    restart_limit: int = defaults.RESTART_LIMIT
    log_level: str = defaults.LOG_LEVEL
    curve_secret: str | None = None  # the service's NAME.key_secret: CURVE on every socket
    curve_clients: str | None = None  # folder of the public keys of the clients allowed in
    insecure_bind: bool = False  # allow non-loopback endpoints without CURVE
    clock: str = "monotonic"  # the clock every time of the service is in (fxis_shm.core.timebase)
    http: str = defaults.HTTP  # HOST:PORT of the live dashboard, or "off"
    http_given: bool = False  # asked for (else the dashboard gives way when its default port is taken)
    foxglove: str = HTTP_OFF  # HOST:PORT of the Foxglove WebSocket server, or "off"
    foxglove_rate: float = DEFAULT_FOXGLOVE_RATE_HZ
    ros2: Ros2Settings | None = None  # the ROS 2 bridge (fxis_shm.service.ros2config), None: off

    @property
    def exposed(self) -> list[str]:
        """Endpoints reachable from other hosts."""
        from fxis_shm.wire.security import is_loopback

        return [e for e in (self.endpoint, self.pub, self.events, *self.viewer_urls.values()) if not is_loopback(e)]

    @property
    def http_url(self) -> str | None:
        """The dashboard's address (None: no dashboard)."""
        return None if self.http == HTTP_OFF else f"http://{self.http}"

    @property
    def foxglove_url(self) -> str | None:
        """The Foxglove WebSocket server's address (None: none)."""
        return None if self.foxglove == HTTP_OFF else f"ws://{self.foxglove}"

    @property
    def viewer_urls(self) -> dict[str, str]:
        """Setting -> address of what serves pictures without CurveZMQ (HTTP, WebSocket)."""
        return {k: v for k, v in (("http", self.http_url), ("foxglove", self.foxglove_url)) if v}

    @property
    def exposed_unencrypted(self) -> list[str]:
        """What other hosts could reach without authentication: every exposed endpoint
        without CurveZMQ, and the dashboard and Foxglove server (no CurveZMQ) in any case."""
        viewers = set(self.viewer_urls.values())
        return [e for e in self.exposed if not self.curve_secret or e in viewers]


def _camera(name: str, kind: str, raw: dict) -> CameraSpec:
    try:
        check_name("camera", name)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return CameraSpec(name, kind, camera_options(name, kind, raw))


def parse_camera_flag(flag: str) -> CameraSpec:
    """``NAME=KIND[:key=value,...]`` as given to ``--camera``."""
    name, sep, rest = flag.partition("=")
    if not sep or not name:
        raise ConfigError(f"--camera {flag!r}: expected NAME=KIND[:key=value,...]")
    kind, _, options = rest.partition(":")
    return _camera(name.strip(), kind.strip(), split_key_values(name, options))


def _check_endpoint(setting: str, endpoint: Any) -> str:
    if not isinstance(endpoint, str) or not endpoint.startswith(("tcp://", "ipc://")):
        raise ConfigError(f"{setting} {endpoint!r}: expected tcp://HOST:PORT or ipc://PATH")
    tcp_host_port(endpoint, setting)
    return endpoint


def tcp_host_port(endpoint: str, setting: str) -> tuple[str, int] | None:
    """(host, port) of a ``tcp://HOST:PORT`` endpoint, None for ``ipc://``; ConfigError if the
    port is missing or is not a number (ZeroMQ would only fail on it later, in the coordinator)."""
    if endpoint.startswith("ipc://"):
        return None
    host, sep, port = endpoint[len("tcp://") :].rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"{setting} {endpoint!r}: expected tcp://HOST:PORT with a port from 0 to 65535")
    return ("0.0.0.0" if host == "*" else host), int(port)


def _with_port_base(config: ServiceConfig, base: Any, given: set[str]) -> ServiceConfig:
    """Ports from ``base`` (requests, streams, events, dashboard: base + 0..3) for every
    address not ``given`` explicitly, on loopback as the defaults are."""
    if isinstance(base, bool) or not isinstance(base, int) or not 1 <= base <= 65535 - len(PORT_BASE_ORDER):
        raise ConfigError(f"port_base must be a port from 1 to {65535 - len(PORT_BASE_ORDER)}, got {base!r}")
    changes: dict[str, Any] = {}
    for index, setting in enumerate(PORT_BASE_ORDER):
        if setting in given:
            continue
        if setting in ("endpoint", "pub", "events"):
            changes[setting] = f"tcp://127.0.0.1:{base + index}"
        elif config.http != HTTP_OFF:  # a dashboard that is on moves with the base
            changes[setting] = f"127.0.0.1:{base + index}"
    return replace(config, **changes)


def http_address(value: str, setting: str = "http") -> tuple[str, int]:
    """``HOST:PORT`` (an IPv6 host in brackets) as (host, port); ConfigError naming ``setting``."""
    host, sep, port = str(value).rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ConfigError(f"{setting} {value!r}: expected HOST:PORT (e.g. {defaults.HTTP}) or {HTTP_OFF!r}")
    return host, int(port)


def _check_http(value: Any, setting: str = "http") -> str:
    if value is False or str(value).lower() == HTTP_OFF:  # http = false in TOML reads as off too
        return HTTP_OFF
    http_address(value, setting)
    return str(value)


def check_foxglove_rate(value: Any, setting: str = "foxglove_rate") -> float:
    """Pictures a second per camera to Foxglove: > 0 and at most MAX_FOXGLOVE_RATE_HZ (a flag's
    text, or a number from the file or from the app's ``rate_hz`` parameter)."""
    try:
        rate = float(value) if isinstance(value, (str, int, float)) and not isinstance(value, bool) else None
    except ValueError:
        rate = None
    if rate is None or not 0 < rate <= MAX_FOXGLOVE_RATE_HZ:  # also refuses nan
        raise ConfigError(
            f"{setting} must be a number of pictures a second, > 0 and at most {MAX_FOXGLOVE_RATE_HZ:g}, got {value!r}"
        )
    return rate


def _check_foxglove_sdk() -> None:
    """The Foxglove server needs the optional foxglove-sdk package: say how to get it."""
    try:
        import foxglove  # noqa: F401
    except ImportError as exc:
        raise ConfigError(
            f"foxglove needs the foxglove-sdk package ({exc}): install the "
            "\"foxglove\" extra, pip install 'fxis-shm[foxglove]'"
        ) from None


def _check_int(setting: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ConfigError(f"{setting} must be an integer >= {minimum}, got {value!r}")
    return value


def load_toml(path: str) -> dict:
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as exc:
        raise ConfigError(f"--config {path}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"--config {path}: not valid TOML: {exc}") from None


def build_config(file_values: dict | None = None, flags: dict | None = None) -> ServiceConfig:
    """Defaults, overridden by the TOML file's values, overridden by flags.

    ``flags`` may hold name, endpoint, pub, slots (None = not given) and
    cameras (a list of --camera strings: they add cameras, or replace
    cameras of the same name).
    """
    file_values = dict(file_values or {})
    flags = {k: v for k, v in (flags or {}).items() if v not in (None, [], ())}
    known = {
        "name",
        "endpoint",
        "pub",
        "events",
        "slots",
        "cameras",
        "restart_limit",
        "log_level",
        "curve_secret",
        "curve_clients",
        "insecure_bind",
        "clock",
        "http",
        "foxglove",
        "foxglove_rate",
        "port_base",
        "history",
        *ROS2_KEYS,
        *SERVICE_SETTINGS,
    }
    file_values.pop("client", None)  # the [client] table: what fxis status, grab, record connect with
    unknown = sorted(set(file_values) - known)
    if unknown:
        raise ConfigError(f"unknown setting(s) {unknown} in the config file; known: {sorted(known)}")
    cameras: dict[str, CameraSpec] = {}
    file_cameras = file_values.pop("cameras", {})
    if not isinstance(file_cameras, dict):
        raise ConfigError("cameras must be a table of [cameras.NAME] sections")
    for name, raw in file_cameras.items():
        if not isinstance(raw, dict) or "kind" not in raw:
            raise ConfigError(f'[cameras.{name}] needs kind = "..."')
        raw = dict(raw)
        cameras[name] = _camera(name, raw.pop("kind"), raw)
    for flag in flags.pop("cameras", []):
        spec = parse_camera_flag(flag)
        cameras[spec.name] = spec
    if not cameras:
        cameras = {s.name: s for s in map(parse_camera_flag, defaults.CAMERAS)}
    values = {**file_values, **flags}
    settings = {}
    for key, kind in SERVICE_SETTINGS.items():
        if key in values:
            settings[key] = _setting(key, kind, values.pop(key))
    config = replace(ServiceConfig(), cameras=tuple(cameras.values()), settings=settings)
    if "name" in values:
        try:
            config = replace(config, name=check_name("service", values["name"]))
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if "endpoint" in values:
        config = replace(config, endpoint=_check_endpoint("endpoint", values["endpoint"]))
    if "pub" in values:
        config = replace(config, pub=_check_endpoint("pub", values["pub"]))
    if "events" in values:
        config = replace(config, events=_check_endpoint("events", values["events"]))
    if "http" in values:
        config = replace(config, http=_check_http(values["http"]), http_given=True)
    if "foxglove" in values:
        config = replace(config, foxglove=_check_http(values["foxglove"], "foxglove"))
        if config.foxglove_url:
            _check_foxglove_sdk()
    if "foxglove_rate" in values:
        config = replace(config, foxglove_rate=check_foxglove_rate(values["foxglove_rate"]))
    if values.get("port_base") is not None:
        config = _with_port_base(config, values["port_base"], {k for k in PORT_BASE_ORDER if k in values})
    config = replace(config, ros2=ros2_settings(values, (c.name for c in config.cameras)))
    endpoints = {"endpoint": config.endpoint, "pub": config.pub, "events": config.events}
    if len(set(endpoints.values())) < len(endpoints):
        raise ConfigError(f"endpoint, pub and events need an address each; got {endpoints}")
    if "slots" in values:
        config = replace(config, slots=_check_int("slots", values["slots"], 2))
    if values.get("history") is not None:
        config = replace(config, history=_setting("history", float, values["history"]))
    if "restart_limit" in values:
        config = replace(config, restart_limit=_check_int("restart_limit", values["restart_limit"], 0))
    config = _security(config, values)
    if "clock" in values:
        from fxis_shm.core.timebase import CLOCK_IDS

        if values["clock"] not in CLOCK_IDS:
            raise ConfigError(f"clock must be one of {', '.join(CLOCK_IDS)}, got {values['clock']!r}")
        config = replace(config, clock=values["clock"])
    if "log_level" in values:
        level = str(values["log_level"]).upper()
        if level not in ("DEBUG", "INFO", "WARNING", "ERROR"):
            raise ConfigError(f"log_level must be DEBUG, INFO, WARNING or ERROR, got {values['log_level']!r}")
        config = replace(config, log_level=level)
    return config


def _setting(key: str, kind: type, value: Any):
    from fxis_shm.core.selection import SYNC_MODES
    from fxis_shm.core.waitpolicy import WAIT_MODES

    choices = {"sync": SYNC_MODES, "wait": WAIT_MODES}.get(key)
    if choices is not None:
        if value not in choices:
            raise ConfigError(f"{key} must be one of {', '.join(choices)}, got {value!r}")
        return value
    try:
        number = kind(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{key} must be a number, got {value!r}") from None
    if kind is int and number != value:
        raise ConfigError(f"{key} must be a whole number, got {value!r}")
    lowest_ok = 0 <= number if key in ZERO_ALLOWED else 0 < number
    if isinstance(value, bool) or not (lowest_ok and number < float("inf")):
        bound = ">= 0" if key in ZERO_ALLOWED else "> 0"
        raise ConfigError(f"{key} must be a finite number {bound}, got {value!r}")
    return number


def _security(config: ServiceConfig, values: dict) -> ServiceConfig:
    secret, clients = values.get("curve_secret"), values.get("curve_clients")
    if bool(secret) != bool(clients):
        raise ConfigError(
            "curve_secret and curve_clients go together: the service's secret key "
            "file and the folder of the client public keys it accepts"
        )
    if secret:
        from fxis_shm.wire.security import load_pair

        try:
            load_pair(secret)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"curve_secret {secret}: {exc}") from None
        if not os.path.isdir(clients) or not any(f.endswith(".key") for f in os.listdir(clients)):
            raise ConfigError(f"curve_clients {clients}: not a folder holding client .key files")
        config = replace(config, curve_secret=secret, curve_clients=clients)
    insecure = values.get("insecure_bind", False)
    if not isinstance(insecure, bool):
        raise ConfigError(f"insecure_bind must be true or false, got {insecure!r}")
    config = replace(config, insecure_bind=insecure)
    what = {"http": "the dashboard", "foxglove": "the Foxglove server"}
    for setting, url in config.viewer_urls.items():
        if url in config.exposed and not insecure:
            raise ConfigError(
                f"{setting} {url.split('://', 1)[1]} can be reached from other hosts, and "
                f"{what[setting]} has no authentication (CurveZMQ does not cover it): bind it to "
                f'127.0.0.1, turn it off ({setting} = "off"), or give insecure_bind to do it anyway'
            )
    zmq_exposed = [e for e in config.exposed if e not in config.viewer_urls.values()]
    if zmq_exposed and not secret and not insecure:
        raise ConfigError(
            f"{', '.join(zmq_exposed)} can be reached from other hosts, and images would travel "
            "unauthenticated: give curve_secret and curve_clients (see fxis keys), or insecure_bind "
            "to do it anyway"
        )
    return config
