"""One request at one moment: must it wait (for which cameras, until when), or
which frames answer it?

``decide`` is the one place this is settled. It runs the wait policy
(fxis_shm.core.waitpolicy) and the selection (fxis_shm.core.selection) over one look at
each camera, and answers with the selection that settled the wait.

Pure: snapshots, camera states, settings and ``now`` in; a ``Wait`` or a
``Plan`` out, or ``Reject`` raised (the request ends with that error).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from fxis_shm.core import sequences
from fxis_shm.core.selection import INDEPENDENT, GridOf, Selection, on_grid, radius_for, select, tolerance_for
from fxis_shm.core.snapshot import CAPTURE_LATE, CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED, Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import AUTO, NEXT, CameraState, waiting_for, waiting_for_selection
from fxis_shm.errors import Code


class Reject(Exception):
    """Ends a request with an error reply."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code, self.message = code, message


@dataclass(frozen=True)
class Wait:
    """Not yet: the cameras waited for, each until it is given up on (None: the deadline)."""

    until: dict[str, int | None]
    reason: str  # what is awaited, for the timeout message


@dataclass(frozen=True)
class Plan:
    """The answer: the reply's fields and the frames it carries, as (camera, snapshot index)."""

    body: dict[str, Any]
    picks: list[tuple[str, int]]
    groups: list[list[tuple[str, int]]] | None = None  # a sequence: the picks of each tuple


@dataclass(frozen=True)
class Context:
    """The request's settings and its cameras' frame periods."""

    periods: dict[str, int]
    wait: str
    sync: str
    sync_tolerance_ms: float
    max_skew_ms: float | None
    max_sequence_frames: int

    @property
    def radius_ns(self) -> int:
        return radius_for(self.periods)

    @property
    def tolerance_ns(self) -> int:
        return tolerance_for(self.periods, self.sync_tolerance_ms)


class Request(Protocol):
    """What ``decide`` reads of a request (fxis_shm.core.engine.Pending)."""

    request: dict[str, Any]
    cameras: list[str]
    t_received: int
    t_star: int
    missing: list[str]
    triggered: frozenset[str]
    t_trigger: int | None
    scheduled: frozenset[str]

    @property
    def op(self) -> str: ...


def decide(
    p: Request, now: int, snaps: Mapping[str, Snapshot], states: Mapping[str, CameraState], ctx: Context
) -> Wait | Plan:
    if p.op == "latest":
        return newest_frames(p.cameras, snaps)
    if p.op == "sequence":
        return _sequence(p, now, snaps, states, ctx)
    return _near(p, now, snaps, states, ctx)


def newest_frames(cameras: list[str], snaps: Mapping[str, Snapshot]) -> Plan:
    """``latest``: the newest stored frame of each camera (it never waits)."""
    check_not_empty(snaps)
    return Plan({"op": "latest"}, [(c, len(snaps[c].timeline) - 1) for c in cameras])


def _chooser(mode: str, ctx: Context) -> Callable[..., Selection]:
    radius, tolerance = ctx.radius_ns, ctx.tolerance_ns

    def choose(timelines: dict[str, Timeline], t: int, tolerance_ns: int = tolerance) -> Selection:
        return select(mode, timelines, t, radius, tolerance_ns)

    return choose


