"""Building Timelines for the tests: logical sequences stored in a circular vector."""

from __future__ import annotations

import numpy as np

from fxis_shm.core.snapshot import SLOT, Snapshot
from fxis_shm.core.timesearch import Timeline

MS = 1_000_000  # ns
POISON = -(10**15)  # fills unused slots: a search that reads one goes wrong visibly


def ring(logical_times, n: int | None = None, start: int = 0) -> Timeline:
    """A Timeline of ``n`` slots whose valid frames, oldest first, are ``logical_times``,
    the oldest stored at physical index ``start`` (wrapping around)."""
    n = len(logical_times) if n is None else n
    slots = [POISON] * n
    for i, t in enumerate(logical_times):
        slots[(start + i) % n] = t
    return Timeline(slots, start % n if n else 0, len(logical_times))


def periodic(period_ns: int, count: int, phase_ns: int = 0, first: int = 0) -> list[int]:
    """Capture times of frames ``first .. first+count-1`` of a free-running camera."""
    return [phase_ns + k * period_ns for k in range(first, first + count)]


def brute_nearest(times, t_star: int) -> int:
    """Index of the frame nearest to t_star; the newest (largest index) wins ties."""
    return min(range(len(times)), key=lambda i: (abs(times[i] - t_star), -i))


def snapshot_of(frames, delay_ns: int = 2 * MS, slots: int = 0) -> Snapshot:
    """A Snapshot of a ring holding ``frames``, oldest first: each ``(t_capture, t_target,
    capture)`` (stored ``delay_ns`` after capture) or ``(t_capture, t_target, capture, t_stored)``;
    ``slots``: a ring of that many slots (default: as many as frames, a full ring)."""
    meta = np.zeros(max(1, slots, len(frames)), dtype=SLOT)
    for w, (t, target, capture, *stored) in enumerate(frames):
        meta[w] = (2 * w + 2, w, t, stored[0] if stored else t + delay_ns, t, 1, target, capture)
    times = [f[0] for f in frames] + [POISON] * (len(meta) - len(frames))
    return Snapshot.of_table(Timeline(times, 0, len(frames)), 0, meta)


class CountedReads(list):
    """Slots (times, or a snapshot's rows) that count the reads of a loop over them and fail past
    ``limit``: a loop that stops moving fails at once instead of hanging."""

    def __init__(self, slots, limit: int):
        super().__init__(slots)
        self.reads, self.limit = 0, limit

    def __getitem__(self, i):
        self.reads += 1
        assert self.reads <= self.limit, f"read more than {self.limit} slots: the loop does not end"
        return super().__getitem__(i)
