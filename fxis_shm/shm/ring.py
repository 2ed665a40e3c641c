"""The per-camera shared-memory ring: one writer (the camera worker), any readers.

Layout of the segment ``/fxis.<service>.<camera>.ring``:

    [header, 1 KiB][slot table: slots x 64 bytes][pad to 4 KiB][slot 0 data][slot 1 data]...

Each slot record holds ``seq``, ``frame_id``, ``t_capture``, ``t_stored``,
``t_available``, ``generation``, ``t_target`` and ``capture`` (how the frame was captured:
free, or triggered for the moment ``t_target``, fxis_shm.core.snapshot.CAPTURES).
``seq`` encodes the global write index w of the frame in the slot: ``2w+1`` while the writer fills it, ``2w+2`` once it
is complete. A reader therefore knows from ``seq`` alone which frame a slot
holds, and a copy is valid only if ``seq`` had the expected value both before
and after it (a seqlock); a torn copy is detected and never returned.

The writer never waits for a reader. After every stored frame it posts the
semaphore ``/fxis.<service>.<camera>.new`` (only when its value is 0, so an
absent reader cannot make it grow). Segments and semaphores are mode 0600.

Ordering: ``seq`` and ``write_count`` are stored with release order and loaded with
acquire order, with a release fence after the odd ``seq`` and an acquire fence before
a reader's final checks (fxis_shm.shm.ordering: C11 fences on ARM64, plain accesses on
x86-64, whose stores and loads keep program order).
"""

from __future__ import annotations

import mmap
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import posix_ipc
from numpy.typing import NDArray

from fxis_shm.core import timebase
from fxis_shm.core.snapshot import CAPTURE_FREE, SLOT, SlotMeta, Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.errors import Overwritten, RingError
from fxis_shm.shm import history, naming, ordering, slotio
from fxis_shm.shm.ringheader import (
    HEADER,
    HEADER_BYTES,
    LAYOUT_VERSION,
    LIVENESS,
    MAGIC,
    NUMBERS,
    STATE_INIT,
    STATE_LIVE,
    STATE_RETIRED,
    TIMING,
    WRITE_COUNT_AT,
    align_to_page,
    seq_at,
)

_PERIOD_SMOOTHING = 16  # EWMA weight 1/16: follows rate changes within a second at 20 fps


@dataclass(frozen=True)
class FrameLayout:
    """Shape and type of the frames a ring holds."""

    height: int
    width: int
    channels: int = 1
    dtype: str = "uint8"

    @classmethod
    def of(cls, image: NDArray[Any]) -> FrameLayout:
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
            raise ValueError(f"an image must be (h, w) or (h, w, 1|3|4), got {image.shape}")
        channels = 1 if image.ndim == 2 else image.shape[2]
        return cls(image.shape[0], image.shape[1], channels, image.dtype.name)

    @property
    def shape(self) -> tuple[int, ...]:
        if self.channels == 1:
            return (self.height, self.width)
        return (self.height, self.width, self.channels)

    @property
    def nbytes(self) -> int:
        return self.height * self.width * self.channels * np.dtype(self.dtype).itemsize


