"""The slots of a LeRobot export (``fxis export BAG --lerobot OUT --fps HZ``): a grid
``t0 + k/fps`` over the span every camera recorded, and at each slot the joint tuple fxis's
service would answer (fxis_shm.core.selection.select_joint, then the least-skew tuple when
the nearest misses the bound, as fxis_shm.core.decisions does for ``max_skew_ms``).

A slot is kept only if its tuple's skew is within ``max_skew_ns`` and every frame of it lies
within half a slot period of the slot: a slot that no tuple fits is dropped and counted,
never filled with an older frame. Pure: capture times in, slots out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from fxis_shm.core.selection import radius_for, select_joint, tolerance_for
from fxis_shm.core.timesearch import Timeline

SYNC_TOLERANCE_MS = 1.0  # the service's default: tuples this much more skewed count as equal


@dataclass(frozen=True)
class Slot:
    k: int  # the slot's number on the grid
    t_ns: int  # t0 + k/fps, in the bag's clock
    index: Mapping[str, int]  # per camera, the chosen frame's position in its capture times
    t_capture: Mapping[str, int]

    @property
    def skew_ns(self) -> int:
        return max(self.t_capture.values()) - min(self.t_capture.values())


@dataclass(frozen=True)
class Grid:
    slots: list[Slot]  # the kept ones, in time order
    total: int  # slots on the grid
    dropped_skew: int  # no tuple within the skew bound
    dropped_far: int  # the tuple's frames lie more than half a slot period from the slot
    dropped_joints: int = 0  # no robot state (or action) within half a slot period (record.bagjoints)

    @property
    def dropped(self) -> int:
        return self.dropped_skew + self.dropped_far + self.dropped_joints


def typical_period_ns(times: Sequence[int]) -> int:
    """A camera's frame period: the median gap between its frames (0 for fewer than two)."""
    gaps = sorted(b - a for a, b in zip(times, times[1:]))
    return gaps[len(gaps) // 2] if gaps else 0


def slot_grid(times: Mapping[str, Sequence[int]], fps: float, max_skew_ns: int) -> Grid:
    """The kept slots of the grid over the span of ``times`` (each camera's capture times, in
    time order) at ``fps``; the counts of those dropped, and why."""
    timelines = {cam: Timeline(list(ts), 0, len(ts)) for cam, ts in times.items()}
    periods = {cam: typical_period_ns(ts) for cam, ts in times.items()}
    radius = radius_for(periods)
    tolerance = tolerance_for(periods, SYNC_TOLERANCE_MS)
    t0 = max(ts[0] for ts in times.values())
    end = min(ts[-1] for ts in times.values())
    half_period = 5e8 / fps
    slots: list[Slot] = []
    total = dropped_skew = dropped_far = 0
    k = 0
    while (t := t0 + round(k * 1e9 / fps)) <= end:
        sel = select_joint(timelines, t, radius, tolerance)
        if sel.skew_ns > max_skew_ns and sel.best_skew_ns <= max_skew_ns:
            sel = select_joint(timelines, t, radius, 0)  # the least-skew tuple, as the service answers
        total += 1
        if sel.skew_ns > max_skew_ns:
            dropped_skew += 1
        elif any(abs(tc - t) > half_period for tc in sel.t.values()):
            dropped_far += 1
        else:
            slots.append(Slot(k, t, dict(sel.index), dict(sel.t)))
        k += 1
    return Grid(slots, total, dropped_skew, dropped_far)
