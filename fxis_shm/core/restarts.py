"""When the supervisor gives up on a crashing process: the crashes of a recent window count,
not those of the service's whole life, so a camera that crashes once a week is always restarted
while one that crash-loops is left down (issue 42, finding 6). Times in, a decision out."""

from __future__ import annotations

from collections.abc import Sequence


def recent_crashes(crash_times: Sequence[float], now: float, window_s: float) -> list[float]:
    """The crashes of the last ``window_s`` seconds before ``now`` (older ones no longer count)."""
    return [t for t in crash_times if now - t < window_s]


def gives_up(crash_times: Sequence[float], now: float, limit: int, window_s: float) -> bool:
    """Whether to leave a process down after it crashed at ``now`` (one of ``crash_times``):
    it gets ``limit`` restarts within any ``window_s`` seconds, and one more crash in the window
    leaves it down. ``limit`` 0: never restarted."""
    return len(recent_crashes(crash_times, now, window_s)) > limit
