"""fxis-shm: multi-camera acquisition into shared-memory rings, served as
time-synchronized images over ZeroMQ. The public API is what ``__all__`` names
(README.md, "The public API")."""

import typing

from fxis_shm import _compiled, _sourcetree  # _compiled first: it chooses how the modules below load
from fxis_shm.errors import (
    BadEndpoint,
    CameraDown,
    ConfigError,
    FrameTimeout,
    FxisError,
    InvalidArgument,
    LocalPathUnavailable,
    Overrun,
    Overwritten,
    ProtocolError,
    RequestTimeout,
    RingError,
    ServiceError,
    SettingRejected,
    SkewExceeded,
    UnknownCamera,
)

if typing.TYPE_CHECKING:
    from fxis_shm.client.client import Client
    from fxis_shm.client.frames import Frame, FrameTuple, FrameView
    from fxis_shm.client.multiclient import MultiClient
    from fxis_shm.client.pubsub import EventPublisher, Message, Subscriber, handshake
    from fxis_shm.core.clockmap import ClockEstimate
    from fxis_shm.formats.stamp import read_stamp
    from fxis_shm.formats.videotracks import VideoSettings
    from fxis_shm.wire.security import ClientKeys

# Imported on first use (PEP 562), not with the package: every process of a service (the
# supervisor, each camera worker, the coordinator) and every `fxis` command imports fxis_shm,
# and the client's modules (OpenCV, the snapshot writer, ...) cost those that never use them
# a third of a CPU-second each: a service's start and stop took 2.4 CPU-s, now 1.4.
_LAZY = {
    "Client": "fxis_shm.client.client",
    "Frame": "fxis_shm.client.frames",
    "FrameTuple": "fxis_shm.client.frames",
    "FrameView": "fxis_shm.client.frames",
    "VideoSettings": "fxis_shm.formats.videotracks",
    "MultiClient": "fxis_shm.client.multiclient",
    "EventPublisher": "fxis_shm.client.pubsub",
    "Message": "fxis_shm.client.pubsub",
    "Subscriber": "fxis_shm.client.pubsub",
    "handshake": "fxis_shm.client.pubsub",
    "ClockEstimate": "fxis_shm.core.clockmap",
    "read_stamp": "fxis_shm.formats.stamp",
    "ClientKeys": "fxis_shm.wire.security",
}

__all__ = [
    "Client",
    "MultiClient",
    "ClientKeys",
    "Frame",
    "FrameView",
    "FrameTuple",
    "VideoSettings",
    "ClockEstimate",
    "Subscriber",
    "EventPublisher",
    "Message",
    "handshake",
    "read_stamp",
    "compiled",
    "FxisError",
    "ConfigError",
    "ProtocolError",
    "RequestTimeout",
    "ServiceError",
    "CameraDown",
    "UnknownCamera",
    "SkewExceeded",
    "FrameTimeout",
    "SettingRejected",
    "LocalPathUnavailable",
    "RingError",
    "Overwritten",
    "InvalidArgument",
    "BadEndpoint",
    "Overrun",
]
__version__ = "0.1.0"

_sourcetree.install(__path__[0])  # fxis_shm.workers from a source checkout, too


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name == "compiled":  # the hot path runs compiled (False: the slow path; said where it runs)
        value = _compiled.check()
    else:
        raise AttributeError(f"module 'fxis_shm' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
