"""The client's side of the local fast path: frames copied straight out of the rings.

A client on the service's kernel sends its boot id with a request; the service
then replies with where each chosen frame is (ring segment, the segment's
instance token, slot, and the seq the slot shows while it holds that frame)
instead of the pixels. ``LocalRings`` opens those segments read-only and copies
the frames out under the ring's seqlock: a slot overwritten before or during
the copy raises ``Overwritten`` and the copy is never returned.

The writer never waits for readers, so nothing pins a slot: a frame stays
readable for as long as the ring takes to come round to its slot again
(slots - 1 frame periods after it was chosen). A zero-copy view (``copy=False``)
is the slot itself: valid while ``LocalFrames.still_valid`` says so, which the
caller checks after using the pixels (the same seqlock, one step later).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from numpy.typing import NDArray

from fxis_shm.errors import RingError
from fxis_shm.shm.bufferpool import BufferPool
from fxis_shm.shm.ring import RingReader
from fxis_shm.wire.headers import FrameMeta

_BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"


def boot_id() -> str | None:
    """This kernel's boot id: equal for two processes exactly when they share a kernel
    (and so CLOCK_MONOTONIC); None where the kernel does not say."""
    try:
        with open(_BOOT_ID_PATH) as f:
            return f.read().strip() or None
    except OSError:
        return None


def time_namespace() -> str | None:
    """This process's time namespace (``time:[inode]``): two processes on one kernel read
    the same CLOCK_MONOTONIC exactly when this is equal; None where the kernel does not say."""
    try:
        return os.readlink("/proc/self/ns/time")
    except OSError:
        return None


class LocalUnavailable(Exception):
    """The rings a reply names cannot be read here (another IPC namespace, another user,
    or a segment that is not the one the service meant)."""


@dataclass(frozen=True)
class SlotRef:
    """Where a local reply says a frame is, and how to tell it is still there."""

    ring: str
    instance: int
    slot: int
    seq: int

    @classmethod
    def of(cls, meta: FrameMeta) -> SlotRef:
        try:
            return cls(str(meta["ring"]), int(meta["instance"]), int(meta["slot"]), int(meta["seq"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise LocalUnavailable(f"a local reply's frame lacks its ring reference: {exc!r}") from None


class LocalRings:
    """The rings this client has opened, by segment name."""

    def __init__(self, max_pooled_bytes: int = 128 << 20):
        self._readers: dict[str, RingReader] = {}
        self._buffers = BufferPool(max_pooled_bytes)  # arrays handed out come back when dropped

    def reader(self, ref: SlotRef) -> RingReader:
        reader = self._readers.get(ref.ring)
        if reader is not None and (reader.retired or reader.instance != ref.instance):
            self._drop(ref.ring)  # the worker replaced its ring: open the new one
            reader = None
        if reader is None:
            try:
                reader = RingReader.named(ref.ring)
            except RingError as exc:
                raise LocalUnavailable(str(exc)) from None
            except (OSError, ValueError) as exc:
                raise LocalUnavailable(f"cannot map {ref.ring}: {exc}") from None
            if reader.instance != ref.instance:
                reader.close()
                raise LocalUnavailable(
                    f"{ref.ring} here is not the service's ring (another IPC namespace, or the ring was replaced)"
                )
            self._readers[ref.ring] = reader
        return reader

    def images(self, metas: Sequence[FrameMeta], copy: bool = True) -> list[NDArray[Any]]:
        """The pixels of every frame of a local reply, in order: copies checked whole,
        or (``copy=False``) read-only views of the slots. Raises Overwritten or LocalUnavailable."""
        images: list[NDArray[Any]] = []
        for meta in metas:
            ref = SlotRef.of(meta)
            reader = self.reader(ref)
            if list(reader.layout.shape) != meta.get("shape") or reader.layout.dtype != meta.get("dtype"):
                raise LocalUnavailable(
                    f"{ref.ring} holds {reader.layout}, the reply says {meta.get('shape')} {meta.get('dtype')}"
                )
            if copy:
                out = self._buffers.take(reader.layout.shape, reader.layout.dtype)
                images.append(reader.copy_slot(ref.slot, ref.seq, out))
            else:
                images.append(reader.view_slot(ref.slot, ref.seq))
        return images

    def still_valid(self, meta: FrameMeta) -> bool:
        """True while the slot still holds the frame ``meta`` names (for zero-copy views)."""
        ref = SlotRef.of(meta)
        reader = self._readers.get(ref.ring)
        return reader is not None and reader.instance == ref.instance and reader.slot_holds(ref.slot, ref.seq)

    def _drop(self, name: str) -> None:
        reader = self._readers.pop(name, None)
        if reader is not None:
            reader.close()

    def close(self) -> None:
        for name in list(self._readers):
            self._drop(name)
