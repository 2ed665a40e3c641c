"""The exit codes every ``fxis`` command follows (docs/cli.md, "Exit codes").

A script can tell from the code alone what happened and whether anything was kept. Which error
ends with which code is fxis_shm.errors.ERROR_TABLE; docs/cli.md's table is generated from it
and from ``MEANINGS`` below: ``python -m fxis_shm.cli.exitcodedocs --write docs/cli.md`` (without
``--write``: print it), and tests/unit/test_exitcode_table.py fails when they differ.
"""

from __future__ import annotations

import errno
import sys

from fxis_shm.errors import Exit, exit_code

DONE = Exit.DONE
MISSING = Exit.MISSING
USAGE = Exit.USAGE
NO_SERVICE = Exit.NO_SERVICE
FAILED = Exit.FAILED
SYNC_FAILED = Exit.SYNC_FAILED
INTERRUPTED = Exit.INTERRUPTED

DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)

# per code: what it means, the failures outside ERROR_TABLE that end with it, and examples
MEANINGS: dict[int, tuple[str, str, str]] = {
    DONE: ("done: the command did all it was asked", "", "a tuple saved; `fxis run` stopped by Ctrl-C or SIGTERM"),
    MISSING: (
        "done, but some of what was asked is missing; what is missing is said on screen and in the files' metadata",
        "",
        "a snapshot whose window lost frames, or whose start the rings no longer held; a recording across a "
        "camera restart that cost frames (docs/recording.md)",
    ),
    USAGE: (
        "bad usage or settings: change the command",
        "an `OSError` naming a path the command was given",
        'an unknown or malformed flag; a number out of its range (docs/cli.md, "Ranges"), negative or NaN; '
        "an endpoint without `tcp://`, with a bad port, an unknown host, an IPv6 address or an ipc path too "
        "long; an `--out` that exists and is not empty, is under /proc, on a read-only disk or under a missing "
        "folder; a file that is not a key file; a camera the service does not have; a setting the camera "
        "refuses (`fxis set left gain=30`, `exposure_us=0`, `foo=1`, `gain=nan`); `fxis keys` over an existing "
        "pair without `--force`, or with a `--name` that is not a plain name (`../evil`, `a/b`: `keys`, `run` "
        "and `clean` take 1-48 letters, digits, `_` or `-`); `fxis run` of a name already running, with two "
        "cameras of one name, with `--realtime=require` where SCHED_FIFO cannot be had, or with a camera "
        "setting the camera refuses (a width beyond its maximum, a file that is not there); `fxis clean` "
        "while that service runs; video settings out of range (`--codec`, `--crf`, ... of `record` and "
        "`snapshot`); a snapshot window longer than the rings hold; `fxis export` of a bag without that "
        "camera's video, or to an `--out` that exists; `fxis export --rerun` or `fxis view --rerun` without the "
        "extra `rerun`, or to a file that exists",
    ),
    NO_SERVICE: (
        "a service did not answer: it is down, the endpoint is wrong, or it refuses this client's keys",
        "",
        "`fxis status` with no service at the endpoint",
    ),
    FAILED: (
        "anything else failed at run time: a request the service refused, a full disk",
        "an `OSError` of a full disk, or naming no path",
        "a full disk (the bag kept what fitted, as the line says), or one that cannot hold a few seconds of a "
        "recording, refused before it starts; a camera restarted during a video recording at a size or format "
        "video cannot carry (the bag kept what came before); a refusal by the service (`CAMERA_DOWN`, "
        "`OVERRUN`, ...); a camera that did not become ready in time; `fxis cameras` whose backends did not "
        "finish looking; a Rerun viewer that did not take what `fxis view --rerun` logged",
    ),
    SYNC_FAILED: (
        "done, measured, and a figure missed its limit",
        "",
        '`fxis sync-report` ending in `FAIL` (docs/sync.md, "Proving sync")',
    ),
    INTERRUPTED: (
        "interrupted (Ctrl-C, SIGTERM): stopped, with what was kept said on screen",
        "",
        "Ctrl-C during `fxis snapshot`",
    ),
}


def for_error(exc: BaseException) -> int | None:
    """The code of a failure a user can cause (None: a bug, which shows its traceback)."""
    code = exit_code(exc)  # ERROR_TABLE
    if code is not None:
        return code
    if isinstance(exc, OSError):  # a path the command was given (unwritable, missing), or a full disk
        return FAILED if exc.errno in DISK_FULL or not exc.filename else USAGE
    return None


def one_line(text: str) -> str:
    """``text`` as one line: every run of whitespace, a line break among them (also one a user
    typed in a name: U+0085, U+2028, ...), one space."""
    return " ".join(text.split())


def say(command: str, text: str) -> None:
    """``fxis COMMAND: text`` on stderr, as one line."""
    print(f"fxis {command}: {one_line(text)}", file=sys.stderr)


def message(exc: BaseException) -> str:
    """The error's one line: what is wrong (the message says what to change)."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, OSError) and exit_code(exc) is None:
        where = f"{exc.filename}: " if exc.filename else ""
        room = "; free some room there, or write elsewhere" if exc.errno in DISK_FULL else ""
        return f"{where}{exc.strerror or exc}{room}"
    return one_line(str(exc)) or type(exc).__name__
