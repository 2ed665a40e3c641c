"""Ordered accesses for the ring's seqlock, on every CPU the service supports.

The seqlock (fxis_shm.shm.ring) needs the writer's ``seq`` and write-counter stores
release-ordered, a release fence between the odd ``seq`` and the data it announces,
and on the reader's side acquire loads and an acquire fence before the final check.
x86-64 gives all of that for free (stores and loads each stay in program order), so
plain accesses are correct there. Weakly ordered CPUs (ARM64: Jetson, Raspberry Pi)
need real fences: the small C helper ``fxis_shm.shm._ordered``, built by the package's
install. Without it, rings refuse to open on such a CPU rather than risk torn frames.

``MODE`` says which is in use: "fenced" (the helper), "x86-tso" (plain accesses,
correct on x86-64) or None (unsupported: the helper is missing on a weak CPU).
"""

from __future__ import annotations

import mmap
import os
import platform
from collections.abc import Callable
from typing import TypeAlias

from fxis_shm.errors import RingError

try:
    from fxis_shm.shm import _ordered
except ImportError:  # not built (a source checkout, or no C compiler at install time)
    _ordered = None  # type: ignore[assignment]  # (the stub types the built helper; it may be missing)

# The memory of a ring's segment: its mapping, or a view of it (the tests' bytearrays too).
Memory: TypeAlias = mmap.mmap | memoryview | bytearray

_TSO_MACHINES = ("x86_64", "amd64", "i386", "i686")


def choose_mode(helper_built: bool, machine: str, want_plain: bool = False) -> str | None:
    """The accesses to use: the helper's fences where built, plain ones only on x86
    (``want_plain``: measure the plain ones where they are correct), else None."""
    plain_is_correct = machine.lower() in _TSO_MACHINES
    if helper_built and not (want_plain and plain_is_correct):
        return "fenced"
    return "x86-tso" if plain_is_correct else None


# FXIS_PLAIN_ORDERING=1: plain accesses where they are correct (bench/costs/ring_ordering.py compares).
MODE = choose_mode(_ordered is not None, platform.machine(), os.environ.get("FXIS_PLAIN_ORDERING") == "1")


def require_supported() -> None:
    """Raise RingError if the rings cannot be read or written correctly on this CPU."""
    if MODE is None:
        raise RingError(
            f"this CPU ({platform.machine()}) orders memory weakly and the ring's fence helper "
            "fxis_shm.shm._ordered is not built: reinstall fxis-shm with a C compiler present "
            "(pip install -e . builds it)"
        )


def _plain_load(buffer: Memory, offset: int) -> int:
    return int.from_bytes(buffer[offset : offset + 8], "little")


def _plain_store(buffer: Memory, offset: int, value: int) -> None:
    buffer[offset : offset + 8] = value.to_bytes(8, "little")


def _no_acquire_fence() -> None:
    """Nothing to do on x86-64: loads are not reordered with other loads."""


def _no_release_fence() -> None:
    """Nothing to do on x86-64: stores are not reordered with other stores."""


load_acquire: Callable[[Memory, int], int] = _plain_load
store_release: Callable[[Memory, int, int], None] = _plain_store
fence_acquire: Callable[[], None] = _no_acquire_fence
fence_release: Callable[[], None] = _no_release_fence
if MODE == "fenced" and _ordered is not None:
    load_acquire, store_release = _ordered.load_acquire, _ordered.store_release
    fence_acquire, fence_release = _ordered.fence_acquire, _ordered.fence_release
