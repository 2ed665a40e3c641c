"""When a request must wait for frames that are not stored yet.

- ``next`` (the paper's): wait until every camera of the request has stored a
  frame after the request arrived.
- ``auto`` (the default): wait for a camera only while its next frame could be
  closer to t* than its newest stored one, i.e. while t* >= newest + period/2,
  and stop waiting for it once that frame is overdue (dropped); a t* whose
  nearest frame is already stored never waits.
- ``none``: answer from what is stored.

Pure: the camera states and ``now`` are passed in; nothing reads a clock.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

AUTO = "auto"
NEXT = "next"
NONE = "none"
WAIT_MODES = (AUTO, NEXT, NONE)


@dataclass(frozen=True)
class CameraState:
    """What the wait policy needs to know of one camera at one moment."""

    count: int  # frames stored so far (the ring's write counter)
    baseline: int  # frames stored when the request arrived
    newest: int | None  # t_capture of the newest stored frame, None if none
    period_ns: int  # measured frame period, 0 if not known yet
    delay_ns: int = 0  # typical time from capture to storage


def give_up_time(t_star: int, cam: CameraState) -> int:
    """When the frame nearest to t* is overdue (dropped): it is captured by
    t* + period/2 and stored a delay later; a full period of slack covers a
    worker delayed by load, which is far commoner than a dropped frame."""
    return t_star + cam.period_ns * 3 // 2 + cam.delay_ns


def waiting_for(
    mode: str, t_star: int, now: int, cameras: Mapping[str, CameraState]
) -> dict[str, int | None]:
    """Cameras the request must still wait for, each mapped to the moment it
    stops waiting for that camera (None: until the request's own deadline)."""
    if mode not in WAIT_MODES:
        raise ValueError(f"unknown wait mode {mode!r}; use one of {WAIT_MODES}")
    waits: dict[str, int | None] = {}
    for name, cam in cameras.items():
        if mode == NONE:
            continue
        if mode == NEXT:
            if cam.count <= cam.baseline:
                waits[name] = None
            continue
        if cam.newest is None:
            waits[name] = None
        elif cam.period_ns > 0 and t_star >= cam.newest + cam.period_ns // 2:  # a tie goes to the newer frame
            until = give_up_time(t_star, cam)
            if now < until:
                waits[name] = until
    return waits
