"""Choosing one frame per camera for a tuple request.

``independent`` is the paper's behaviour: every camera's nearest frame to t*,
chosen on its own, which spikes (a skew near one frame period) when t* falls
about halfway between frames. ``joint`` chooses the frames together: among the
frames near t* (within about one frame period of the slowest camera), the
tuples whose skew (max minus min capture time) is within ``tolerance_ns`` of
the smallest possible skew, and of those the one closest to t*.

Pure: timelines and numbers in, a Selection out.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from fxis_shm.core.timesearch import Timeline

INDEPENDENT = "independent"
JOINT = "joint"
SYNC_MODES = (JOINT, INDEPENDENT)


@dataclass(frozen=True)
class Selection:
    """Chosen logical index and capture time per camera."""

    index: Mapping[str, int]
    t: Mapping[str, int]
    least_skew_ns: int | None = None  # the least skew any candidate tuple had (joint only)

    @property
    def skew_ns(self) -> int:
        return max(self.t.values()) - min(self.t.values())

    @property
    def best_skew_ns(self) -> int:
        """The least skew available near t* (for a joint selection; else this tuple's)."""
        return self.skew_ns if self.least_skew_ns is None else self.least_skew_ns

    def max_abs_error_ns(self, t_star: int) -> int:
        return max(abs(t_star - t) for t in self.t.values())


def select_independent(timelines: Mapping[str, Timeline], t_star: int) -> Selection:
    index = {cam: tl.nearest(t_star) for cam, tl in timelines.items()}
    return Selection(index, {cam: timelines[cam].at(i) for cam, i in index.items()})


def _candidates(tl: Timeline, t_star: int, radius: int) -> range:
    """The frames within ``radius`` of t*, and the nearest one: one run of indices, since the
    nearest frame lies inside the window or next to it."""
    near = tl.within(t_star - radius, t_star + radius)
    nearest = tl.nearest(t_star)
    return range(min(near.start, nearest), max(near.stop, nearest + 1))


def select_joint(
    timelines: Mapping[str, Timeline],
    t_star: int,
    radius_ns: int,
    tolerance_ns: int = 1_000_000,
) -> Selection:
    """The tuple of least skew near ``t_star``; ties (within ``tolerance_ns``) go to the closest.

    ``radius_ns`` bounds how far from t* a candidate frame may lie (normally the
    longest frame period among the cameras); each camera's nearest frame is
    always a candidate, so a camera with no frame that near still gets one.
    """
    if len(timelines) == 1:
        return select_independent(timelines, t_star)
    events: list[tuple[int, str, int]] = []  # (time, camera, index) of every candidate, in time order
    for cam, tl in timelines.items():
        run = _candidates(tl, t_star, radius_ns)
        for i in range(run.start, run.stop):
            events.append((tl.at(i), cam, i))
    events.sort()
    n_cams = len(timelines)
    # Two pointers: for every right end, the shortest window holding every camera.
    starts: list[int] = []
    ends: list[int] = []
    inside: dict[str, int] = {}
    left = 0
    for right in range(len(events)):
        cam = events[right][1]
        inside[cam] = inside.get(cam, 0) + 1
        while len(inside) == n_cams:
            left_cam = events[left][1]
            if inside[left_cam] == 1:
                break
            inside[left_cam] -= 1
            left += 1
        if len(inside) == n_cams:
            starts.append(left)
            ends.append(right)
    best_skew = min([events[ends[w]][0] - events[starts[w]][0] for w in range(len(starts))])
    best: Selection | None = None
    best_error = best_tuple_skew = 0
    for w in range(len(starts)):
        start, end = starts[w], ends[w]
        if events[end][0] - events[start][0] > best_skew + tolerance_ns:
            continue
        # each camera's frame in the window closest to t*; the newest wins ties, as in Timeline.nearest
        index: dict[str, int] = {}
        times: dict[str, int] = {}
        distance: dict[str, int] = {}
        for k in range(start, end + 1):
            t, cam, i = events[k]
            d = abs(t - t_star)
            if cam not in distance or d <= distance[cam]:
                index[cam], times[cam], distance[cam] = i, t, d
        error = max(distance.values())
        skew = max(times.values()) - min(times.values())
        # later windows are newer: newest wins ties
        if best is None or error < best_error or (error == best_error and skew <= best_tuple_skew):
            best, best_error, best_tuple_skew = Selection(index, times, best_skew), error, skew
    assert best is not None  # the tuple of least skew is always within tolerance
    return best


def select(
    mode: str,
    timelines: Mapping[str, Timeline],
    t_star: int,
    radius_ns: int,
    tolerance_ns: int = 1_000_000,
) -> Selection:
    if mode == INDEPENDENT:
        return select_independent(timelines, t_star)
    if mode == JOINT:
        return select_joint(timelines, t_star, radius_ns, tolerance_ns)
    raise ValueError(f"unknown sync mode {mode!r}; use one of {SYNC_MODES}")


def radius_for(periods: Mapping[str, int]) -> int:
    """How far from t* a tuple's frames may lie: the longest frame period."""
    return max(periods.values(), default=0)


def tolerance_for(periods: Mapping[str, int], tolerance_ms: float) -> int:
    """The sync tolerance: tuples this much more skewed than the least count as equally
    synchronized. Capped at a quarter of the shortest frame period, so it never lets a
    tuple of another skew class (a period apart) through."""
    known = [p for p in periods.values() if p > 0]
    tolerance = int(tolerance_ms * 1e6)
    return min(tolerance, min(known) // 4) if known else tolerance