def _near(
    p: Request, now: int, snaps: Mapping[str, Snapshot], states: Mapping[str, CameraState], ctx: Context
) -> Wait | Plan:
    """image and tuple: one frame per camera near t*."""
    mode = INDEPENDENT if p.op == "image" else ctx.sync
    choose = _chooser(mode, ctx)
    usable = {c: _usable(p, c, snaps[c]) for c in p.cameras}
    timelines = {c: u[0] for c, u in usable.items() if u is not None}
    first = {c: u[1] for c, u in usable.items() if u is not None}
    stored: Selection | None = None
    if p.scheduled:  # the frames captured for t* (a capture at T), and the others' around t*
        waits = waiting_for(AUTO, p.t_star, now, {c: s for c, s in states.items() if c not in p.scheduled})
        waits.update({c: None for c, u in usable.items() if u is None})
    elif p.triggered:  # the triggered frames, and the others' frames around the trigger
        free = {c: s for c, s in states.items() if c not in p.triggered}
        waits = waiting_for(AUTO, p.t_star, now, free)
        waits.update(waiting_for(NEXT, p.t_star, now, {c: states[c] for c in p.triggered}, t_arrival=p.t_trigger or 0))
        waits.update({c: None for c, u in usable.items() if u is None})
    elif ctx.wait == NEXT:
        waits = waiting_for(NEXT, p.t_star, now, states, t_arrival=p.t_received)
        if p.t_star > now:  # a future t*: also reach the frames around it
            waits.update(waiting_for(AUTO, p.t_star, now, states))
    elif ctx.wait == AUTO:
        waits = {c: None for c, s in states.items() if s.newest is None}
        if not waits:
            stored = choose(timelines, p.t_star)
            waits = waiting_for_selection(
                p.t_star,
                now,
                timelines,
                states,
                lambda tls: choose(tls, p.t_star),
                ctx.radius_ns,
                ctx.tolerance_ns,
                stored=stored,
            )
    else:
        waits = {}
    if waits:
        return Wait(waits, f"the frames awaited from {sorted(waits)}")

    check_not_empty(snaps)
    if p.request.get("at") is not None:  # "now" is never too old: the ring moved on
        for cam in p.cameras:
            if cam not in p.triggered and cam not in p.scheduled:
                check_history(cam, snaps[cam], p.t_star, p.t_received, ctx.periods[cam])
    grid = _grid_of(snaps, first)

    def answer(tolerance_ns: int, chosen: Selection | None = None) -> Selection:
        """The reply's selection: lockstep frames held to one grid point (selection.on_grid)."""
        sel = chosen or choose(timelines, p.t_star, tolerance_ns)
        return on_grid(sel, timelines, p.t_star, ctx.radius_ns, tolerance_ns, grid, mode)

    sel = answer(ctx.tolerance_ns, stored)
    limit = None if ctx.max_skew_ms is None else ctx.max_skew_ms * 1e6
    if p.op == "tuple" and limit is not None and sel.skew_ns > limit:
        if sel.best_skew_ns <= limit:  # the least-skew tuple meets the limit
            sel = answer(0)
        if sel.skew_ns > limit:
            raise Reject(
                Code.SKEW_EXCEEDED,
                f"the best tuple near t* has a skew of {sel.best_skew_ns / 1e6:.3f} ms, "
                f"more than max_skew_ms={ctx.max_skew_ms}",
            )
    picks = [(c, first[c] + sel.index[c]) for c in p.cameras]  # in the order asked; back to snapshot indices
    body: dict[str, Any] = {"op": p.op, "t_request": p.t_star}
    if p.op == "tuple":
        body.update(skew_ns=sel.skew_ns, sync=mode)
        if p.missing:
            body["missing"] = p.missing
        if sel.grid_mismatch:
            body["grid_mismatch"] = dict(sel.grid_mismatch)
    return Plan(body, picks)


def _grid_of(snaps: Mapping[str, Snapshot], first: Mapping[str, int]) -> GridOf:
    """The grid point of a camera's frame by its index in the request's timeline of the
    camera (which starts at snapshot index ``first[cam]``): its t_target if it was captured
    on the lockstep grid, else 0."""

    def grid(cam: str, i: int) -> int:
        snap = snaps[cam]
        row = snap.rows[snap.slot(first[cam] + i)]
        return row.t_target if row is not None and row.capture == CAPTURE_LOCKSTEP else 0

    return grid


def _usable(p: Request, cam: str, snap: Snapshot) -> tuple[Timeline, int] | None:
    """The camera's frames the request may use, and the snapshot index of the first:
    for a camera the request triggered, only those stored after the trigger, and for one it
    scheduled, only the frame captured for t* (None: none yet)."""
    tl = snap.timeline
    if cam in p.scheduled:
        for i in range(len(tl) - 1, -1, -1):
            meta = snap.frame_meta(i)
            if meta.t_stored < p.t_received:  # stored before the request came: not its frame
                break
            if (meta.capture == CAPTURE_SCHEDULED or meta.capture == CAPTURE_LATE) and meta.t_target == p.t_star:
                return Timeline(tl.times, tl.physical(i), 1), i
        return None
    if cam not in p.triggered:
        return tl, 0
    first = len(tl)
    while first > 0 and snap.frame_meta(first - 1).t_stored >= (p.t_trigger or 0):
        first -= 1
    if first == len(tl):
        return None
    return Timeline(tl.times, tl.physical(first), len(tl) - first), first


