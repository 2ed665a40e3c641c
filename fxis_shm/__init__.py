"""fxis-shm: multi-camera acquisition into shared-memory rings, served as
time-synchronized images over ZeroMQ."""
from .client import Client, Frame, FrameTuple
from .errors import (
    CameraDown, ConfigError, FrameTimeout, FxisError, LocalPathUnavailable, Overwritten,
    ProtocolError, RequestTimeout, ServiceError, SkewExceeded, UnknownCamera,
)
from .security import ClientKeys
from .stamp import read_stamp

__all__ = [
    "Client", "ClientKeys", "Frame", "FrameTuple", "read_stamp",
    "FxisError", "ConfigError", "ProtocolError", "RequestTimeout", "ServiceError",
    "CameraDown", "UnknownCamera", "SkewExceeded", "FrameTimeout", "LocalPathUnavailable",
    "Overwritten",
]
__version__ = "0.1.0"
