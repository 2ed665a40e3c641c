"""The ring reader's three seqlock reads, in C where built (``fxis_shm.shm._slotio``) and in
Python otherwise; ``IMPL`` says which ("c" or "python"). Both do the same steps in the same
order (tests/unit/test_slotio.py checks that they answer alike); FXIS_PURE_PYTHON=1 takes
the Python ones (fxis_shm._compiled).

- ``records(buffer, table, slots, lo, hi)``: the slot records of writes lo..hi-1 that were
  whole while read, as (w, frame_id, t_capture, t_stored, t_available, generation, t_target,
  capture), oldest first;
- ``copy(buffer, seq_at, seq, src, nbytes, out)``: the slot's bytes into ``out`` if the slot
  showed ``seq`` before and after: 0, else 1 (overwritten before) or 2 (during);
- ``copies(items)``: ``copy`` of each (buffer, seq_at, seq, src, nbytes, out) in order, up to
  the first that was not whole: None if all were, else (its index, 1 or 2); the C one lets the
  GIL go once and streams frames of 512 KiB and more past the caches (same bytes, same checks);
- ``holds(buffer, seq_at, seq)``: after an acquire fence, does the slot still show ``seq``?
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

from fxis_shm.shm import ordering
from fxis_shm.shm.ordering import Memory

# One copy: (segment, seq_at, seq, src, nbytes, out), as ``copy`` takes it.
CopyJob: TypeAlias = tuple[Memory, int, int, int, int, NDArray[Any]]
Copies: TypeAlias = Callable[[list[CopyJob]], "tuple[int, int] | None"]
_RECORD = struct.Struct("<QQqqqQqQ")  # the ring's slot record (fxis_shm.core.snapshot.SLOT)


def py_records(buffer: Memory, table: int, slots: int, lo: int, hi: int) -> list[tuple[int, ...]]:
    out: list[tuple[int, ...]] = []
    for w in range(lo, hi):
        at = table + (w % slots) * _RECORD.size
        expected = 2 * w + 2
        if ordering.load_acquire(buffer, at) != expected:
            continue
        rec = _RECORD.unpack_from(buffer, at)
        ordering.fence_acquire()  # the fields were read before seq is read again
        if ordering.load_acquire(buffer, at) == expected:
            out.append((w, *rec[1:]))
    return out


def py_copy(buffer: Memory, seq_at: int, seq: int, src: int, nbytes: int, out: NDArray[Any] | Memory) -> int:
    if ordering.load_acquire(buffer, seq_at) != seq:
        return 1
    target = np.frombuffer(out, dtype=np.uint8) if not isinstance(out, np.ndarray) else out.reshape(-1).view(np.uint8)
    if target.nbytes != nbytes:
        raise ValueError(f"copy: the target holds {target.nbytes} bytes, the frame {nbytes}")
    np.copyto(target, np.frombuffer(buffer, dtype=np.uint8, count=nbytes, offset=src))
    ordering.fence_acquire()  # every byte was read before seq is read again
    return 0 if ordering.load_acquire(buffer, seq_at) == seq else 2


def py_copies(items: list[CopyJob]) -> tuple[int, int] | None:
    for k, item in enumerate(items):
        torn = py_copy(*item)
        if torn:
            return k, torn
    return None


def py_holds(buffer: Memory, seq_at: int, seq: int) -> bool:
    ordering.fence_acquire()
    return ordering.load_acquire(buffer, seq_at) == seq


try:
    if os.environ.get("FXIS_PURE_PYTHON") == "1":
        raise ImportError("FXIS_PURE_PYTHON=1")
    from fxis_shm.shm import _slotio
except ImportError:
    _slotio = None  # type: ignore[assignment]  # (the stub types the built helper; it may be missing)

COPIES_AT_ONCE = 64  # what one call of the C ``copies`` takes (MAX_JOBS in _slotio.c)


def in_batches(copies_at_once: Copies) -> Copies:
    """``copies`` over any number of items, in calls of at most COPIES_AT_ONCE (a sequence
    request can copy hundreds of frames)."""

    def copies(items: list[CopyJob]) -> tuple[int, int] | None:
        for start in range(0, len(items), COPIES_AT_ONCE):
            torn = copies_at_once(items[start : start + COPIES_AT_ONCE])
            if torn is not None:
                return start + torn[0], torn[1]
        return None

    return copies


records: Callable[[Memory, int, int, int, int], list[tuple[int, ...]]] = py_records
copy: Callable[[Memory, int, int, int, int, NDArray[Any]], int] = py_copy
copies: Copies = py_copies
holds: Callable[[Memory, int, int], bool] = py_holds
IMPL = "python"  # not built (no C compiler at install time), or FXIS_PURE_PYTHON=1
if _slotio is not None:
    IMPL = "c"
    records, copy, holds = _slotio.records, _slotio.copy, _slotio.holds
    copies = in_batches(_slotio.copies)