class _Mapping:
    """The numpy views shared by writer and reader over one mapped segment."""

    def _map(self, fd: int, size: int, writable: bool) -> None:
        ordering.require_supported()
        prot = mmap.PROT_READ | (mmap.PROT_WRITE if writable else 0)
        self._mm = mmap.mmap(fd, size, flags=mmap.MAP_SHARED | mmap.MAP_POPULATE, prot=prot)
        self.header: NDArray[Any] = np.ndarray((), dtype=HEADER, buffer=self._mm)
        if self.header["magic"] != MAGIC or self.header["version"] != LAYOUT_VERSION:
            if writable and self.header["magic"] == b"":
                return  # being created
            raise RingError(f"segment is not an fxis ring of layout version {LAYOUT_VERSION}")
        self._views()

    def _views(self) -> None:
        h = self.header
        self.layout = FrameLayout(int(h["height"]), int(h["width"]), int(h["channels"]), h["dtype"].item().decode())
        self.slots = int(h["slots"])
        self.table: NDArray[Any] = np.ndarray((self.slots,), dtype=SLOT, buffer=self._mm, offset=HEADER_BYTES)
        self.seq: NDArray[Any] = np.ndarray(
            (self.slots,), dtype="<u8", buffer=self._mm, offset=HEADER_BYTES, strides=(SLOT.itemsize,)
        )
        stride = int(h["slot_stride"])
        self.data: NDArray[Any] = np.ndarray(
            (self.slots, self.layout.nbytes),
            dtype=np.uint8,
            buffer=self._mm,
            offset=int(h["data_offset"]),
            strides=(stride, 1),
        )

    def slot_image(self, slot: int) -> NDArray[Any]:
        image: NDArray[Any] = self.data[slot].view(self.layout.dtype).reshape(self.layout.shape)
        return image

    def field(self, name: str) -> int:
        if name == "write_count":  # the word that publishes frames: read it ordered
            return ordering.load_acquire(self._mm, WRITE_COUNT_AT)
        unpack, offset = NUMBERS[name]
        value: int = unpack(self._mm, offset)[0]
        return value

    def liveness(self) -> tuple[int, int, int, int]:
        """(state, writer_pid, write_count, heartbeat_ns) in one read: the signs of life (the
        write count read plainly, as a sign of life, not to read the frames it publishes)."""
        state, writer_pid, write_count, heartbeat_ns = LIVENESS(self._mm)
        return state, writer_pid, write_count, heartbeat_ns

    def timing(self) -> tuple[int, int]:
        """(period_ns, delay_ns) in one read."""
        period_ns, delay_ns = TIMING(self._mm)
        return period_ns, delay_ns

    def _unmap(self) -> None:
        for attr in ("header", "table", "seq", "data", "_views_ro"):
            self.__dict__.pop(attr, None)
        mapping = self.__dict__.pop("_mm", None)
        if mapping is not None:
            try:
                mapping.close()
            except BufferError:  # a zero-copy view handed out still maps it; unmapped when it goes
                pass


def segment_size(layout: FrameLayout, slots: int) -> tuple[int, int, int]:
    """(total size, data offset, slot stride) of a ring."""
    data_offset = align_to_page(HEADER_BYTES + slots * SLOT.itemsize)
    stride = align_to_page(layout.nbytes)
    return data_offset + slots * stride, data_offset, stride


