"""Which frames a stream at ``rate_hz`` sends: for each time of an ideal schedule
(one every 1/rate from the first frame sent), the frame nearest to it.

The schedule is kept, not the time of the last frame sent, so the long-run rate is
the one asked for: at 10 Hz from a 25 fps camera the frames sent alternate between
2 and 3 periods apart (10 per second), where "at least 1/rate since the last one"
would send every 2nd frame (12.5 per second). A rate at or above the camera's sends
every frame.

Frames are taken one at a time, as they arrive: frame t is sent when the next schedule
time lies before half a period after it (where the next frame would become nearer), and
answers that one schedule time. Tuples complete irregularly (their reference time moves
with whichever camera is behind), so a frame may come a little late for its schedule time:
the schedule times it passed are then kept for the frames after it, and only those more
than an interval behind are given up (after a stall, no burst). Pure: frame times in,
decisions out.
"""

from __future__ import annotations

import math


class Decimator:
    def __init__(self, rate_hz: float | None):
        if rate_hz is not None and not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ValueError(f"a stream rate must be a positive number of Hz, got {rate_hz!r}")
        self.rate_hz = rate_hz
        self._start: int | None = None  # schedule time 0: the first frame sent
        self._next = 0  # index of the first schedule time no frame has answered yet

    def _time(self, k: int) -> int:
        assert self._start is not None and self.rate_hz is not None
        return self._start + round(k * 1e9 / self.rate_hz)  # from the start: no rounding drift

    def offer(self, t: int, period_ns: int) -> bool:
        """Whether to send the frame captured at ``t`` (frames come in time order, each
        camera ``period_ns`` apart)."""
        if self.rate_hz is None:
            return True
        if self._start is None:
            self._start, self._next = t, 1
            return True
        covers_until = t + period_ns // 2  # schedule times before this are nearest to t
        if self._time(self._next) >= covers_until:
            return False
        interval = 1e9 / self.rate_hz
        # This frame answers the next schedule time, and the schedule goes on from the first
        # time after the frame: a frame that came late for its time (tuples complete
        # irregularly) leaves the next time to the next frame, and after a stall the times
        # missed are given up rather than sent in a burst.
        self._next = max(self._next + 1, math.floor((t - self._start) / interval) + 1)
        return True


def every_frame(rate_hz: float | None, period_ns: int) -> bool:
    """True when a stream at ``rate_hz`` gets every frame of a camera of this period."""
    return rate_hz is None or period_ns <= 0 or rate_hz * period_ns >= 1e9
