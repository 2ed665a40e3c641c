"""The exit codes every ``fxis`` command follows (docs/cli.md, "Exit codes").

A script can tell from the code alone what happened and whether anything was kept.
"""

from __future__ import annotations

import errno

from fxis_shm.errors import (
    ConfigError,
    FxisError,
    InvalidArgument,
    RequestTimeout,
    SettingRejected,
    SpecError,
    UnknownCamera,
)

DONE = 0  # the command did all it was asked
MISSING = 1  # done, but some of what was asked is missing (frames gone, a camera down)
USAGE = 2  # bad usage or settings (a flag, a path, a key file, a config): change the command
NO_SERVICE = 3  # a service did not answer (down, wrong endpoint, wrong keys)
FAILED = 4  # anything else went wrong at run time (a full disk, a refusal by the service)
SYNC_FAILED = 5  # done, measured, and the figures missed a limit (fxis sync-report's FAIL)
INTERRUPTED = 130  # Ctrl-C or SIGTERM: stopped, with what was kept said on screen (128 + SIGINT)

DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def for_error(exc: BaseException) -> int | None:
    """The code of a failure a user can cause (None: a bug, which shows its traceback)."""
    if isinstance(exc, KeyboardInterrupt):
        return INTERRUPTED
    if isinstance(exc, (ConfigError, InvalidArgument, UnknownCamera, SpecError, SettingRejected)):
        return USAGE  # the command, a file it names, or a camera it names is to change
    if isinstance(exc, RequestTimeout):
        return NO_SERVICE  # no answer: down, a wrong endpoint, keys it refuses
    if isinstance(exc, OSError):  # a path the command was given (unwritable, missing), or a full disk
        return FAILED if exc.errno in DISK_FULL or not exc.filename else USAGE
    if isinstance(exc, FxisError):
        return FAILED  # the service refused (CAMERA_DOWN, OVERRUN, ...), a full disk, a start that failed
    return None


def message(exc: BaseException) -> str:
    """The error's one line: what is wrong (the message says what to change)."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, OSError) and not isinstance(exc, FxisError):
        where = f"{exc.filename}: " if exc.filename else ""
        room = "; free some room there, or write elsewhere" if exc.errno in DISK_FULL else ""
        return f"{where}{exc.strerror or exc}{room}"
    return " ".join(str(exc).split()) or type(exc).__name__
