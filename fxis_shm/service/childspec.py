"""What the supervisor tells each child process: a typed, versioned spec per
role, sent as JSON on the child's command line and checked by the child before
it does anything else (``python -m MODULE '<json>' READY_FD``).

A spec names the worker module that runs it, so the supervisor starts children
by name and never imports them. Adding a role is a ChildSpec subclass here plus
its module under workers/ (which calls ``workers._child.child_main``).
"""

from __future__ import annotations

import dataclasses
import json
import sys
import types
import typing
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from fxis_shm.errors import SpecError
from fxis_shm.wire.security import ClientKeys, load_pair

S = TypeVar("S", bound="ChildSpec")


@dataclass(frozen=True, kw_only=True)
class ChildSpec:
    ROLE: ClassVar[str]
    MODULE: ClassVar[str]  # run as ``python -m MODULE``, or its main() in a fork of the supervisor
    FORKABLE: ClassVar[bool] = False  # may start as a fork of the supervisor (service/forkstart.py)
    TITLE: ClassVar[str] = ""  # a forked child's process name, as ps and top show it (at most 15 bytes)
    VERSION: ClassVar[int]  # raise it when a field changes meaning, is added or removed

    service: str
    log_level: str = "INFO"
    clock: str = "monotonic"  # the clock every time of the service is in (fxis_shm.core.timebase)

    def to_json(self) -> str:
        return json.dumps({"role": self.ROLE, "version": self.VERSION, **dataclasses.asdict(self)})

    def command(self, ready_fd: int) -> list[str]:
        return [sys.executable, "-m", self.MODULE, self.to_json(), str(ready_fd)]

    @classmethod
    def from_json(cls: type[S], text: str) -> S:
        """The spec, or SpecError saying what does not fit this version of the class."""
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise SpecError(f"{cls.ROLE} spec is not JSON: {exc}") from None
        if not isinstance(data, dict):
            raise SpecError(f"{cls.ROLE} spec must be a JSON object, got {type(data).__name__}")
        role, version = data.pop("role", None), data.pop("version", None)
        if role != cls.ROLE:
            raise SpecError(f"a {cls.ROLE} process was given a spec for {role!r}")
        if version != cls.VERSION:
            raise SpecError(
                f"{cls.ROLE} spec version {version!r}, but this {cls.ROLE} reads version "
                f"{cls.VERSION}: the supervisor and its workers come from different installs"
            )
        hints = typing.get_type_hints(cls)
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - set(fields))
        missing = sorted(
            name
            for name, f in fields.items()
            if name not in data and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        )
        if unknown or missing:
            raise SpecError(f"{cls.ROLE} spec: unknown field(s) {unknown}, missing field(s) {missing}")
        for name, value in data.items():
            if not _fits(value, hints[name]):
                raise SpecError(f"{cls.ROLE} spec: field {name!r} must be {_describe(hints[name])}, got {value!r}")
        return cls(**data)


def _fits(value: Any, hint: Any) -> bool:
    """Does a JSON value fit a field's type (str, int, float, bool, None, dict[str, T], unions, Any)?"""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return True
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, arg) for arg in args)
    if origin is dict:
        return isinstance(value, dict) and all(isinstance(k, str) and _fits(v, args[1]) for k, v in value.items())
    if hint is type(None):
        return value is None
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


