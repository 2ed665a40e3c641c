"""How many slots hold ``history`` seconds of a camera, and whether /dev/shm has room for
them: a ring is sized in seconds (``history=SECONDS``) from the camera's frame period, and a
segment that /dev/shm cannot hold is refused before it is created, with the numbers (tmpfs
would otherwise let it be created and kill the writer with SIGBUS on the first page it lacks).
"""

from __future__ import annotations

import math
import os

from fxis_shm.errors import RingError
from fxis_shm.shm.naming import SHM_DIR

SPARE_SLOTS = 2  # the slot being written and one a reader may be copying: not history


def slots_for(history_s: float | None, period_ns: int, default_slots: int) -> int:
    """Slots that hold ``history_s`` seconds at ``period_ns``; ``default_slots`` without a
    history asked for or a period known (a triggered camera has none)."""
    if not history_s or period_ns <= 0:
        return default_slots
    return max(2, math.ceil(history_s * 1e9 / period_ns) + SPARE_SLOTS)


def held_seconds(slots: int, period_ns: int) -> float | None:
    """The history ``slots`` hold at ``period_ns`` (None: no period known)."""
    return round((slots - SPARE_SLOTS) * period_ns / 1e9, 3) if period_ns > 0 and slots > SPARE_SLOTS else None


def shm_free_bytes() -> int:
    stats = os.statvfs(SHM_DIR)
    return stats.f_bavail * stats.f_frsize


def mib(n: float) -> str:
    return f"{n / 2**20:,.0f} MiB" if n >= 2**20 else f"{n / 2**10:,.0f} KiB"


def room_hint(needed: int) -> str:
    """How to give /dev/shm room for ``needed`` more bytes: the size it would need, rounded up
    to a GiB, or, beyond this host's memory, that no size will do."""
    stats = os.statvfs(SHM_DIR)
    used = (stats.f_blocks - stats.f_bfree) * stats.f_frsize
    size_gib = math.ceil((used + needed) / 2**30)
    memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    if size_gib * 2**30 > memory:
        return f"{SHM_DIR} would need {size_gib} GiB, more than this host's {memory / 2**30:.0f} GiB of memory"
    return f"give {SHM_DIR} more room (mount -o remount,size={size_gib}G {SHM_DIR})"


def check_room(needed: int, what: str) -> None:
    """RingError naming the numbers if /dev/shm cannot hold ``needed`` more bytes."""
    free = shm_free_bytes()
    if needed > free:
        raise RingError(
            f"{what} needs {mib(needed)}, and {SHM_DIR} has {mib(free)} free: ask for less history "
            f"(history=, slots=); {room_hint(needed)}"
        )
