"""The service lock: an ``flock`` the supervisor holds for its lifetime, so two supervisors of
one name never run at once; the kernel drops it when the supervisor dies, even by kill -9.

It lives where no other user can reach it: ``$XDG_RUNTIME_DIR`` (the user's own 0700 folder,
as systemd makes it), else ``/run/fxis`` for root and ``/tmp/fxis-UID`` for any other user,
each made 0700 and refused when it is a symlink, another user's, or open to others. In a folder
everyone may write, another user could plant a symlink there (the lock's pid written into a file
of theirs choosing) or hold an flock on the name (the service kept from starting). The file is
opened without following a symlink and must be this user's.

The file is never removed: a process that opened it and waits to lock it would then lock a file
no longer there, while a third creates and locks a new one: two supervisors of one name. The
flock alone says whether the service runs; the file stays, a few bytes, until the next boot.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import tempfile

from fxis_shm.errors import ConfigError

ROOT_FOLDER = "/run/fxis"


class LockRefused(ConfigError):
    """The lock's folder or file is not safely this user's: the message says what to fix."""


class AlreadyRunning(ConfigError):
    """Another supervisor of this name holds the lock."""


def _folder_name() -> str:
    uid = os.geteuid()
    return os.environ.get("XDG_RUNTIME_DIR") or (
        ROOT_FOLDER if uid == 0 else os.path.join(tempfile.gettempdir(), f"fxis-{uid}")
    )


def lock_folder() -> str:
    """The folder of this user's service locks, made if it is not there (checked either way)."""
    folder = _folder_name()
    if os.environ.get("XDG_RUNTIME_DIR"):  # the session's own: not ours to make
        return checked_folder(folder)
    try:
        os.mkdir(folder, 0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        raise LockRefused(f"cannot make the lock folder {folder}: {exc.strerror}") from None
    return checked_folder(folder)


def checked_folder(folder: str) -> str:
    """``folder`` if it is a real folder (not a symlink) of this user that no one else may
    enter; else LockRefused saying what is wrong with it."""
    try:
        info = os.lstat(folder)
    except OSError as exc:
        raise LockRefused(f"lock folder {folder}: {exc.strerror}") from None
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        raise LockRefused(f"lock folder {folder} is not a folder (a symlink?); remove it, or set XDG_RUNTIME_DIR")
    if info.st_uid != os.geteuid():
        raise LockRefused(
            f"lock folder {folder} belongs to uid {info.st_uid}, not to this user (uid {os.geteuid()}); "
            "remove it, or set XDG_RUNTIME_DIR"
        )
    if stat.S_IMODE(info.st_mode) & 0o077:
        raise LockRefused(f"lock folder {folder} has mode {stat.S_IMODE(info.st_mode):04o}: chmod 700 it")
    return folder


def lock_path(service: str) -> str:
    """The lock file of ``service`` (its folder made and checked)."""
    return os.path.join(lock_folder(), _file_name(service))


def _file_name(service: str) -> str:
    return f"fxis-{service}.lock"


def _open(path: str, create: bool) -> int:
    """The lock file's descriptor; never through a symlink, and only a regular file of this user."""
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | (os.O_CREAT if create else 0)
    try:
        fd = os.open(path, flags, 0o600)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise LockRefused(f"lock file {path} is a symlink: refusing to follow it") from None
        raise
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_uid != os.geteuid():
        os.close(fd)
        raise LockRefused(f"lock file {path} is not a file of this user (uid {info.st_uid}): remove it")
    return fd


def _try_lock(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _holder(fd: int) -> str:
    return os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"


class ServiceLock:
    """The service's lock, held from here until ``release`` (or the process's end)."""

    def __init__(self, service: str):
        self.path = lock_path(service)
        self._fd = _open(self.path, create=True)
        if not _try_lock(self._fd):
            holder = _holder(self._fd)
            os.close(self._fd)
            raise AlreadyRunning(
                f"service {service!r} is already running (supervisor pid {holder}); "
                "stop it first, or pick another --name"
            )
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, str(os.getpid()).encode(), 0)

    def release(self) -> None:
        """Let go of the lock; the file stays (see the module's note)."""
        os.ftruncate(self._fd, 0)
        os.close(self._fd)


def service_running(service: str) -> bool:
    """Whether a supervisor of ``service`` holds its lock (nothing is made to find out)."""
    folder = _folder_name()
    if not os.path.lexists(folder):
        return False
    path = os.path.join(checked_folder(folder), _file_name(service))
    try:
        fd = _open(path, create=False)
    except FileNotFoundError:
        return False
    try:
        if _try_lock(fd):
            fcntl.flock(fd, fcntl.LOCK_UN)
            return False
        return True
    finally:
        os.close(fd)
