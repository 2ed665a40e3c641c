"""The service configuration: defaults, a TOML file, and command-line flags.

Every problem raises ConfigError with a message that names the setting.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field, replace
from typing import Any

from fxis_shm.core.requestdefaults import REQUEST_DEFAULTS
from fxis_shm.core.schedule import check_grid_clock, parse_lockstep
from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.service.options import split_key_values
from fxis_shm.service.ros2config import KEYS as ROS2_KEYS, Ros2Settings, ros2_settings
from fxis_shm.service.rtpolicy import Realtime, parse_realtime
from fxis_shm.service.viewertokens import ViewerAccess, check_viewer_files, read_token_file, viewer_token
from fxis_shm.shm.naming import check_name
from fxis_shm.wire import defaults, ranges
from fxis_shm.wire.endpoints import check_endpoint

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
    lockstep: tuple[float, int] | None = None  # (hz, phase_ns): trigger on the grid k/hz + phase of lockstep_clock
    lockstep_clock: str = "realtime"  # the clock the grid is counted in (core.schedule.GRID_CLOCKS)
    realtime: Realtime | None = None  # SCHED_FIFO for the capture and request path (service.rtpolicy)
    cameras: tuple[CameraSpec, ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)
    restart_limit: int = defaults.RESTART_LIMIT
    restart_window_s: float = defaults.RESTART_WINDOW_S  # the restart limit counts the crashes of this long
    log_level: str = defaults.LOG_LEVEL
    curve_secret: str | None = None  # the service's NAME.key_secret: CURVE on every socket
    curve_clients: str | None = None  # folder of the public keys of the clients allowed in
    curve_operators: str | None = None  # folder of the keys that may change camera settings (None: every client)
    insecure_bind: bool = False  # allow non-loopback endpoints without CURVE
    clock: str = "monotonic"  # the clock every time of the service is in (fxis_shm.core.timebase)
    http: str = defaults.HTTP  # HOST:PORT of the live dashboard, or "off"
    http_given: bool = False  # asked for (else the dashboard gives way when its default port is taken)
    foxglove: str = HTTP_OFF  # HOST:PORT of the Foxglove WebSocket server, or "off"
    foxglove_rate: float = DEFAULT_FOXGLOVE_RATE_HZ
    viewer_token_file: str | None = None  # the viewers' token (else a random one where one is needed)
    operator_token_file: str | None = None  # the token the dashboard requires to change settings (service.changers)
    viewer_tls_cert: str | None = None  # PEM certificate and key: the viewers serve https and wss
    viewer_tls_key: str | None = None
    ros2: Ros2Settings | None = None  # the ROS 2 bridge (fxis_shm.service.ros2config), None: off

    @property
    def exposed(self) -> list[str]:
        """Endpoints reachable from other hosts."""
        from fxis_shm.wire.security import is_loopback

        return [e for e in (self.endpoint, self.pub, self.events, *self.viewer_urls.values()) if not is_loopback(e)]

    @property
    def http_url(self) -> str | None:
        """The dashboard's address (None: no dashboard)."""
        return None if self.http == HTTP_OFF else f"{'https' if self.viewer_tls_cert else 'http'}://{self.http}"

    @property
    def foxglove_url(self) -> str | None:
        """The Foxglove WebSocket server's address (None: none)."""
        return None if self.foxglove == HTTP_OFF else f"{'wss' if self.viewer_tls_cert else 'ws'}://{self.foxglove}"

    @property
    def viewer_urls(self) -> dict[str, str]:
        """Setting -> address of what serves pictures without CurveZMQ (HTTP, WebSocket)."""
        return {k: v for k, v in (("http", self.http_url), ("foxglove", self.foxglove_url)) if v}

    @property
    def token_viewers(self) -> list[str]:
        """The viewers (settings) that require the token: every one with a token file, else
        those other hosts reach, unless insecure_bind says no."""
        return [
            setting
            for setting, url in self.viewer_urls.items()
            if self.viewer_token_file or (url in self.exposed and not self.insecure_bind)
        ]

    @property
    def exposed_unencrypted(self) -> list[str]:
        """What other hosts could reach without authentication: every exposed endpoint
        without CurveZMQ, and the dashboard and Foxglove server (no CurveZMQ) without a token."""
        open_viewers = {url for setting, url in self.viewer_urls.items() if setting not in self.token_viewers}
        zmq = set(self.exposed) - set(self.viewer_urls.values())
        return [e for e in self.exposed if e in open_viewers or (e in zmq and not self.curve_secret)]


