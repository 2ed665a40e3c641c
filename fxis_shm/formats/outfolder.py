"""The folder a command or a call writes into (``fxis grab``, ``fxis record``, ``fxis snapshot``,
``client.snapshot(out=...)``), checked before anything is asked of a service: a new folder
that can be made there, or an empty one that can be written into. A path under /proc, on a
read-only disk, or under a folder that does not exist is then one error naming the path and
what to change, not an OSError half-way through, and the check leaves nothing behind."""

from __future__ import annotations

import errno
import os

from fxis_shm.errors import InvalidArgument


def check_out_folder(path: str, setting: str = "out") -> None:
    """InvalidArgument (naming ``setting``) unless ``path`` can be written into as a new or
    empty folder."""
    try:
        if os.path.lexists(path):
            if not os.path.isdir(path) or os.listdir(path):
                raise InvalidArgument(
                    f"{setting} {path}: exists and is not an empty folder; give a new one, or empty it"
                )
            probe = os.path.join(path, f".fxis-probe-{os.getpid()}")
            os.mkdir(probe)
            os.rmdir(probe)
        else:
            os.mkdir(path)
            os.rmdir(path)
    except OSError as exc:
        raise InvalidArgument(f"{setting} {path}: {_why(path, exc)}") from None


def _why(path: str, exc: OSError) -> str:
    parent = os.path.dirname(os.path.abspath(path))
    if exc.errno == errno.ENOENT and not os.path.isdir(parent):
        return f"the folder {parent} does not exist; create it first, or give another folder"
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"{exc.strerror}: free some room there, or give a folder on another disk"
    return f"cannot write there ({exc.strerror}); give a folder on a disk this user can write to"
