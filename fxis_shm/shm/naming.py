"""Names of the shared-memory objects of a service, and removal of leftovers.

Every object a service creates carries the prefix ``fxis.<service>.`` so that
the objects of one service can be found (and cleaned) without a registry.
On Linux, POSIX shared memory appears as ``/dev/shm/<name>`` and a named
semaphore as ``/dev/shm/sem.<name>``.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil

import posix_ipc

SHM_DIR = "/dev/shm"
_NAME_RE = re.compile(r"^[A-Za-z0-9_-]{1,48}$")


def check_name(kind: str, name: str) -> str:
    """Return ``name`` if it is a valid service or camera name, else raise ValueError."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ValueError(f"{kind} name {name!r} is invalid: use 1-48 letters, digits, '_' or '-'")
    return name


def prefix(service: str) -> str:
    return f"fxis.{service}."


def ring_name(service: str, camera: str) -> str:
    """posix_ipc name of a camera's ring segment."""
    return f"/{prefix(service)}{camera}.ring"


def semaphore_name(service: str, camera: str) -> str:
    """posix_ipc name of the semaphore posted on every stored frame."""
    return f"/{prefix(service)}{camera}.new"


def trigger_name(service: str, camera: str) -> str:
    """posix_ipc semaphore the coordinator posts to trigger a software-triggered camera."""
    return f"/{prefix(service)}{camera}.trigger"


def commands_dir(service: str) -> str:
    """The folder (mode 0700) holding the command sockets of the service's camera workers."""
    return os.path.join(SHM_DIR, f"{prefix(service)}commands")


_IPC_PATH_MAX = 107  # sun_path holds 108 bytes with its terminating NUL


def command_endpoint(service: str, camera: str) -> str:
    """The ZeroMQ ipc endpoint a camera worker binds for the coordinator's commands. The
    camera's name is the file's, unless the path would not fit a Unix socket address: then
    a digest of it (names are at most 48 characters, so only long pairs of names need it)."""
    path = os.path.join(commands_dir(service), camera)
    if len(path.encode()) > _IPC_PATH_MAX:
        path = os.path.join(commands_dir(service), "h" + hashlib.sha256(camera.encode()).hexdigest()[:16])
    return "ipc://" + path


def supervisor_state_path(service: str) -> str:
    """The supervisor's process table, read by the coordinator for status."""
    return state_path(service, "supervisor")


def state_path(service: str, process: str) -> str:
    """What a process of the service reports for the status (its counters, as JSON)."""
    return os.path.join(SHM_DIR, f"{prefix(service)}{process}.json")


def leftovers(service: str) -> list[str]:
    """Paths under /dev/shm that belong to ``service``."""
    try:
        entries = os.listdir(SHM_DIR)
    except FileNotFoundError:
        return []
    shm = prefix(service)
    sem = "sem." + shm
    return sorted(os.path.join(SHM_DIR, e) for e in entries if e.startswith(shm) or e.startswith(sem))


def remove_leftovers(service: str) -> list[str]:
    """Unlink every shared-memory segment and semaphore of ``service``; return what was removed."""
    removed = []
    for path in leftovers(service):
        entry = os.path.basename(path)
        try:
            if os.path.isdir(path):  # the folder of command sockets
                shutil.rmtree(path)
            elif entry.endswith((".json", ".tmp")):
                os.unlink(path)
            elif entry.startswith("sem."):
                posix_ipc.unlink_semaphore("/" + entry[len("sem.") :])
            else:
                posix_ipc.unlink_shared_memory("/" + entry)
        except (posix_ipc.ExistentialError, FileNotFoundError):
            continue
        removed.append(path)
    return removed
