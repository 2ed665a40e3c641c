"""The ROS 2 bridge's settings (``fxis run --ros2``): on or off, the DDS domain, the
namespace of its topics and the rate of its tuple topics, checked before anything starts.

Every ROS name the bridge will use is checked here against ROS's naming rules, so that a
camera name ROS cannot carry is refused at start-up with a message saying which and why.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

from fxis_shm.errors import ConfigError
from fxis_shm.formats import rosnames

KEYS = (
    "ros2",
    "ros2_domain",
    "ros2_namespace",
    "ros2_tuples",
    "ros2_snapshots",
    "ros2_via",
    "ros2_python",
    "ros2_settings",
)
SETTINGS_ACCESS = ("allow", "read")  # NS/settings may change settings, or only read them (service.changers)
VIAS = ("auto", "rclpy", "cyclone")  # how the bridge publishes (docs/ros2.md, "Two ways onto the graph")
DOMAIN_ENV = "ROS_DOMAIN_ID"  # what every ROS 2 node reads
MAX_DOMAIN = 232  # the highest id DDS's port mapping allows (ROS's own advice: 0-101)
MAX_TUPLES_HZ = 120.0


@dataclass(frozen=True)
class Ros2Settings:
    domain: int = 0
    namespace: str = ""  # "" or "/a/b"
    tuples_hz: float | None = None  # joint tuples on NS/tuple/NAME/..., None: no tuple topics
    snapshots: str | None = None  # the folder NS/snapshot requests write their bags into, None: no topic
    via: str = "auto"  # rclpy (a real ROS 2 node), cyclone (no ROS install), auto: rclpy where it imports
    python: str | None = None  # the bridge's interpreter (one that imports rclpy), None: fxis's own
    settings: str | None = None  # "allow", "read", None: read only under --curve-operators (service.changers)


def ros2_settings(
    values: Mapping[str, Any], cameras: Iterable[str], environ: Mapping[str, str] = os.environ
) -> Ros2Settings | None:
    """The bridge's settings from the file and flags (None: no bridge); ConfigError naming the setting."""
    enabled = values.get("ros2", False)
    if not isinstance(enabled, bool):
        raise ConfigError(f"ros2 must be true or false, got {enabled!r}")
    if not enabled:
        given = [k for k in KEYS[1:] if values.get(k) is not None]
        if given:
            raise ConfigError(f"{', '.join(given)} set without ros2: turn the bridge on (--ros2, ros2 = true)")
        return None
    via = _via(values.get("ros2_via"))
    python = _python(values.get("ros2_python"))
    if via == "cyclone" or (via == "auto" and python is None):
        _check_cyclonedds()
    settings = Ros2Settings(
        _domain(values.get("ros2_domain"), environ), _namespace(values.get("ros2_namespace")), via=via, python=python
    )
    tuples = values.get("ros2_tuples")
    if tuples is not None:
        settings = replace(settings, tuples_hz=_rate(tuples))
    access = values.get("ros2_settings")
    if access is not None:
        if access not in SETTINGS_ACCESS:
            raise ConfigError(f"ros2_settings must be one of {', '.join(SETTINGS_ACCESS)}, got {access!r}")
        settings = replace(settings, settings=access)
    if values.get("ros2_snapshots") is not None:
        settings = replace(settings, snapshots=_folder(values["ros2_snapshots"]))
    for camera in cameras:  # every topic the bridge will publish must be a ROS name
        try:
            rosnames.topic(settings.namespace, camera, "image_raw")
        except ValueError as exc:
            raise ConfigError(f"camera {camera!r} cannot be a ROS 2 topic name: {exc}") from None
    return settings


def _domain(value: Any, environ: Mapping[str, str]) -> int:
    setting = "ros2_domain"
    if value is None:
        value, setting = environ.get(DOMAIN_ENV) or "0", DOMAIN_ENV  # unset or empty: ROS's default
    digits = str(value).strip()
    if isinstance(value, bool) or not digits.isdigit() or int(digits) > MAX_DOMAIN:
        raise ConfigError(f"{setting} must be a DDS domain id from 0 to {MAX_DOMAIN}, got {value!r}")
    return int(digits)


def _namespace(value: Any) -> str:
    if value is None or value == "":
        return ""
    try:
        return rosnames.check_namespace(str(value))
    except ValueError as exc:
        raise ConfigError(f"ros2_namespace {value!r}: {exc}") from None


def _rate(value: Any) -> float:
    try:
        rate = float(value) if not isinstance(value, bool) else -1.0
    except (TypeError, ValueError):
        rate = -1.0
    if not 0 < rate <= MAX_TUPLES_HZ:  # also refuses nan
        raise ConfigError(f"ros2_tuples must be a rate in Hz, > 0 and at most {MAX_TUPLES_HZ:g}, got {value!r}")
    return rate


def _folder(value: Any) -> str:
    folder = os.path.abspath(str(value))
    if not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        raise ConfigError(f"ros2_snapshots {value!r}: not a folder this user can write snapshots into")
    return folder


def _via(value: Any) -> str:
    if value is None:
        return "auto"
    if value not in VIAS:
        raise ConfigError(f"ros2_via must be one of {', '.join(VIAS)}, got {value!r}")
    return str(value)


def _python(value: Any) -> str | None:
    """An interpreter for the bridge: a file this user can run (that it imports rclpy and fxis_shm
    is checked by the bridge itself at start, which reports what failed)."""
    if value is None or value == "":
        return None
    path = os.path.abspath(os.path.expanduser(str(value)))
    if not os.path.isfile(path) or not os.access(path, os.X_OK):
        raise ConfigError(f"ros2_python {value!r}: not a Python interpreter this user can run")
    return path


def _check_cyclonedds() -> None:
    """The bridge needs the optional cyclonedds package: say how to get it."""
    try:
        import cyclonedds  # noqa: F401
    except ImportError as exc:
        raise ConfigError(
            f"ros2 needs the cyclonedds package ({exc}): install the \"ros2\" extra, pip install 'fxis-shm[ros2]'"
        ) from None
