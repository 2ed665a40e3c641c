"""A virtual clock (fxis_shm.core.timebase.Clock), as trio's MockClock: its time moves only when
the harness moves it, or when the one thread that uses it sleeps (autojump: a sleep returns at
once, at its deadline). One thread: the harness runs every actor itself, in time order."""

from __future__ import annotations

from fxis_shm.core import timebase

START_NS = 1_000 * 10**9  # the service clock (CLOCK_MONOTONIC) when a cell starts: 1000 s after boot
# the cell's common clocks, ahead of the service's: whole seconds, so that a lockstep grid of
# the realtime clock falls on whole periods of the service's too
REALTIME_AHEAD_NS = 1_700_000_000 * 10**9 - START_NS
TAI_AHEAD_NS = REALTIME_AHEAD_NS + 37 * 10**9


class VirtualClock:
    def __init__(self, start_ns: int = START_NS):
        self._now = start_ns
        self.ahead = {"monotonic": 0, "realtime": REALTIME_AHEAD_NS, "tai": TAI_AHEAD_NS}

    def now_ns(self) -> int:
        return self._now

    def read(self, name: str) -> int:
        return self._now + self.ahead[timebase.check(name)]

    def sleep_until(self, t_ns: int, stop: timebase.StopEvent | None = None) -> bool:
        if stop is not None and stop.is_set():
            return False
        self._now = max(self._now, t_ns)
        return True

    def advance_to(self, t_ns: int) -> None:
        if t_ns < self._now:
            raise ValueError(f"virtual time runs forward only: {t_ns} is before now ({self._now})")
        self._now = t_ns