def viewer_accesses(config: ServiceConfig) -> dict[str, ViewerAccess]:
    """Setting -> access of each viewer that is on. One token for them all: the token file's,
    else a new random one (secrets), made only if some viewer requires it."""
    needing, token = config.token_viewers, None
    if needing:
        token = viewer_token(config.viewer_token_file)
    return {
        setting: ViewerAccess(token if setting in needing else None, config.viewer_tls_cert, config.viewer_tls_key)
        for setting in config.viewer_urls
    }


def _camera(name: str, kind: str, raw: dict[str, Any]) -> CameraSpec:
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


def _in_range(setting: str, value: Any, limits: ranges.Range, *, text: bool = False) -> Any:
    """A number of the config file or a flag within ``limits`` (``text``: a flag's text taken
    too), else ConfigError."""
    try:
        return limits.parse(value, setting) if text and isinstance(value, str) else limits.check(value, setting)
    except InvalidArgument as exc:
        raise ConfigError(str(exc)) from None


def load_toml(path: str) -> dict[str, Any]:
    try:
        with open(path, "rb") as f:
            table: dict[str, Any] = tomllib.load(f)
            return table
    except OSError as exc:
        raise ConfigError(f"--config {path}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"--config {path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # TOML is UTF-8
        raise ConfigError(f"--config {path}: not UTF-8 text (byte {exc.start}): a config file is TOML") from None


def build_config(file_values: dict[str, Any] | None = None, flags: dict[str, Any] | None = None) -> ServiceConfig:
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
        "restart_window_s",
        "log_level",
        "curve_secret",
        "curve_clients",
        "curve_operators",
        "insecure_bind",
        "clock",
        "http",
        "foxglove",
        "foxglove_rate",
        "viewer_token_file",
        "operator_token_file",
        "viewer_tls_cert",
        "viewer_tls_key",
        "port_base",
        "history",
        "lockstep",
        "lockstep_clock",
        "realtime",
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
    flagged: set[str] = set()
    for flag in flags.pop("cameras", []):
        spec = parse_camera_flag(flag)
        if spec.name in flagged:  # (a flag may replace the file's camera of its name, not another flag's)
            raise ConfigError(f"--camera {flag!r}: a camera named {spec.name!r} is given twice; give each a name")
        flagged.add(spec.name)
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
        config = replace(config, endpoint=check_endpoint(values["endpoint"], "endpoint", bind=True))
    if "pub" in values:
        config = replace(config, pub=check_endpoint(values["pub"], "pub", bind=True))
    if "events" in values:
        config = replace(config, events=check_endpoint(values["events"], "events", bind=True))
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
        config = replace(config, slots=_in_range("slots", values["slots"], ranges.SLOTS))
    if values.get("history") is not None:
        config = replace(config, history=_in_range("history", values["history"], ranges.HISTORY_S, text=True))
    if values.get("lockstep") is not None:
        try:
            config = replace(config, lockstep=parse_lockstep(str(values["lockstep"])))
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if values.get("lockstep_clock") is not None:
        try:
            config = replace(config, lockstep_clock=check_grid_clock(str(values["lockstep_clock"])))
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    if "realtime" in values:
        config = replace(config, realtime=parse_realtime(values["realtime"]))
    if "restart_limit" in values:
        config = replace(
            config, restart_limit=_in_range("restart_limit", values["restart_limit"], ranges.RESTART_LIMIT)
        )
    if values.get("restart_window_s") is not None:
        config = replace(config, restart_window_s=_number("restart_window_s", float, values["restart_window_s"]))
    config = _security(config, values)
    if "clock" in values:
        from fxis_shm.core.timebase import CLOCK_IDS, short_name

        clock = short_name(values["clock"])
        if clock not in CLOCK_IDS:
            raise ConfigError(f"clock must be one of {', '.join(CLOCK_IDS)}, got {values['clock']!r}")
        config = replace(config, clock=clock)
    if "log_level" in values:
        level = str(values["log_level"]).upper()
        if level not in ("DEBUG", "INFO", "WARNING", "ERROR"):
            raise ConfigError(f"log_level must be DEBUG, INFO, WARNING or ERROR, got {values['log_level']!r}")
        config = replace(config, log_level=level)
    return config


def _setting(key: str, kind: type[int] | type[float], value: Any) -> str | float:
    """A request default of the config file: a mode of its choices, or a number (``_number``)."""
    from fxis_shm.core.selection import SYNC_MODES
    from fxis_shm.core.waitpolicy import WAIT_MODES

    choices = {"sync": SYNC_MODES, "wait": WAIT_MODES}.get(key)
    if choices is None:
        return _number(key, kind, value)
    if value not in choices:
        raise ConfigError(f"{key} must be one of {', '.join(choices)}, got {value!r}")
    mode: str = value
    return mode


def _number(key: str, kind: type[int] | type[float], value: Any) -> float:
    """A number of ``kind``, finite and above 0 (or 0 too, for the keys of ZERO_ALLOWED), else ConfigError."""
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


def _security(config: ServiceConfig, values: dict[str, Any]) -> ServiceConfig:
    secret, clients = values.get("curve_secret"), values.get("curve_clients")
    if bool(secret) != bool(clients):
        raise ConfigError(
            "curve_secret and curve_clients go together: the service's secret key "
            "file and the folder of the client public keys it accepts"
        )
    if secret and clients:  # (both or neither, as just checked)
        from fxis_shm.wire.security import load_pair

        try:
            load_pair(secret)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"curve_secret {secret}: {exc}") from None
        if not os.path.isdir(clients) or not any(f.endswith(".key") for f in os.listdir(clients)):
            raise ConfigError(f"curve_clients {clients}: not a folder holding client .key files")
        config = replace(config, curve_secret=secret, curve_clients=clients)
    operators = values.get("curve_operators")
    if operators:
        if not secret:
            raise ConfigError(
                "curve_operators needs curve_secret and curve_clients: without CurveZMQ no client has a key"
            )
        if not os.path.isdir(operators) or not any(f.endswith(".key") for f in os.listdir(operators)):
            raise ConfigError(f"curve_operators {operators}: not a folder holding .key files")
        config = replace(config, curve_operators=operators)
    insecure = values.get("insecure_bind", False)
    if not isinstance(insecure, bool):
        raise ConfigError(f"insecure_bind must be true or false, got {insecure!r}")
    config = _viewer_access(replace(config, insecure_bind=insecure), values)
    zmq_exposed = [e for e in config.exposed if e not in config.viewer_urls.values()]
    if zmq_exposed and not secret and not insecure:
        raise ConfigError(
            f"{', '.join(zmq_exposed)} can be reached from other hosts, and images would travel "
            "unauthenticated: give curve_secret and curve_clients (see fxis keys), or insecure_bind "
            "to do it anyway"
        )
    return config


def _viewer_access(config: ServiceConfig, values: dict[str, Any]) -> ServiceConfig:
    """The viewers' token file and TLS files, and the dashboard's operator token file (its own
    token, never the viewers'), checked now: a bad one stops the start here."""
    files = ("viewer_token_file", "viewer_tls_cert", "viewer_tls_key", "operator_token_file")
    token_file, cert, key, operator_file = (values.get(k) or None for k in files)
    for setting, value in zip(files, (token_file, cert, key, operator_file), strict=True):
        if value is not None and not isinstance(value, str):
            raise ConfigError(f"{setting} must be the path of a file, got {value!r}")
    check_viewer_files(token_file, cert, key)
    operator = read_token_file(operator_file, files[3]) if operator_file else None
    if operator is not None and token_file and operator == read_token_file(token_file):
        raise ConfigError(f"{files[3]} {operator_file} holds the viewer token: give the operators a token of their own")
    return replace(
        config,
        viewer_token_file=token_file,
        viewer_tls_cert=cert,
        viewer_tls_key=key,
        operator_token_file=operator_file,
    )
