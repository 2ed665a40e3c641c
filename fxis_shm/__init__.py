"""fxis-shm: multi-camera acquisition into shared-memory rings, served as
time-synchronized images over ZeroMQ. The public API is what ``__all__`` names
(README.md, "The public API")."""

from fxis_shm import _compiled, _sourcetree  # _compiled first: it chooses how the modules below load
from fxis_shm.client.client import Client
from fxis_shm.client.frames import Frame, FrameTuple
from fxis_shm.client.multiclient import MultiClient
from fxis_shm.client.pubsub import EventPublisher, Message, Subscriber, handshake
from fxis_shm.core.clockmap import ClockEstimate
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
from fxis_shm.formats.stamp import read_stamp
from fxis_shm.wire.security import ClientKeys

__all__ = [
    "Client",
    "MultiClient",
    "ClientKeys",
    "Frame",
    "FrameTuple",
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
compiled = _compiled.check()  # the hot path runs compiled (False: the slow path; said where it runs)