def _describe(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")


@dataclass(frozen=True, kw_only=True)
class CameraWorkerSpec(ChildSpec):
    ROLE = "camera"
    MODULE = "fxis_shm.workers.camera"
    FORKABLE = True
    TITLE = "fxis camera"
    VERSION = 4  # 2: lockstep_hz, lockstep_phase_ns; 3: lockstep_clock; 4: realtime

    camera: str
    kind: str  # an entry of fxis_shm.service.camerakinds.KINDS
    options: dict[str, Any]  # typed by the kind's schema; the worker checks them again
    slots: int  # without history_s, or without a frame period to size it by
    time_origin_ns: int  # shared by the service's cameras (synthetic frame times)
    history_s: float | None = None  # seconds the ring holds at the camera's nominal rate
    lockstep_hz: float | None = None  # fire the trigger on the grid k/HZ + phase of lockstep_clock
    lockstep_phase_ns: int = 0
    lockstep_clock: str = "realtime"  # realtime or tai (core.schedule.GRID_CLOCKS)
    realtime: int | None = None  # SCHED_FIFO priority of the trigger timer (service.rtpolicy), None: normal


@dataclass(frozen=True, kw_only=True)
class CoordinatorSpec(ChildSpec):
    ROLE = "coordinator"
    MODULE = "fxis_shm.workers.coordinator"
    FORKABLE = True
    TITLE = "fxis coord"  # "fxis coordinator" is a byte too long for the kernel
    VERSION = 3  # 3: realtime

    endpoint: str
    pub: str
    events: str
    cameras: dict[str, str]  # camera name -> kind
    settings: dict[str, Any]  # request defaults the config changed (core.requestdefaults)
    curve_secret: str | None = None
    curve_clients: str | None = None
    curve_operators: str | None = None  # the keys that may change camera settings (None: every client)
    history: dict[str, float] = dataclasses.field(default_factory=dict)  # camera -> seconds asked for
    realtime: int | None = None  # the service's --realtime priority (its loop runs one below), None: normal


@dataclass(frozen=True, kw_only=True)
class ViewerSpec(ChildSpec):
    """What every process showing the cameras (a client of the service) is told."""

    endpoint: str  # the coordinator it is a client of
    cameras: dict[str, Any]  # camera name -> {"kind", "fps" configured or None}
    curve_secret: str | None = None  # the service's pair, to connect with under CurveZMQ

    def client_keys(self) -> ClientKeys | None:
        """Under CurveZMQ the child connects with the service's own pair (the coordinator lets
        it in, serversockets.AllowedKeys); None without CurveZMQ."""
        if not self.curve_secret:
            return None
        public, secret = load_pair(self.curve_secret)
        return ClientKeys(public, public, secret)


@dataclass(frozen=True, kw_only=True)
class DashboardSpec(ViewerSpec):
    ROLE = "dashboard"
    MODULE = "fxis_shm.workers.dashboard"
    VERSION = 1

    http: str  # HOST:PORT it serves


@dataclass(frozen=True, kw_only=True)
class FoxgloveSpec(ViewerSpec):
    ROLE = "foxglove"
    MODULE = "fxis_shm.workers.foxglove_server"
    VERSION = 1

    foxglove: str  # HOST:PORT of its WebSocket server
    rate_hz: float  # pictures a second per camera, until a viewer sets another rate


@dataclass(frozen=True, kw_only=True)
class Ros2Spec(ViewerSpec):
    """The ROS 2 bridge (fxis_shm.ros2); its ``cameras`` also name each camera's frame_id
    and calibration file (None: size only)."""

    ROLE = "ros2"
    MODULE = "fxis_shm.workers.ros2_bridge"
    VERSION = 3

    domain: int
    namespace: str  # "" or "/a/b"
    tuples_hz: float | None = None
    snapshots: str | None = None  # where NS/snapshot requests write their bags (None: no such topic)
    via: str = "auto"  # "rclpy", "cyclone", or "auto": rclpy where it imports (fxis_shm.ros2.participants)
    python: str | None = None  # the interpreter the bridge runs in (a ROS 2 one), None: the supervisor's
    may_change: bool = True  # NS/settings may change settings, else only read them (service.changers)

    def command(self, ready_fd: int) -> list[str]:
        return [self.python or sys.executable, *super().command(ready_fd)[1:]]


ROLES: dict[str, type[ChildSpec]] = {
    cls.ROLE: cls for cls in (CameraWorkerSpec, CoordinatorSpec, DashboardSpec, FoxgloveSpec, Ros2Spec)
}
