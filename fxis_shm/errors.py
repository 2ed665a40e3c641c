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
    """The camera's worker is not running (code CAMERA_DOWN)."""


class UnknownCamera(ServiceError):
    """The service has no camera of that name (code UNKNOWN_CAMERA)."""


class SkewExceeded(ServiceError):
    """No tuple meets ``max_skew_ms`` (code SKEW_EXCEEDED)."""


class FrameTimeout(ServiceError, TimeoutError):
    """The frames waited for did not arrive within the request's timeout (code TIMEOUT)."""


class Overrun(ServiceError, Overwritten):
    """The service's ring came round while the frames were copied, at every attempt (code
    OVERRUN): the ring holds too little history for the request, or the reader is too slow."""


class BadRequest(ServiceError):
    """The service could not read the request (code BAD_REQUEST)."""


class UnsupportedVersion(ServiceError):
    """The service speaks another protocol version (code UNSUPPORTED_VERSION)."""


class UnknownOp(ServiceError):
    """The service has no such operation (code UNKNOWN_OP)."""


class NoFrames(ServiceError):
    """The camera has stored nothing yet (code NO_FRAMES)."""


class OutOfRange(ServiceError):
    """t* too far in the future, or history the ring no longer holds (code OUT_OF_RANGE)."""


class TooLarge(ServiceError):
    """A limit of the service was exceeded (code TOO_LARGE)."""


class Busy(ServiceError):
    """Too many requests wait already (code BUSY)."""


class Forbidden(ServiceError):
    """This client's key may not do that (code FORBIDDEN)."""


class InternalError(ServiceError):
    """The service failed answering (code INTERNAL)."""


class Exit:
    """The exit codes of every ``fxis`` command (docs/cli.md, "Exit codes"; named again in
    fxis_shm.cli.exitcodes, where the commands take them from)."""

    DONE = 0  # the command did all it was asked
    MISSING = 1  # done, but some of what was asked is missing (frames gone, a camera down)
    USAGE = 2  # bad usage or settings (a flag, a path, a key file, a config): change the command
    NO_SERVICE = 3  # a service did not answer (down, wrong endpoint, wrong keys)
    FAILED = 4  # anything else went wrong at run time (a full disk, a refusal by the service)
    SYNC_FAILED = 5  # done, measured, and the figures missed a limit (fxis sync-report's FAIL)
    INTERRUPTED = 130  # Ctrl-C or SIGTERM: stopped, with what was kept said on screen (128 + SIGINT)


# THE table: each error class, the exit code a command ends with when it is raised, and the
# wire code it travels as (None: raised on this side, never sent). A subclass not named here
# takes the row of its nearest named base (fxis_shm.cli's own errors do). docs/cli.md's
# exit-code table is generated from it (python -m fxis_shm.cli.exitcodedocs), and a test keeps them equal.
ERROR_TABLE: tuple[tuple[type[BaseException], int, str | None], ...] = (
    (FxisError, Exit.FAILED, None),
    (ConfigError, Exit.USAGE, None),
    (InvalidArgument, Exit.USAGE, None),
    (BadEndpoint, Exit.USAGE, None),
    (SpecError, Exit.USAGE, None),
    (SettingRefused, Exit.USAGE, None),
    (RequestTimeout, Exit.NO_SERVICE, None),
    (DiskFull, Exit.FAILED, None),
    (ServiceNotStarted, Exit.FAILED, None),
    (ProtocolError, Exit.FAILED, None),
    (RingError, Exit.FAILED, None),
    (Overwritten, Exit.FAILED, None),
    (LocalPathUnavailable, Exit.FAILED, None),
    (ServiceError, Exit.FAILED, None),
    (UnknownCamera, Exit.USAGE, Code.UNKNOWN_CAMERA),
    (SettingRejected, Exit.USAGE, Code.SETTING_REFUSED),
    (CameraDown, Exit.FAILED, Code.CAMERA_DOWN),
    (SkewExceeded, Exit.FAILED, Code.SKEW_EXCEEDED),
    (FrameTimeout, Exit.FAILED, Code.TIMEOUT),
    (Overrun, Exit.FAILED, Code.OVERRUN),
    (BadRequest, Exit.FAILED, Code.BAD_REQUEST),
    (UnsupportedVersion, Exit.FAILED, Code.UNSUPPORTED_VERSION),
    (UnknownOp, Exit.FAILED, Code.UNKNOWN_OP),
    (NoFrames, Exit.FAILED, Code.NO_FRAMES),
    (OutOfRange, Exit.FAILED, Code.OUT_OF_RANGE),
    (TooLarge, Exit.FAILED, Code.TOO_LARGE),
    (Busy, Exit.FAILED, Code.BUSY),
    (Forbidden, Exit.FAILED, Code.FORBIDDEN),
    (InternalError, Exit.FAILED, Code.INTERNAL),
    (KeyboardInterrupt, Exit.INTERRUPTED, None),
)

_EXIT_OF: dict[type[BaseException], int] = {cls: code for cls, code, _ in ERROR_TABLE}
_BY_CODE: dict[str, type[ServiceError]] = {
    wire: cls for cls, _, wire in ERROR_TABLE if wire is not None and issubclass(cls, ServiceError)
}


def exit_code(exc: BaseException) -> int | None:
    """The exit code of ``exc`` by the table (its nearest named class), None if no row names it."""
    for cls in type(exc).__mro__:
        if cls in _EXIT_OF:
            return _EXIT_OF[cls]
    return None


def service_error(code: str, message: str) -> ServiceError:
    """The exception for an error reply with this code."""
    return _BY_CODE.get(code, ServiceError)(code, message)
