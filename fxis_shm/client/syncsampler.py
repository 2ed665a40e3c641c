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

import numpy as np

from fxis_shm.client.api import ClientApi
from fxis_shm.client.frames import FrameTuple
from fxis_shm.core.syncstats import ABSENT, CAPTURE_METHODS, Samples
from fxis_shm.errors import FxisError

LEAD_NS = 50_000_000  # the first slot: this far ahead of the moment the schedule is made


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
) -> Taken:
    """``seconds * rate_hz`` slots (at least one) of joint tuples of ``cameras``. Ends by the last
    slot's time plus ``grace_s``, whatever the services do; Ctrl-C ends it early with what came
    (``interrupted``), the slots not reached left out."""
    n = max(1, round(seconds * rate_hz))
    interval = round(1e9 / rate_hz)
    columns = {name: c for c, name in enumerate(cameras)}
    slots = client.clock() + LEAD_NS + np.arange(n, dtype=np.int64) * interval
    shape = (n, len(cameras))
    frame_id, t_capture, generation = (np.zeros(shape, dtype=np.int64) for _ in range(3))
    capture = np.full(shape, ABSENT, dtype=np.int64)
    residual = np.full(shape, np.nan)
    errors: Counter[str] = Counter()
    end = int(slots[-1]) + round(grace_s * 1e9)
    reached, k = n, 0
    try:
        for k, t_k in enumerate(slots.tolist()):
            now = client.clock()
            if now > end:
                errors[f"no time left to ask (the schedule ended {grace_s:g} s after its last slot)"] += n - k
                break
            if now < t_k:
                sleep((t_k - now) / 1e9)
            try:
                tuple_ = client.tuple(cameras, at=t_k, partial=True)
            except FxisError as exc:
                errors[" ".join(str(exc).split())] += 1
                continue
            with tuple_:
                _keep(tuple_, k, columns, frame_id, t_capture, generation, capture, residual)
    except KeyboardInterrupt:
        reached = k
    samples = Samples(
        cameras, slots[:reached], frame_id[:reached], t_capture[:reached], generation[:reached],
        capture[:reached], residual[:reached],
    )  # fmt: skip
    return Taken(samples, errors, reached < n)


def _keep(tuple_: FrameTuple, k: int, columns: dict[str, int], *arrays: np.ndarray) -> None:
    frame_id, t_capture, generation, capture, residual = arrays
    for name, frame in tuple_.items():
        c = columns.get(name)
        if c is None:
            continue
        frame_id[k, c], t_capture[k, c], generation[k, c] = frame.frame_id, frame.t_capture, frame.generation
        capture[k, c] = CAPTURE_METHODS.index(frame.capture)  # frames.py's FREE, SCHEDULED, LOCKSTEP
        if frame.residual_ns is not None:
            residual[k, c] = frame.residual_ns
