"""Nearest-time search over a circular vector of timestamps (the paper's Algorithm 1).

A ring of ``n`` slots holds ``count`` valid frames; the oldest sits at physical
index ``start`` and the others follow it, wrapping around. Their timestamps are
nondecreasing in that logical order. Every search here is a binary search over
logical indices, mapped onto physical slots: O(log n) reads of the vector.

Pure: arrays and numbers in, indices out.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Timeline:
    """``count`` valid timestamps in a circular vector, oldest at ``start``."""

    times: list[int]
    start: int
    count: int
    # the valid frames do not wrap around the end of the vector: plain slices serve them
    contiguous: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = len(self.times)
        if not (0 <= self.count <= n) or (n and not 0 <= self.start < n):
            raise ValueError(f"bad timeline: start={self.start} count={self.count} n={n}")
        object.__setattr__(self, "contiguous", self.start + self.count <= n)

    def __len__(self) -> int:
        return self.count

    def physical(self, i: int) -> int:
        """Physical slot of logical index ``i`` (0 = oldest)."""
        return (self.start + i) % len(self.times)

    def at(self, i: int) -> int:
        if self.contiguous:
            return int(self.times[self.start + i])
        return int(self.times[self.physical(i)])

    def bisect_left(self, t: int) -> int:
        """First logical index whose time is >= t (``count`` if none)."""
        if self.contiguous:
            return bisect.bisect_left(self.times, t, self.start, self.start + self.count) - self.start
        lo, hi = 0, self.count
        while lo < hi:
            mid = (lo + hi) // 2
            if self.at(mid) < t:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def bisect_right(self, t: int) -> int:
        """First logical index whose time is > t (``count`` if none)."""
        if self.contiguous:
            return bisect.bisect_right(self.times, t, self.start, self.start + self.count) - self.start
        lo, hi = 0, self.count
        while lo < hi:
            mid = (lo + hi) // 2
            if self.at(mid) <= t:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def nearest(self, t_star: int) -> int:
        """Logical index of the frame nearest to ``t_star``.

        Among equally near frames (equal timestamps, or ``t_star`` exactly
        halfway) the newest wins. Raises ValueError on an empty timeline.
        """
        if self.count == 0:
            raise ValueError("no frames to search")
        after = self.bisect_right(t_star)  # first frame later than t*
        if after == self.count:
            return self.count - 1
        newest_equal_after = self.bisect_right(self.at(after)) - 1
        if after == 0:
            return newest_equal_after
        before = after - 1  # newest frame at or before t*
        if t_star - self.at(before) < self.at(after) - t_star:
            return before
        return newest_equal_after

    def within(self, lo: int, hi: int) -> range:
        """Logical indices of the frames whose times lie in [lo, hi]."""
        return range(self.bisect_left(lo), self.bisect_right(hi))
