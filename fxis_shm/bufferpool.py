"""Reusable, pre-faulted buffers for frames copied out of the rings.

The coordinator copies a reply's frames out of the rings (the copy is what lets
the seqlock prove them whole) and hands them to ZeroMQ without another copy; a
local client copies them into the arrays it returns. A fresh buffer per frame
would page-fault on every page of that copy (it costs 3 to 4 times the copy
itself); a pooled one is already mapped. A buffer is reused only once nothing
refers to it any more: ZeroMQ holds a reference to a zero-copy frame until it
has sent it, and an array handed out holds one through its base, so the
reference count says when a buffer is free again (CPython's count is exact;
each pool is used by one thread).
"""
from __future__ import annotations

import math
import sys

import numpy as np

_IDLE_REFS = 3  # the pool's list, the loop variable, getrefcount's argument


class BufferPool:
    """At most ``max_bytes`` of buffers are kept; beyond, buffers are one-off allocations."""

    def __init__(self, max_bytes: int = 256 << 20):
        self.max_bytes = max_bytes
        self._buffers: dict[int, list[np.ndarray]] = {}
        self.kept_bytes = 0

    def take(self, shape: tuple[int, ...], dtype: str) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` whose contents are undefined."""
        nbytes = math.prod(shape) * np.dtype(dtype).itemsize
        same_size = self._buffers.setdefault(nbytes, [])
        for buf in same_size:
            if sys.getrefcount(buf) <= _IDLE_REFS:
                return buf.view(dtype).reshape(shape)
        buf = np.empty(nbytes, np.uint8)
        if self.kept_bytes + nbytes <= self.max_bytes:
            buf.fill(0)  # fault every page in now, not during a copy someone waits for
            same_size.append(buf)
            self.kept_bytes += nbytes
        return buf.view(dtype).reshape(shape)