def _sequence(
    p: Request, now: int, snaps: Mapping[str, Snapshot], states: Mapping[str, CameraState], ctx: Context
) -> Wait | Plan:
    spec = sequence_spec(p.request, p.t_star)
    waits: dict[str, int | None] = {}
    for cam, state in states.items():
        waits.update(waiting_for(AUTO, sequences.latest_needed(spec, state.period_ns), now, {cam: state}))
    if waits:
        return Wait(waits, f"the frames awaited from {sorted(waits)}")
    check_not_empty(snaps)
    ref = p.cameras[0]
    if spec.kind != sequences.CONSECUTIVE:  # consecutive frames are checked exactly, by index
        for cam in p.cameras:
            period = ctx.periods[cam]
            check_history(cam, snaps[cam], sequences.earliest_needed(spec, period), p.t_received, period)
    choose = _chooser(ctx.sync, ctx)
    timelines = {c: snaps[c].timeline for c in p.cameras}
    whole = dict.fromkeys(p.cameras, 0)  # the timelines start at snapshot index 0

    def held(tls: dict[str, Timeline], t: int, first: dict[str, int]) -> Selection:
        """The tuple at ``t``, its lockstep frames held to one grid point as a tuple's are."""
        grid = _grid_of(snaps, first)
        return on_grid(choose(tls, t), tls, t, ctx.radius_ns, ctx.tolerance_ns, grid, ctx.sync)

    groups: list[dict[str, int]] = []
    mismatches: list[dict[str, int] | None] = []
    if spec.kind == sequences.INTERVAL:
        targets = sequences.target_times(spec)
        for t in targets:
            sel = held(timelines, t, whole)
            groups.append(dict(sel.index))
            mismatches.append(dict(sel.grid_mismatch) if sel.grid_mismatch else None)
    else:
        try:
            indices = sequences.reference_indices(spec, timelines[ref])
        except sequences.NotYet as not_yet:  # (two names: mypyc types each by its first except)
            return Wait({ref: None}, f"the frames of camera {ref!r} ({not_yet})")
        except sequences.NotHeld as not_held:
            raise Reject(Code.OUT_OF_RANGE, f"camera {ref!r}: {not_held}") from None
        targets = [timelines[ref].at(i) for i in indices]
        t_last = targets[-1] if targets else p.t_star
        for cam in p.cameras[1:]:
            if waiting_for(AUTO, t_last, now, {cam: states[cam]}):
                return Wait({cam: None}, f"the frame of camera {cam!r} near the last reference time")
        for i, t in zip(indices, targets):
            only_this = {ref: Timeline(timelines[ref].times, timelines[ref].physical(i), 1)}
            sel = held({**timelines, **only_this}, t, {**whole, ref: i})
            groups.append({**sel.index, ref: i})
            mismatches.append(dict(sel.grid_mismatch) if sel.grid_mismatch else None)
    check_size(len(groups) * len(p.cameras), ctx.max_sequence_frames)
    tuples = [[(c, g[c]) for c in p.cameras] for g in groups]
    body: dict[str, Any] = {"op": "sequence", "t_request": p.t_star, "targets": targets}
    if len(p.cameras) > 1 and any(mismatches):
        body["grid_mismatch"] = mismatches  # per tuple: None, or each lockstep camera's point
    return Plan(body, [pick for t in tuples for pick in t], tuples)


def sequence_spec(request: dict[str, Any], t_star: int) -> sequences.SequenceSpec:
    return sequences.SequenceSpec(
        kind=request["kind"],
        t_star=t_star,
        count=request["count"] or 1,
        direction=request["direction"],
        interval_ns=int((request["interval_ms"] or 0) * 1e6),
        start=request["start"] or 0,
        end=request["end"] or 0,
    )


def check_not_empty(snaps: Mapping[str, Snapshot]) -> None:
    empty = [c for c, snap in snaps.items() if not len(snap.timeline)]
    if empty:
        raise Reject(Code.NO_FRAMES, f"camera(s) {empty} have stored no frame yet")


def check_history(cam: str, snap: Snapshot, t_earliest: int, t_received: int, period_ns: int) -> None:
    """OUT_OF_RANGE for a time more than half a period older than the camera's oldest frame:
    the frame nearest it was overwritten, and the oldest held is not it."""
    oldest = snap.timeline.at(0)
    if 2 * (oldest - t_earliest) > period_ns:
        raise Reject(
            Code.OUT_OF_RANGE,
            f"asks for frames {(oldest - t_earliest) / 1e6:.1f} ms older than the oldest "
            f"frame of camera {cam!r}; its ring holds {len(snap.timeline)} frames, the "
            f"oldest from {(t_received - oldest) / 1e6:.1f} ms before the request",
        )


def check_size(n_frames: int, limit: int) -> None:
    if n_frames > limit:
        raise Reject(Code.TOO_LARGE, f"the sequence names {n_frames} frames; the limit is {limit}")