class RingWriter(_Mapping):
    """The camera worker's side: creates (or re-attaches to) the ring and stores frames. Its
    times (t_stored, the heartbeat) are ``clock``'s: the real one but in virtual-time tests."""

    def __init__(
        self,
        service: str,
        camera: str,
        layout: FrameLayout,
        slots: int,
        nominal_period_ns: int = 0,
        clock: timebase.Clock = timebase.REAL,
    ):
        if slots < 2:
            raise ValueError(f"a ring needs at least 2 slots, got {slots}")
        self.clock = clock
        self.name = naming.ring_name(service, camera)
        self.layout = layout
        self._open_or_create(layout, slots)
        h = self.header
        h["generation"] = int(h["generation"]) + 1
        h["writer_pid"] = os.getpid()
        h["generation_started_ns"] = h["heartbeat_ns"] = clock.now_ns()
        h["nominal_period_ns"] = nominal_period_ns
        if int(h["period_ns"]) <= 0:
            h["period_ns"] = nominal_period_ns
        self.generation = int(h["generation"])
        self._count = int(h["write_count"])
        # (frame_id, t_capture) of the previous stored frame; their count
        self._last: tuple[int, int] | None = None
        self._samples = 0
        self.semaphore = posix_ipc.Semaphore(
            naming.semaphore_name(service, camera), posix_ipc.O_CREAT, mode=0o600, initial_value=0
        )
        h["state"] = STATE_LIVE

    def _open_or_create(self, layout: FrameLayout, slots: int) -> None:
        size, data_offset, stride = segment_size(layout, slots)
        try:
            shm = posix_ipc.SharedMemory(self.name)
        except posix_ipc.ExistentialError:
            shm = None
        if shm is not None:
            try:
                self._map(shm.fd, shm.size, writable=True)
                compatible = getattr(self, "layout", None) == layout and self.slots == slots and shm.size == size
            except (RingError, ValueError, TypeError):  # not a ring, or truncated
                compatible = False
            finally:
                shm.close_fd()
            if compatible:
                return
            # Another layout: retire the old segment so readers re-open by name.
            if getattr(self, "header", None) is not None and self.header["magic"] == MAGIC:
                self.header["state"] = STATE_RETIRED
            posix_ipc.unlink_shared_memory(self.name)
        old = getattr(self, "header", None)
        generation = int(old["generation"]) if old is not None and old["magic"] == MAGIC else 0
        del old
        self._unmap()
        history.check_room(size, f"the ring {self.name} ({slots} slots of {layout.shape} {layout.dtype})")
        shm = posix_ipc.SharedMemory(self.name, posix_ipc.O_CREX, mode=0o600, size=size)
        try:
            self._map(shm.fd, size, writable=True)
        finally:
            shm.close_fd()
        np.frombuffer(self._mm, dtype=np.uint8)[:] = 0  # touch every page now, not on first frames
        h = self.header
        h["version"], h["state"] = LAYOUT_VERSION, STATE_INIT
        h["height"], h["width"], h["channels"] = layout.height, layout.width, layout.channels
        h["dtype"], h["slots"] = layout.dtype.encode(), slots
        h["generation"] = generation  # continues across a layout change: never repeats
        h["slot_stride"], h["data_offset"] = stride, data_offset
        h["instance"] = int.from_bytes(os.urandom(8), "little")
        h["magic"] = MAGIC
        self._views()

    def write(
        self,
        image: NDArray[Any],
        frame_id: int,
        t_capture: int,
        t_available: int | None = None,
        t_target: int = 0,
        capture: int = CAPTURE_FREE,
    ) -> int:
        """Store one frame (``capture``: how, for the moment ``t_target`` if triggered for one);
        returns its t_stored. Never blocks on readers."""
        w = self._count
        slot = w % self.slots
        ordering.store_release(self._mm, seq_at(slot), 2 * w + 1)
        ordering.fence_release()  # the slot reads as being written before any of its new bytes show
        np.copyto(self.slot_image(slot), image, casting="no")
        rec = self.table[slot]
        t_stored = self.clock.now_ns()
        rec["frame_id"], rec["t_capture"], rec["t_stored"] = frame_id, t_capture, t_stored
        rec["t_available"] = t_capture if t_available is None else t_available
        rec["generation"] = self.generation
        rec["t_target"], rec["capture"] = t_target, capture
        ordering.store_release(self._mm, seq_at(slot), 2 * w + 2)  # after every byte of the frame
        self._count = w + 1
        ordering.store_release(self._mm, WRITE_COUNT_AT, self._count)
        self.header["heartbeat_ns"] = t_stored
        self._update_timing(frame_id, t_capture, t_stored)
        if self.semaphore.value == 0:
            self.semaphore.release()
        return t_stored

    def _update_timing(self, frame_id: int, t_capture: int, t_stored: int) -> None:
        """Running estimates of the frame period and the capture-to-storage delay:
        a plain mean over this generation's first samples (so one slow start-up
        frame does not linger), then an exponential average. The delay rises at once
        to a later frame's: a worker that fell behind stores the frames its driver held
        late, and a request waiting for one must not give it up as dropped meanwhile
        (core/waitpolicy.py: a frame is overdue a period plus this delay after capture)."""
        h = self.header
        self._samples += 1
        weight = min(self._samples, _PERIOD_SMOOTHING)
        if self._last is not None and frame_id > self._last[0] and t_capture > self._last[1]:
            interval = (t_capture - self._last[1]) // (frame_id - self._last[0])
            old = int(h["period_ns"])
            h["period_ns"] = interval if old <= 0 else old + (interval - old) // weight
        self._last = (frame_id, t_capture)
        old_delay, delay = int(h["delay_ns"]), t_stored - t_capture
        h["delay_ns"] = delay if delay > old_delay else old_delay + (delay - old_delay) // weight

    def new_generation(self) -> int:
        """The camera came back after an outage: later frames carry a new generation."""
        self.generation = int(self.header["generation"]) + 1
        self.header["generation"], self.header["generation_started_ns"] = self.generation, self.clock.now_ns()
        self._last, self._samples = None, 0
        return self.generation

    def set_period(self, nominal_period_ns: int) -> None:
        """A new frame rate: readers take its period at once (no stale average); the estimate restarts."""
        self.header["nominal_period_ns"] = self.header["period_ns"] = nominal_period_ns
        self._last, self._samples = None, 0

    def heartbeat(self) -> None:
        self.header["heartbeat_ns"] = self.clock.now_ns()

    def count(self, field: str, n: int = 1) -> None:
        """Add to one of the counters frames_captured, frames_dropped, hook_errors."""
        self.header[field] = int(self.header[field]) + n

    def set_flags(self, flags: int) -> None:
        self.header["flags"] = flags

    def set_sync(self, figures: dict[str, int]) -> None:
        """The trigger figures (SYNC_FIELDS, by name) for ``status``."""
        for name, value in figures.items():
            self.header[name] = value

    def set_status(self, text: str) -> None:
        self.header["status_text"] = text.encode()[:255]

    def close(self) -> None:
        """Detach; the segment stays for the next generation (the supervisor unlinks it)."""
        if getattr(self, "header", None) is not None:
            self.header["writer_pid"] = 0
        self._unmap()
        self.semaphore.close()


