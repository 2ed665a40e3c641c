"""The exception hierarchy and the stable error codes that cross the wire.

Every error a caller can see is an ``FxisError``. Errors that the service
reports travel as ``{"code": ..., "message": ...}`` and are raised on the
client as ``ServiceError`` (or the subclass registered for that code).
"""

from __future__ import annotations


class Code:
    """Stable error codes of the wire protocol (docs/protocol.md)."""

    BAD_REQUEST = "BAD_REQUEST"  # malformed message, bad JSON, wrong types
    UNSUPPORTED_VERSION = "UNSUPPORTED_VERSION"
    UNKNOWN_OP = "UNKNOWN_OP"
    UNKNOWN_CAMERA = "UNKNOWN_CAMERA"
    CAMERA_DOWN = "CAMERA_DOWN"  # the camera's worker is not running
    NO_FRAMES = "NO_FRAMES"  # the camera has stored nothing yet
    TIMEOUT = "TIMEOUT"  # the frames waited for did not arrive in time
    SKEW_EXCEEDED = "SKEW_EXCEEDED"  # no tuple meets max_skew_ms
    OUT_OF_RANGE = "OUT_OF_RANGE"  # t* too far in the future, or history not held
    TOO_LARGE = "TOO_LARGE"  # a configured limit was exceeded
    BUSY = "BUSY"  # too many pending requests
    OVERRUN = "OVERRUN"  # the ring came round during every copy attempt: a ring too small, a reader too slow
    SETTING_REFUSED = "SETTING_REFUSED"  # a camera setting unknown, read-only or out of its limits
    FORBIDDEN = "FORBIDDEN"  # this client's key may not do that (changing settings: --curve-operators)
    INTERNAL = "INTERNAL"

    ALL = frozenset(v for k, v in vars().items() if k.isupper() and isinstance(v, str))


class FxisError(Exception):
    """Base class of every error raised by fxis_shm."""


class ConfigError(FxisError):
    """A setting is invalid; the message names the setting."""


class DiskFull(FxisError):
    """Writing a bag stopped because its disk is full (or a quota or the file size limit was
    reached). ``valid``: the bag was closed and holds ``kept`` (messages per topic), over
    ``seconds``, in a file of ``file_bytes``; if not, ``fxis record --recover FOLDER`` makes
    it readable once there is room. ``reason`` is the system's word (``strerror``)."""

    def __init__(
        self,
        message: str,
        *,
        folder: str = "",
        reason: str = "",
        kept: dict[str, int] | None = None,
        seconds: float = 0.0,
        file_bytes: int = 0,
        valid: bool = True,
    ):
        super().__init__(message)
        self.folder, self.reason, self.kept = folder, reason, kept or {}
        self.seconds, self.file_bytes, self.valid = seconds, file_bytes, valid


class SpecError(FxisError):
    """A child process was given a spec it cannot use (another version, a bad field)."""


class InvalidArgument(FxisError, ValueError):
    """A function was called with a value it cannot take; the message says which."""


class BadEndpoint(ConfigError, InvalidArgument):
    """An endpoint that is not ``tcp://HOST:PORT`` or ``ipc://PATH``, or whose host is not
    known here; the message names it and the form."""


class ServiceNotStarted(FxisError, RuntimeError):
    """A service launched from Python (fxis_shm.service.launch) did not come up; the message says why."""


class ProtocolError(FxisError):
    """A message does not follow docs/protocol.md."""

    def __init__(self, message: str, code: str = Code.BAD_REQUEST):
        super().__init__(message)
        self.code = code
        self.message = message


class SettingRefused(FxisError, ValueError):
    """A camera refused a change of its settings (unknown key, read-only, out of its limits);
    the message names the limits, and the camera keeps its old settings."""


class RequestTimeout(FxisError, TimeoutError):
    """The service did not answer within the client's timeout."""


class RingError(FxisError):
    """A shared-memory ring is missing, retired or not of the expected layout."""


class Overwritten(RingError):
    """A frame's slot was overwritten before or while it was copied: the copy is not returned."""


class LocalPathUnavailable(FxisError):
    """The local fast path was required (``Client(local="require")``) but cannot be used;
    the message says why."""


class ServiceError(FxisError):
    """The service answered with an error reply."""

    def __init__(self, code: str, message: str):
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


class SettingRejected(ServiceError):
    """The service's camera refused a change of settings (code SETTING_REFUSED)."""


class CameraDown(ServiceError):
    pass


class UnknownCamera(ServiceError):
    pass


class SkewExceeded(ServiceError):
    pass


class FrameTimeout(ServiceError, TimeoutError):
    pass


class Overrun(ServiceError, Overwritten):
    """The service's ring came round while the frames were copied, at every attempt (code
    OVERRUN): the ring holds too little history for the request, or the reader is too slow."""


_BY_CODE = {
    Code.CAMERA_DOWN: CameraDown,
    Code.UNKNOWN_CAMERA: UnknownCamera,
    Code.SKEW_EXCEEDED: SkewExceeded,
    Code.TIMEOUT: FrameTimeout,
    Code.OVERRUN: Overrun,
    Code.SETTING_REFUSED: SettingRejected,
}


def service_error(code: str, message: str) -> ServiceError:
    """The exception for an error reply with this code."""
    return _BY_CODE.get(code, ServiceError)(code, message)
