"""Which frames a sequence request names (issue: sequences and pub/sub).

Kinds, for one camera (a list of frames) or several (a list of tuples, each
chosen jointly around a reference time):

- ``consecutive``: ``count`` frames ``before`` t* (the newest at or before it),
  ``after`` it (the oldest at or after it) or ``around`` it (centred on the
  frame nearest to t*). With several cameras, the first camera's frames are the
  reference times.
- ``interval``: the frames nearest to t* + i*interval for i = 0..count-1
  (interval may be negative).
- ``range``: every frame captured in [start, end] (the first camera's, with
  several cameras).

Pure: a timeline and numbers in; reference times, or what is missing, out.
"""

from __future__ import annotations

from dataclasses import dataclass

from fxis_shm.core.timesearch import Timeline

CONSECUTIVE, INTERVAL, RANGE = "consecutive", "interval", "range"
KINDS = (CONSECUTIVE, INTERVAL, RANGE)
DIRECTIONS = ("before", "after", "around")


@dataclass(frozen=True)
class SequenceSpec:
    kind: str
    t_star: int
    count: int = 1
    direction: str = "before"
    interval_ns: int = 0
    start: int = 0
    end: int = 0


class NotHeld(Exception):
    """The sequence reaches back further than the ring holds."""


class NotYet(Exception):
    """Frames the sequence needs are not captured yet."""


def latest_needed(spec: SequenceSpec, period_ns: int) -> int:
    """The latest capture time the sequence needs: wait until frames reach it."""
    if spec.kind == CONSECUTIVE:
        ahead = {"before": 0, "after": spec.count - 1, "around": spec.count // 2}[spec.direction]
        return spec.t_star + ahead * period_ns
    if spec.kind == INTERVAL:
        return spec.t_star + max(0, (spec.count - 1) * spec.interval_ns)
    return spec.end


def earliest_needed(spec: SequenceSpec, period_ns: int) -> int:
    """The earliest capture time the sequence needs: the ring must reach back to it."""
    if spec.kind == CONSECUTIVE:
        behind = {"before": spec.count - 1, "after": 0, "around": (spec.count - 1) // 2}[spec.direction]
        return spec.t_star - behind * period_ns
    if spec.kind == INTERVAL:
        return spec.t_star + min(0, (spec.count - 1) * spec.interval_ns)
    return spec.start


def reference_indices(spec: SequenceSpec, tl: Timeline) -> list[int]:
    """Logical indices, oldest first, of the reference camera's frames for CONSECUTIVE and RANGE."""
    if spec.kind == RANGE:
        return list(tl.within(spec.start, spec.end))
    if spec.kind != CONSECUTIVE:
        raise ValueError(f"{spec.kind} sequences have target times, not reference frames")
    if spec.direction == "before":
        last = tl.bisect_right(spec.t_star) - 1
        first = last - spec.count + 1
    elif spec.direction == "after":
        first = tl.bisect_left(spec.t_star)
        last = first + spec.count - 1
    else:
        centre = tl.nearest(spec.t_star)
        first = centre - (spec.count - 1) // 2
        last = first + spec.count - 1
    if first < 0:
        raise NotHeld(f"only {max(0, last + 1)} frame(s) at or before the first needed one are held")
    if last >= len(tl):
        raise NotYet(f"only {len(tl) - first} of {spec.count} frames exist yet")
    return list(range(first, last + 1))


def target_times(spec: SequenceSpec) -> list[int]:
    """t* + i*interval for INTERVAL sequences."""
    return [spec.t_star + i * spec.interval_ns for i in range(spec.count)]