class RingReader(_Mapping):
    """A read-only view of a camera's ring (the coordinator, or a local client)."""

    def __init__(self, service: str, camera: str, with_semaphore: bool = True):
        self._open(naming.ring_name(service, camera))
        self.semaphore = None
        if with_semaphore:
            try:
                self.semaphore = posix_ipc.Semaphore(naming.semaphore_name(service, camera))
            except posix_ipc.ExistentialError:
                self.close()
                raise RingError(f"semaphore of ring {self.name} does not exist") from None

    @classmethod
    def named(cls, name: str) -> RingReader:
        """The ring of segment ``name`` (as a reply of the local fast path names it), without its semaphore."""
        reader = cls.__new__(cls)
        reader.semaphore = None
        reader._open(name)
        return reader

    def _open(self, name: str) -> None:
        self.name = name
        self._seen = self._first = 0  # the writes read so far; the oldest still valid then
        self._rows: list[SlotMeta | None] = []
        self._times: list[int] = []
        self._last: Snapshot | None = None
        self._views_ro: list[NDArray[Any]] | None = None
        try:
            shm = posix_ipc.SharedMemory(self.name, read_only=True)
        except posix_ipc.ExistentialError:
            raise RingError(f"ring {self.name} does not exist (is the camera worker running?)") from None
        except posix_ipc.PermissionsError:
            raise RingError(f"ring {self.name} belongs to another user") from None
        try:
            if shm.size < HEADER_BYTES:
                raise RingError(f"ring {self.name} is not initialised yet")
            self._map(shm.fd, shm.size, writable=False)
        finally:
            shm.close_fd()
        self._rows, self._times = [None] * self.slots, [0] * self.slots
        self._data_at, self._stride = self.field("data_offset"), self.field("slot_stride")

    @property
    def retired(self) -> bool:
        return self.field("state") == STATE_RETIRED

    def snapshot(self) -> Snapshot:
        """The frames that are complete now, oldest first. Only the slot records written since
        the last look are read (the others are known), and with nothing new since then the
        last snapshot is the answer."""
        n = self.slots
        for _ in range(4):
            count = self.field("write_count")
            start = max(self._seen, count - n)  # the writes not read yet
            if start == count:
                fresh = []
                break
            fresh = slotio.records(self._mm, HEADER_BYTES, n, start, count)
            if self.field("write_count") == count:
                break
        first = max(self._first, count - n)
        if len(fresh) != count - start:  # a record overwritten while read: the valid run starts after it
            read = {rec[0] for rec in fresh}
            first = max(first, max(w for w in range(start, count) if w not in read) + 1)
        # the writer may have begun to overwrite the oldest frame (write count's slot)
        while first < count and first == count - n and not slotio.holds(self._mm, seq_at(first % n), 2 * first + 2):
            first += 1
        if not fresh and first == self._first and self._last is not None:
            return self._last
        rows, times = self._rows, self._times
        if fresh:
            rows, times = list(rows), list(times)  # snapshots handed out keep theirs
            for w, *record in fresh:
                rows[w % n] = SlotMeta(*record)
                times[w % n] = record[1]
            self._rows, self._times = rows, times
        self._seen, self._first = count, first
        # Oldest first in a list: the searches read single elements, which a list serves far
        # faster than numpy, and a vector that does not wrap is searched by plain bisection.
        oldest = first % n
        self._last = Snapshot(Timeline(times[oldest:] + times[:oldest], 0, count - first), first, rows)
        return self._last

    @property
    def instance(self) -> int:
        return self.field("instance")

    def copy(self, snapshot: Snapshot, i: int, out: NDArray[Any] | None = None) -> NDArray[Any]:
        """Copy the frame of logical index ``i``; raises Overwritten if the slot changed."""
        return self.copy_slot(snapshot.slot(i), snapshot.seq(i), out)

    def copy_slot(self, slot: int, expected_seq: int, out: NDArray[Any] | None = None) -> NDArray[Any]:
        """Copy the frame in ``slot`` if it is the one ``expected_seq`` names and stays
        so to the end of the copy; raises Overwritten otherwise."""
        if out is None:
            out = np.empty(self.layout.shape, dtype=self.layout.dtype)
        torn = slotio.copy(*self.copy_job(slot, expected_seq, out))
        if torn:
            raise self.overwritten(slot, torn)
        return out

    def copy_job(self, slot: int, expected_seq: int, out: NDArray[Any]) -> slotio.CopyJob:
        """What ``slotio.copy`` and ``slotio.copies`` take to copy the frame in ``slot`` (the one
        ``expected_seq`` names) into ``out``."""
        if not 0 <= slot < self.slots:
            raise Overwritten(f"{self.name} has no slot {slot}")
        return self._mm, seq_at(slot), expected_seq, self._data_at + slot * self._stride, self.layout.nbytes, out

    def overwritten(self, slot: int, torn: int) -> Overwritten:
        """The error of a copy ``slotio`` found torn (1: overwritten before it, 2: during it)."""
        return Overwritten(f"slot {slot} of {self.name} was overwritten {'before' if torn == 1 else 'during'} the copy")

    @property
    def seen_count(self) -> int:
        """The write count the last snapshot read (before reading the records it shows)."""
        return self._seen

    def view_slot(self, slot: int, expected_seq: int) -> NDArray[Any]:
        """A read-only view of the frame in ``slot`` (no copy): valid only while
        ``slot_holds(slot, expected_seq)`` stays true; the writer may overwrite it any time."""
        self.check_slot(slot, expected_seq, "before")
        view: NDArray[Any] = self.slot_views()[slot].view()
        return view

    def slot_views(self) -> list[NDArray[Any]]:
        """A read-only array over each slot's frame, made once: a view of one of them is cheaper
        than a new one (hand out views, never these)."""
        if self._views_ro is None:
            self._views_ro = [self.slot_image(s) for s in range(self.slots)]
            for view in self._views_ro:
                view.flags.writeable = False
        return self._views_ro

    def geometry(self) -> tuple[mmap.mmap, int, int, int, int, int]:
        """(mapping, slots, slot table offset, data offset, slot stride, frame bytes): where a C
        reader finds the slots (fxis_shm.shm._fastpick.Rings)."""
        return self._mm, self.slots, HEADER_BYTES, self._data_at, self._stride, self.layout.nbytes

    def slot_holds(self, slot: int, expected_seq: int) -> bool:
        """True while the slot still holds that frame; what was read of it before is valid."""
        return slotio.holds(self._mm, seq_at(slot), expected_seq)

    def check_slot(self, slot: int, expected_seq: int, when: str) -> None:
        if not 0 <= slot < self.slots:
            raise Overwritten(f"{self.name} has no slot {slot}")
        if ordering.load_acquire(self._mm, seq_at(slot)) != expected_seq:
            raise Overwritten(f"slot {slot} of {self.name} was overwritten {when} the copy")

    def wait_for_frame(self, timeout: float) -> bool:
        """Block until the writer posts a new frame or ``timeout`` seconds pass."""
        if self.semaphore is None:
            raise RingError(f"ring {self.name} was opened without its semaphore: nothing to wait on")
        try:
            self.semaphore.acquire(timeout)
        except posix_ipc.BusyError:
            return False
        return True

    def close(self) -> None:
        self._unmap()
        if self.semaphore is not None:
            self.semaphore.close()
            self.semaphore = None
