"""The joint tuples ``fxis sync-report`` judges: one asked for at each t_k of a schedule (every
1/rate from a moment just ahead, in the caller's clock), from one service or a cell
(``Client([a, b])``), as ``client.tuple(at=t_k, partial=True)`` would give it. Only the
frames' identities and times are kept (fxis_shm.core.syncstats.Samples); the pixels are
released at once.

A slot whose tuple does not come (a service down, a refusal) stays empty and the next is asked;
slots the schedule has no time left for (a request that waited for its time-out) are empty too.
Either way they count as dropped, never as an error of the report.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fxis_shm.client.api import ClientApi
from fxis_shm.client.frames import FrameTuple
from fxis_shm.core.syncstats import ABSENT, CAPTURE_METHODS, Samples
from fxis_shm.errors import FxisError, InvalidArgument
from fxis_shm.wire import ranges

LEAD_NS = 50_000_000  # the first slot: this far ahead of the moment the schedule is made
# a capture at t_k (cameras that capture on request) is asked this far ahead at most: room for
# the service's 5 ms and a camera's trigger latency (the Aravis fake camera's: about 20 ms)
CAPTURE_LEAD_NS = 100_000_000


@dataclass
class Taken:
    """What the schedule gave: the samples, and why slots stayed empty (message -> count)."""

    samples: Samples
    errors: Counter[str] = field(default_factory=Counter)
    interrupted: bool = False


def take(
    client: ClientApi,
    cameras: list[str],
    seconds: float,
    rate_hz: float,
    grace_s: float = 5.0,
    sleep: Callable[[float], None] = time.sleep,
    capture: bool = False,
) -> Taken:
    """``seconds * rate_hz`` slots (at least one) of joint tuples of ``cameras``. Ends by the last
    slot's time plus ``grace_s``, whatever the services do; Ctrl-C ends it early with what came
    (``interrupted``), the slots not reached left out. With ``capture`` each t_k is asked ahead
    as a capture at T: the cameras that capture on request are triggered for it."""
    n = planned_slots(seconds, rate_hz)
    interval = round(1e9 / rate_hz)
    first = client.clock() + CAPTURE_LEAD_NS if capture else _first_slot(client, cameras, interval)
    lead = CAPTURE_LEAD_NS if capture else 0
    slots = first + np.arange(n, dtype=np.int64) * interval
    rows: list[Row | None] = []
    errors: Counter[str] = Counter()
    end = int(slots[-1]) + round(grace_s * 1e9)
    interrupted = False
    try:
        for k, t_k in enumerate(slots.tolist()):
            now = client.clock()
            if now > end:
                errors[f"no time left to ask (the schedule ended {grace_s:g} s after its last slot)"] += n - k
                rows += [None] * (n - k)
                break
            if now < t_k - lead:
                sleep((t_k - lead - now) / 1e9)
            try:
                tuple_ = client.tuple(cameras, at=t_k, partial=True, capture=capture)
            except FxisError as exc:
                errors[" ".join(str(exc).split())] += 1
                rows.append(None)
                continue
            with tuple_:
                rows.append(row_of(tuple_))
    except KeyboardInterrupt:
        interrupted = True
    return Taken(samples_of(cameras, slots[: len(rows)], rows), errors, interrupted)


def planned_slots(seconds: float, rate_hz: float) -> int:
    """The slots of ``seconds`` at ``rate_hz`` (at least one); InvalidArgument if either is out
    of its range (fxis_shm.wire.ranges) or they make more than MAX_TUPLES."""
    ranges.DURATION_S.check(seconds, "seconds")
    ranges.RATE_HZ.check(rate_hz, "rate")
    n = max(1, round(seconds * rate_hz))
    if n > ranges.MAX_TUPLES:
        raise InvalidArgument(
            f"{seconds:g} s at {rate_hz:g} Hz is {n} tuples, more than {ranges.MAX_TUPLES} a report takes: "
            "give fewer seconds or a lower rate"
        )
    return n


def _first_slot(client: ClientApi, cameras: list[str], interval: int) -> int:
    """LEAD_NS ahead, on the cameras' own frame times: the newest tuple's latest capture moved
    on by whole intervals. (A schedule half a period off the frames asks between two of them,
    where the cameras' jitter flips the nearest one: a frame read twice, then one skipped,
    though the camera dropped none: 9 of 60 slots so on a loaded machine.)"""
    ahead = client.clock() + LEAD_NS
    try:
        with client.tuple(cameras, partial=True) as newest:
            anchor = max(frame.t_capture for frame in newest.values())
    except (FxisError, ValueError):  # no service answers now, or no frame: the slots will say so
        return ahead
    return anchor + -(-(ahead - anchor) // interval) * interval


# what a tuple says of each camera's frame: frame id, t_capture, generation, capture method (an
# index into CAPTURE_METHODS) and residual (ns, NaN for a frame without a target)
Row = dict[str, tuple[int, int, int, int, float]]


def row_of(tuple_: FrameTuple) -> Row:
    return {
        name: (
            frame.frame_id,
            frame.t_capture,
            frame.generation,
            CAPTURE_METHODS.index(frame.capture),  # frames.py's FREE, SCHEDULED, LOCKSTEP
            float("nan") if frame.residual_ns is None else float(frame.residual_ns),
        )
        for name, frame in tuple_.items()
    }


def samples_of(cameras: list[str], slots: NDArray[Any], rows: list[Row | None]) -> Samples:
    """The arrays of ``cameras`` from one row per slot (None: no tuple came for it)."""
    shape = (len(rows), len(cameras))
    frame_id, t_capture, generation = (np.zeros(shape, dtype=np.int64) for _ in range(3))
    capture = np.full(shape, ABSENT, dtype=np.int64)
    residual = np.full(shape, np.nan)
    for k, row in enumerate(rows):
        for c, name in enumerate(cameras):
            if row is not None and name in row:
                frame_id[k, c], t_capture[k, c], generation[k, c], capture[k, c], residual[k, c] = row[name]
    return Samples(cameras, np.asarray(slots, dtype=np.int64), frame_id, t_capture, generation, capture, residual)
