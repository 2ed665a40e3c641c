"""Reusable, pre-faulted buffers for frames copied out of the rings.

The coordinator copies a reply's frames out of the rings (the copy is what lets
the seqlock prove them whole) and hands them to ZeroMQ without another copy; a
local client copies them into the arrays it returns. A fresh buffer per frame
would page-fault on every page of that copy (it costs 3 to 4 times the copy
itself); a pooled one is already mapped.

Ownership is explicit. Each array handed out is made over a lease object of its
own (its ``base``), and every view of the array keeps that lease alive, as does
ZeroMQ while it sends the array without copying. The buffer comes
back to the pool when the lease is gone (a weak reference to it says so: the last array or view
of it was dropped) or when the holder gives it back (``release``, behind
``Frame.release()`` and ``with frame:``), whichever is first. After ``release``
the holder must not use the array: the pool may fill it with another frame.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass(eq=False)
class _Buffer:
    memory: NDArray[Any]  # the pooled bytes
    address: int  # of its first byte
    lease: weakref.ref[_Lease] | None = field(default=None)  # to the lease of the array handed out last

    @property
    def free(self) -> bool:
        lease = self.lease() if self.lease is not None else None
        return lease is None or lease.ended


class _Lease:
    """The owner of one array handed out: NumPy makes the array over it and keeps it as
    the array's base, so it lives exactly as long as the array or any view of it. A weak
    reference to it (no callback: the pool looks when it needs a buffer) says whether it does."""

    __slots__ = ("__weakref__", "__array_interface__", "ended", "memory")

    def __init__(self, memory: NDArray[Any], interface: dict[str, object]):
        self.memory = memory  # the pool's bytes live as long as the array, even if the pool does not
        self.__array_interface__ = interface
        self.ended = False  # set by release(): the holder gave the buffer back early


class BufferPool:
    """At most ``max_bytes`` of buffers are kept; beyond, buffers are one-off allocations."""

    def __init__(self, max_bytes: int = 256 << 20):
        self.max_bytes = max_bytes
        self._buffers: dict[int, list[_Buffer]] = {}
        self._sizes: dict[
            tuple[tuple[int, ...], str], tuple[int, str]
        ] = {}  # (shape, dtype) -> (bytes, NumPy's typestr)
        self.kept_bytes = 0

    def take(self, shape: tuple[int, ...], dtype: str) -> NDArray[Any]:
        """An array of ``shape`` and ``dtype`` whose contents are undefined, leased to the caller."""
        size = self._sizes.get((shape, dtype))
        if size is None:
            kind = np.dtype(dtype)
            size = self._sizes[(tuple(shape), dtype)] = (math.prod(shape) * kind.itemsize, kind.str)
        nbytes, typestr = size
        same_size = self._buffers.get(nbytes)
        if same_size is None:
            same_size = self._buffers[nbytes] = []
        for buffer in same_size:
            if buffer.free:
                break
        else:
            memory = np.empty(nbytes, np.uint8)
            if self.kept_bytes + nbytes > self.max_bytes:
                return memory.view(dtype).reshape(shape)  # one-off: nothing to give back
            memory.fill(0)  # fault every page in now, not during a copy someone waits for
            buffer = _Buffer(memory, memory.__array_interface__["data"][0])
            same_size.append(buffer)
            self.kept_bytes += nbytes
        lease = _Lease(
            buffer.memory, {"data": (buffer.address, False), "shape": tuple(shape), "typestr": typestr, "version": 3}
        )
        buffer.lease = weakref.ref(lease)  # dead when no array or view of it is left; or ended by release()
        return np.asarray(lease)

    @property
    def leased(self) -> int:
        """How many kept buffers are handed out now."""
        return sum(not b.free for same in self._buffers.values() for b in same)


def release(array: NDArray[Any]) -> bool:
    """Give the buffer under ``array`` back to its pool now, whatever still refers to it
    (True); False if ``array`` is not a leased pool buffer (nothing to give back)."""
    lease = getattr(array, "base", None)
    if isinstance(lease, _Lease) and not lease.ended:
        lease.ended = True
        return True
    return False
