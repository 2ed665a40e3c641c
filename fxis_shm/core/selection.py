"""Choosing one frame per camera for a tuple request.

``independent`` is the paper's behaviour: every camera's nearest frame to t*,
chosen on its own, which spikes (a skew near one frame period) when t* falls
about halfway between frames. ``joint`` chooses the frames together: among the
frames near t* (within one frame period of the slowest camera of t*, or of any
camera's nearest frame), the tuples whose skew (max minus min capture time) is
within ``tolerance_ns`` of the smallest possible skew, and of those the one
closest to t*.

``on_grid`` then holds lockstep frames to one grid point (their ``t_target``):
a joint tuple whose lockstep frames come from different points is replaced by
the best tuple of one point when one is stored near t*, and otherwise (and in
``independent`` mode) says so in ``grid_mismatch``.

Pure: timelines and numbers in, a Selection out.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from fxis_shm.core.timesearch import Timeline

INDEPENDENT = "independent"
JOINT = "joint"
SYNC_MODES = (JOINT, INDEPENDENT)
# The grid point (t_target) of a camera's frame, by its index in the camera's timeline, if the
# frame was captured on the lockstep grid; 0 otherwise.
GridOf = Callable[[str, int], int]


@dataclass(frozen=True)
class Selection:
    """Chosen logical index and capture time per camera."""

    index: Mapping[str, int]
    t: Mapping[str, int]
    least_skew_ns: int | None = None  # the least skew any candidate tuple had (joint only)
    # lockstep frames of different grid points, and no tuple of one point near t*: each such
    # camera's grid point (on_grid); None when the lockstep frames share one point
    grid_mismatch: Mapping[str, int] | None = None

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


def _candidates(tl: Timeline, centres: list[int], radius: int) -> list[range]:
    """The frames within ``radius`` of any of the ``centres`` (t* and every camera's nearest
    frame), as disjoint runs of indices in time order."""
    runs = sorted([tl.within(c - radius, c + radius) for c in centres], key=lambda run: run.start)
    merged: list[range] = []
    for run in runs:
        if not len(run):
            continue
        if merged and run.start <= merged[-1].stop:
            merged[-1] = range(merged[-1].start, max(merged[-1].stop, run.stop))
        else:
            merged.append(run)
    return merged


def _centres(timelines: Mapping[str, Timeline], t_star: int) -> list[int]:
    """t* and each camera's nearest frame: a tuple of less skew than any near t* may lie
    around a camera's nearest frame when that frame is far from t* (a camera that dropped
    frames, or stored them late), so the frames around each are candidates too."""
    return [t_star, *(tl.at(tl.nearest(t_star)) for tl in timelines.values())]


def select_joint(
    timelines: Mapping[str, Timeline],
    t_star: int,
    radius_ns: int,
    tolerance_ns: int = 1_000_000,
) -> Selection:
    """The tuple of least skew near ``t_star``; ties (within ``tolerance_ns``) go to the closest.

    ``radius_ns`` bounds how far a candidate frame may lie from t* or from a camera's
    nearest frame (normally the longest frame period among the cameras); each camera's
    nearest frame is always a candidate, so a camera with no frame near t* still gets one,
    and the frames of the others near it are candidates too.
    """
    if len(timelines) == 1:
        return select_independent(timelines, t_star)
    centres = _centres(timelines, t_star)
    events: list[tuple[int, str, int]] = []  # (time, camera, index) of every candidate, in time order
    for cam, tl in timelines.items():
        for run in _candidates(tl, centres, radius_ns):
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


def on_grid(
    sel: Selection,
    timelines: Mapping[str, Timeline],
    t_star: int,
    radius_ns: int,
    tolerance_ns: int,
    grid: GridOf,
    mode: str,
) -> Selection:
    """``sel`` if its lockstep frames share one grid point (or there are fewer than two).
    Else, in ``joint`` mode, the best tuple of one grid point among those of the lockstep
    frames chosen and of each camera's nearest frame, if every one of these cameras stores
    a frame of that point near t*; failing that (and in ``independent`` mode) ``sel`` with
    ``grid_mismatch`` naming each lockstep camera's point."""
    points = {c: g for c, g in ((c, grid(c, i)) for c, i in sel.index.items()) if g}
    if len(set(points.values())) < 2:
        return sel
    if mode == JOINT:
        matched = _one_grid_point(timelines, t_star, radius_ns, tolerance_ns, grid, points)
        if matched is not None:
            return matched
    return Selection(sel.index, sel.t, sel.least_skew_ns, points)


def _one_grid_point(
    timelines: Mapping[str, Timeline],
    t_star: int,
    radius_ns: int,
    tolerance_ns: int,
    grid: GridOf,
    points: dict[str, int],
) -> Selection | None:
    """Of the tuples whose frames of the cameras ``points`` names share a grid point, the
    least skewed (ties within the tolerance: the closest to t*, then the newest point); None
    if no point near t* has a frame of each of these cameras."""
    centres = _centres(timelines, t_star)
    nearest = {c: grid(c, tl.nearest(t_star)) for c, tl in timelines.items()}
    options: list[Selection] = []
    for point in sorted({*points.values(), *(g for g in nearest.values() if g)}):
        only: dict[str, int] = {}  # each lockstep camera's newest candidate frame of this point
        for cam in points:
            for run in _candidates(timelines[cam], centres, radius_ns):
                for i in range(run.start, run.stop):
                    if grid(cam, i) == point:
                        only[cam] = i
        if len(only) < len(points):
            continue
        tls = dict(timelines)
        for cam, i in only.items():
            tls[cam] = Timeline(tls[cam].times, tls[cam].physical(i), 1)
        chosen = select_joint(tls, t_star, radius_ns, tolerance_ns)
        index = {c: only.get(c, i) for c, i in chosen.index.items()}  # back to the whole timelines
        options.append(Selection(index, chosen.t))
    if not options:
        return None
    least = min(o.skew_ns for o in options)
    best: Selection | None = None
    for option in options:  # in grid order: the newest point wins ties
        if option.skew_ns > least + tolerance_ns:
            continue
        if best is None or option.max_abs_error_ns(t_star) <= best.max_abs_error_ns(t_star):
            best = option
    assert best is not None  # the least skewed option is within tolerance
    return Selection(best.index, best.t, least)


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
