"""fxis-shm: multi-camera acquisition into shared-memory rings, served as
time-synchronized images over ZeroMQ. The public API is what ``__all__`` names
(README.md, "The public API")."""

from . import _sourcetree
from .client import Client, Frame, FrameTuple
from .clockmap import ClockEstimate
from .errors import (
    CameraDown,
    ConfigError,
    FrameTimeout,
    FxisError,
    InvalidArgument,
    LocalPathUnavailable,
    Overwritten,
    ProtocolError,
    RequestTimeout,
    RingError,
    ServiceError,
    SkewExceeded,
    UnknownCamera,
)
from .multiclient import MultiClient
from .pubsub import EventPublisher, Message, Subscriber, handshake
from .security import ClientKeys
from .stamp import read_stamp

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
    "FxisError",
    "ConfigError",
    "ProtocolError",
    "RequestTimeout",
    "ServiceError",
    "CameraDown",
    "UnknownCamera",
    "SkewExceeded",
    "FrameTimeout",
    "LocalPathUnavailable",
    "RingError",
    "Overwritten",
    "InvalidArgument",
]
__version__ = "0.1.0"

_sourcetree.install(__path__[0])  # fxis_shm.workers from a source checkout, too
