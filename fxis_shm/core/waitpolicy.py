"""When a request must wait for frames that are not stored yet.

- ``next`` (the paper's): wait until every camera of the request has stored a
  frame after the request arrived.
- ``auto`` (the default): wait only for frames the answer would use. Each
  camera's coming frames are predicted from its period (newest + k*period);
  the request's own selection runs over stored plus predicted frames, and the
  request waits for exactly the cameras whose chosen frame is still to come,
  each until that frame is overdue (then taken as dropped). For one camera this
  is: wait while t* >= newest + period/2 (with a sync tolerance, + tolerance/2:
  a predicted frame nearer by less than the tolerance may be so by jitter alone).
  A t* whose best frames are already stored never waits.
- ``none``: answer from what is stored.

A camera that captures only on a trigger (``CameraState.triggered``) delivers no frame by
itself: for a t* already past, none of its frames is predicted or waited for (``auto``), and
the engine refuses at once a request that needs one where it has stored none
(``never_coming``).

Pure: the camera states, timelines and ``now`` are passed in; nothing reads a clock.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from fxis_shm.core.selection import Selection
from fxis_shm.core.timesearch import Timeline

AUTO = "auto"
NEXT = "next"
NONE = "none"
WAIT_MODES = (AUTO, NEXT, NONE)


@dataclass(frozen=True)
class CameraState:
    """What the wait policy needs to know of one camera at one moment."""

    newest: int | None  # t_capture of the newest stored frame, None if none
    period_ns: int  # measured frame period, 0 if not known yet
    delay_ns: int = 0  # typical time from capture to storage
    newest_stored: int | None = None  # t_stored of the newest stored frame
    triggered: bool = False  # captures only on a trigger (trigger=software): no frame comes on its own


def comes_by_itself(cam: CameraState, t_star: int, now: int) -> bool:
    """Whether a frame for ``t_star`` may still come without this request triggering one: not
    for a t* already past on a camera that captures only on a trigger (its period is only the
    spacing of the triggers so far, and no frame is due)."""
    return not cam.triggered or t_star > now


def never_coming(t_star: int, now: int, cameras: Mapping[str, CameraState]) -> list[str]:
    """The cameras that have stored no frame and will store none for ``t_star`` by themselves."""
    return [name for name, cam in cameras.items() if cam.newest is None and not comes_by_itself(cam, t_star, now)]


def overdue_time(t_frame: int, cam: CameraState) -> int:
    """When a frame due at ``t_frame`` counts as dropped: it is stored a delay after
    capture; a full period of slack covers a worker delayed by load, which is far
    commoner than a dropped frame."""
    return t_frame + cam.period_ns + cam.delay_ns


def give_up_time(t_star: int, cam: CameraState) -> int:
    """When the frame nearest to t* (captured by t* + period/2) is overdue."""
    return overdue_time(t_star + cam.period_ns // 2, cam)


def waiting_for(
    mode: str, t_star: int, now: int, cameras: Mapping[str, CameraState], t_arrival: int = 0
) -> dict[str, int | None]:
    """Cameras the request must still wait for, each mapped to the moment it
    stops waiting for that camera (None: until the request's own deadline).

    The per-camera rules: ``auto`` waits while t* >= newest + period/2 (the next
    frame would be nearer, or as near and newer); ``next`` while no frame was
    stored at or after ``t_arrival``."""
    if mode not in WAIT_MODES:
        raise ValueError(f"unknown wait mode {mode!r}; use one of {WAIT_MODES}")
    waits: dict[str, int | None] = {}
    for name, cam in cameras.items():
        if mode == NONE or (mode == AUTO and not comes_by_itself(cam, t_star, now)):
            continue
        if mode == NEXT:
            if cam.newest_stored is None or cam.newest_stored < t_arrival:
                waits[name] = None
        elif cam.newest is None:
            waits[name] = None
        elif cam.period_ns > 0 and t_star >= cam.newest + cam.period_ns // 2:  # a tie goes to the newer frame
            until = give_up_time(t_star, cam)
            if now < until:
                waits[name] = until
    return waits


def with_predictions(tl: Timeline, cam: CameraState, now: int, up_to: int) -> tuple[Timeline, list[int]]:
    """``tl`` extended by the frames the camera should still deliver up to ``up_to``
    (skipping those already overdue); also returns the predicted times."""
    predicted = []
    if cam.newest is not None and cam.period_ns > 0:
        t = cam.newest + cam.period_ns
        while t <= up_to:
            if now < overdue_time(t, cam):
                predicted.append(t)
            t += cam.period_ns
    if not predicted:
        return tl, predicted
    times = [tl.at(i) for i in range(len(tl))] + predicted
    return Timeline(times, 0, len(times)), predicted


def waiting_for_selection(
    t_star: int,
    now: int,
    timelines: Mapping[str, Timeline],
    cameras: Mapping[str, CameraState],
    choose: Callable[[dict[str, Timeline]], Selection],
    radius_ns: int,
    tolerance_ns: int = 0,
    stored: Selection | None = None,
) -> dict[str, int | None]:
    """``auto`` for a request answered by ``choose``: the cameras whose frame in the
    best selection over stored and predicted frames is not stored yet.

    Predicted frames carry no timing jitter, so a tuple of them may look less skewed, or
    nearer to t*, than a stored one by noise alone: when the best stored tuple is at most
    ``tolerance_ns`` farther from t* and at most twice ``tolerance_ns`` more skewed, it is
    answered at once. (Waiting for a tuple only as near as the jitter says, the request once
    got the stored one anyway, a period late: issue 41.) ``stored``: the selection over the
    stored frames, if the caller made it already (it answers with it)."""
    waits: dict[str, int | None] = {n: None for n, c in cameras.items() if c.newest is None}
    if waits:
        return waits
    extended, stored_count, any_predicted = {}, {}, False
    for name, tl in timelines.items():
        cam = cameras[name]
        predicted: list[int] = []
        extended[name] = tl
        if comes_by_itself(cam, t_star, now):
            extended[name], predicted = with_predictions(tl, cam, now, t_star + radius_ns)
        stored_count[name] = len(tl)
        any_predicted = any_predicted or bool(predicted)
    if not any_predicted:  # every frame the request can use is stored
        return {}
    chosen = choose(extended)
    future = {n for n, i in chosen.index.items() if i >= stored_count[n]}
    if not future:
        return {}
    if stored is None:
        stored = choose(dict(timelines))
    as_near = stored.max_abs_error_ns(t_star) < chosen.max_abs_error_ns(t_star) + tolerance_ns
    if as_near and stored.skew_ns <= chosen.skew_ns + 2 * tolerance_ns:
        return {}
    return {n: overdue_time(extended[n].at(chosen.index[n]), cameras[n]) for n in future}
