"""Reusable, pre-faulted buffers for frames copied out of the rings.

The coordinator copies a reply's frames out of the rings (the copy is what lets
the seqlock prove them whole) and hands them to ZeroMQ without another copy; a
local client copies them into the arrays it returns. A fresh buffer per frame
would page-fault on every page of that copy (it costs 3 to 4 times the copy
itself); a pooled one is already mapped.

Ownership is explicit. Each array handed out is made over a lease object of its
own (its ``base``), and every view of the array keeps that lease alive, as does
ZeroMQ while it sends the array without copying. The buffer comes
back to the pool when the lease is gone (a finalizer on it: the last array or view
of it was dropped) or when the holder gives it back (``release``, behind
``Frame.release()`` and ``with frame:``), whichever is first. After ``release``
the holder must not use the array: the pool may fill it with another frame.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np


@dataclass(eq=False)
class _Buffer:
    memory: np.ndarray  # the pooled bytes
    lease: weakref.finalize | None = field(default=None)  # set while handed out

    @property
    def free(self) -> bool:
        return self.lease is None or not self.lease.alive


class _Lease:
    """The owner of one array handed out: NumPy makes the array over it and keeps it as
    the array's base, so it lives exactly as long as the array or any view of it."""

    __slots__ = ("__weakref__", "memory", "__array_interface__", "end")

    def __init__(self, memory: np.ndarray, shape: tuple[int, ...], dtype: str):
        self.memory = memory
        self.end = weakref.finalize(self, _no_op)  # alive while the lease lasts; end() ends it
        self.__array_interface__ = {
            "data": (memory.ctypes.data, False),
            "shape": tuple(shape),
            "typestr": np.dtype(dtype).str,
            "version": 3,
        }


class BufferPool:
    """At most ``max_bytes`` of buffers are kept; beyond, buffers are one-off allocations."""

    def __init__(self, max_bytes: int = 256 << 20):
        self.max_bytes = max_bytes
        self._buffers: dict[int, list[_Buffer]] = {}
        self.kept_bytes = 0

    def take(self, shape: tuple[int, ...], dtype: str) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` whose contents are undefined, leased to the caller."""
        nbytes = math.prod(shape) * np.dtype(dtype).itemsize
        same_size = self._buffers.setdefault(nbytes, [])
        buffer = next((b for b in same_size if b.free), None)
        if buffer is None:
            buffer = _Buffer(np.empty(nbytes, np.uint8))
            if self.kept_bytes + nbytes > self.max_bytes:
                return buffer.memory.view(dtype).reshape(shape)  # one-off: nothing to give back
            buffer.memory.fill(0)  # fault every page in now, not during a copy someone waits for
            same_size.append(buffer)
            self.kept_bytes += nbytes
        lease = _Lease(buffer.memory, shape, dtype)
        buffer.lease = lease.end  # ends when the lease goes (no array or view of it is left) or on release()
        return np.asarray(lease)

    @property
    def leased(self) -> int:
        """How many kept buffers are handed out now."""
        return sum(not b.free for same in self._buffers.values() for b in same)


def release(array: np.ndarray) -> bool:
    """Give the buffer under ``array`` back to its pool now, whatever still refers to it
    (True); False if ``array`` is not a leased pool buffer (nothing to give back)."""
    lease = getattr(array, "base", None)
    if isinstance(lease, _Lease) and lease.end.alive:
        lease.end()
        return True
    return False


def _no_op() -> None:
    """A lease's finalizer does nothing itself: that it is no longer alive frees the buffer."""
