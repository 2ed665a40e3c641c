"""The sync figures of ``fxis sync-report`` (docs/sync.md, "Proving sync"): joint tuples taken
on a schedule in, librealsense's criteria and a PASS/FAIL verdict out.

librealsense's camera-sync test (unit-tests/live/camera-sync/test-intra-camera-sync.py) pairs
frames, takes the timestamp gap of each pair and asks: 95th percentile gap <= 3 ms, >= 95 % of
pairs within 3 ms, and <= 5 % of frames dropped (a frame number that did not advance by exactly
1). Here a "pair" is a joint tuple and its gap is the tuple's skew (max - min t_capture).

The definitions, per slot k of the schedule (one tuple asked for at t_k, every 1/rate):

- gap: the skew of slot k's tuple when it came complete (every camera in it); the percentiles
  are over complete tuples only (numpy's linear interpolation).
- synced: complete, and its gap <= the threshold; the percentage is of all slots.
- dropped: slot k is dropped when no tuple came, a camera is missing from it, or a camera's frame
  id did not advance as its period says since the slot j it was last in: ``r = (t_k - t_j) /
  period`` periods passed, so when r is a whole number exactly r new frames were due, and
  otherwise floor(r) or ceil(r) (the frame nearest t_k is one or the other, as the phases fall).
  Fewer is a *repeat* (the same frame again when a new one was due), more a *skip* (the frames
  beyond ceil(r) lost). A camera faster than the slowest is allowed ceil(slowest period / its
  period) - 1 frames more or fewer: the joint selection matches its frame to the slowest
  camera's. Ids of different generations (a camera restarted) are not compared. The percentage
  is of all slots. At the default rate (the slowest camera's) r = 1 for the slowest camera and
  every camera of its rate: librealsense's "frame number did not advance by 1".
- a camera that captures on request (trigger=software, not on a lockstep grid) has no rate of
  its own: the report asks it to capture at each t_k (capture at T), and it is judged on those
  moments: a slot whose frame was not captured for t_k (a frame of an earlier request read
  again) counts as a repeat, and so as dropped; one captured for t_k but late is the slot's
  frame (its lateness is in the gap and residual); its frame ids are not judged by a period.

Pure: arrays in, figures out; no I/O.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

# librealsense's criteria (the issue's): p95 gap <= 3 ms, >= 95 % synced, <= 5 % dropped
DEFAULT_THRESHOLD_MS = 3.0
DEFAULT_MAX_P95_MS = 3.0
DEFAULT_MIN_SYNCED_PCT = 95.0
DEFAULT_MAX_DROPPED_PCT = 5.0

# Frame.capture's values, in the order of the ``capture`` codes below (-1: no frame)
CAPTURE_METHODS = ("free", "scheduled", "lockstep", "late")
ABSENT = -1

Ints = npt.NDArray[np.int64]
# a slot interval within this share of a period of a whole number of periods counts as that
# whole number (rounded rates: 1e9 / 30 ns is not a whole number of ns)
WHOLE = 1e-3
# a frame's t_target within this of t_k was captured for slot k (both mapped through the
# caller's clock estimate, which may round by a few ns)
TARGET_SLACK_NS = 1_000
_TRIGGERED = [CAPTURE_METHODS.index("scheduled"), CAPTURE_METHODS.index("late")]  # captured for their t_target


@dataclass(frozen=True)
class Samples:
    """What the schedule gave: ``slots`` (n,) the t_k asked for; per camera (columns, in the order
    of ``cameras``) arrays (n, c): ``frame_id``, ``t_capture``, ``generation`` and ``capture`` (an
    index into CAPTURE_METHODS, ABSENT where the camera was not in slot k's tuple), and
    ``residual_ns`` (float, NaN where the frame had no target). Times in one clock, ns."""

    cameras: Sequence[str]
    slots: Ints
    frame_id: Ints
    t_capture: Ints
    generation: Ints
    capture: Ints
    residual_ns: npt.NDArray[np.float64]

    @property
    def present(self) -> npt.NDArray[np.bool_]:
        present: npt.NDArray[np.bool_] = self.capture != ABSENT
        return present


@dataclass(frozen=True)
class Thresholds:
    threshold_ms: float = DEFAULT_THRESHOLD_MS  # a tuple is synced when its gap is at most this
    max_p95_ms: float = DEFAULT_MAX_P95_MS
    min_synced_pct: float = DEFAULT_MIN_SYNCED_PCT
    max_dropped_pct: float = DEFAULT_MAX_DROPPED_PCT


@dataclass(frozen=True)
class CameraFigures:
    period_ms: float | None  # the period the frame ids are judged by
    missing: int  # slots whose tuple lacked this camera (or that got no tuple)
    repeated: int  # slots where its frame id advanced less than its period says
    skipped: int  # frames lost: advances beyond what its period says, summed
    captures: dict[str, int]  # frames per capture method
    residual_ms: dict[str, float] | None  # |t_capture - t_target|: p50, p99, max (scheduled/lockstep frames)
    on_request: bool = False  # captures on request: judged on the slots' moments, not a period


@dataclass(frozen=True)
class Check:
    name: str
    value: float | None
    relation: str  # "<=" or ">=": what the value must be to the limit
    limit: float
    unit: str
    passed: bool

    def __str__(self) -> str:
        value = "-" if self.value is None else f"{self.value:g} {self.unit}"
        return f"{self.name} {value} ({self.relation} {self.limit:g} {self.unit}{'' if self.passed else ': not met'})"


@dataclass(frozen=True)
class Figures:
    slots: int
    complete: int
    gap_ms: dict[str, float] | None  # p50, p95, p99, max, mean over complete tuples; None without any
    synced_pct: float
    dropped_pct: float
    cameras: dict[str, CameraFigures]
    checks: list[Check] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def as_dict(self) -> dict[str, Any]:
        return {
            "slots": self.slots,
            "complete": self.complete,
            "gap_ms": self.gap_ms,
            "synced_pct": self.synced_pct,
            "dropped_pct": self.dropped_pct,
            "cameras": {name: vars(cam) for name, cam in self.cameras.items()},
            "checks": [vars(c) for c in self.checks],
            "verdict": "PASS" if self.passed else "FAIL",
        }


def gaps_ns(samples: Samples) -> npt.NDArray[np.float64]:
    """Each slot's gap (max - min t_capture) in ns; NaN where the tuple was not complete."""
    n = len(samples.slots)
    if not len(samples.cameras):
        return np.full(n, np.nan)
    complete = samples.present.all(axis=1)
    times = samples.t_capture.astype(np.float64)
    gaps = times.max(axis=1) - times.min(axis=1)
    return np.where(complete, gaps, np.nan)


def _percentiles_ms(values_ns: npt.NDArray[np.float64], names: Mapping[str, float]) -> dict[str, float]:
    figures = {name: round(float(np.percentile(values_ns, q)) / 1e6, 3) for name, q in names.items()}
    figures["max"] = round(float(values_ns.max()) / 1e6, 3)
    return figures


def estimated_period_ns(frame_id: Ints, t_capture: Ints, generation: Ints) -> float | None:
    """A camera's period from its own frames (present ones, in slot order): the median of
    capture-time step over id step, between frames of one generation with ids that advanced."""
    did, dt = np.diff(frame_id), np.diff(t_capture)
    usable = (did > 0) & (np.diff(generation) == 0)
    if not usable.any():
        return None
    return float(np.median(dt[usable] / did[usable]))


def advance_faults(
    slots: Ints,
    frame_id: Ints,
    generation: Ints,
    present: npt.NDArray[np.bool_],
    period_ns: float | None,
    slack: int = 0,
) -> tuple[npt.NDArray[np.bool_], int, int]:
    """One camera's frame-id faults (see the module's text): a bool per slot (a repeat or a skip
    ends there), the repeats and the frames skipped; ``slack`` frames more or fewer allowed."""
    faulty = np.zeros(len(slots), dtype=bool)
    where = np.flatnonzero(present)
    if period_ns is None or period_ns <= 0 or len(where) < 2:
        return faulty, 0, 0
    now, before = where[1:], where[:-1]
    periods = (slots[now] - slots[before]) / period_ns
    # a whole number of periods: exactly that many new frames; between two whole numbers, either
    # (the frame nearest to t_k is the next or the one after, as the phases fall)
    fewest = np.floor(periods + WHOLE).astype(np.int64) - slack
    most = np.ceil(periods - WHOLE).astype(np.int64) + slack
    advance = frame_id[now] - frame_id[before]
    judged = generation[now] == generation[before]
    repeat = judged & (advance < fewest)
    skip = judged & (advance > most)
    faulty[now[repeat | skip]] = True
    return faulty, int(repeat.sum()), int(np.where(skip, advance - most, 0).sum())


def missed_moments(samples: Samples, c: int) -> npt.NDArray[np.bool_]:
    """Camera ``c``'s slots whose frame was not captured for the slot's moment t_k (a camera that
    captures on request, asked to capture at each t_k). A frame triggered for t_k that landed
    beyond the camera's tolerance (``late``) was captured for it: its lateness is in the gap and
    the residual, not a repeat."""
    target = samples.t_capture[:, c].astype(np.float64) - samples.residual_ns[:, c]
    triggered = np.isin(samples.capture[:, c], _TRIGGERED)
    captured_for_slot = triggered & (np.abs(np.nan_to_num(target - samples.slots, nan=np.inf)) <= TARGET_SLACK_NS)
    missed: npt.NDArray[np.bool_] = samples.present[:, c] & ~captured_for_slot
    return missed


def figures(
    samples: Samples,
    thresholds: Thresholds | None = None,
    nominal_period_ns: Mapping[str, float | None] | None = None,
    on_request: Sequence[str] = (),
) -> Figures:
    """The report's figures and its checks. ``nominal_period_ns``: each camera's set period (its
    status' fps), which its frame ids are judged by; where not given, estimated from its frames.
    ``on_request``: the cameras that capture on request, judged on the slots' moments instead."""
    thresholds = thresholds or Thresholds()
    n = len(samples.slots)
    present = samples.present
    gaps = gaps_ns(samples)
    complete = ~np.isnan(gaps)
    dropped = ~present.all(axis=1) if len(samples.cameras) else np.ones(n, dtype=bool)
    cameras = {}
    periods: dict[str, float | None] = {}
    for c, name in enumerate(samples.cameras):
        mine = present[:, c]
        ids, times, gens = samples.frame_id[mine, c], samples.t_capture[mine, c], samples.generation[mine, c]
        if name in on_request:
            periods[name] = None
            continue
        periods[name] = (nominal_period_ns or {}).get(name) or estimated_period_ns(ids, times, gens)
    slowest = max((p for p in periods.values() if p), default=None)
    for c, name in enumerate(samples.cameras):
        mine, period = present[:, c], periods[name]
        # a joint tuple matches a faster camera's frame to the slowest one's: it may be that many off
        slack = 0 if not (period and slowest) else int(np.ceil(slowest / period - WHOLE)) - 1
        faulty, repeated, skipped = advance_faults(
            samples.slots, samples.frame_id[:, c], samples.generation[:, c], mine, period, slack
        )
        if name in on_request:
            faulty = missed_moments(samples, c)
            repeated = int(faulty.sum())
        dropped |= faulty
        methods = samples.capture[mine, c]
        residuals = np.abs(samples.residual_ns[mine, c])
        residuals = residuals[~np.isnan(residuals)]
        cameras[name] = CameraFigures(
            period_ms=None if period is None else round(period / 1e6, 3),
            missing=int((~mine).sum()),
            repeated=repeated,
            skipped=skipped,
            captures={m: int((methods == i).sum()) for i, m in enumerate(CAPTURE_METHODS)},
            residual_ms=_percentiles_ms(residuals, {"p50": 50, "p99": 99}) if len(residuals) else None,
            on_request=name in on_request,
        )
    synced = complete & (np.nan_to_num(gaps, nan=np.inf) <= thresholds.threshold_ms * 1e6)
    gap_ms = _percentiles_ms(gaps[complete], {"p50": 50, "p95": 95, "p99": 99}) if complete.any() else None
    if gap_ms is not None:
        gap_ms["mean"] = round(float(gaps[complete].mean()) / 1e6, 3)
    synced_pct = round(100.0 * float(synced.sum()) / n, 2) if n else 0.0
    dropped_pct = round(100.0 * float(dropped.sum()) / n, 2) if n else 100.0
    p95 = None if gap_ms is None else gap_ms["p95"]
    t = thresholds
    checks = [
        Check("p95 gap", p95, "<=", t.max_p95_ms, "ms", p95 is not None and p95 <= t.max_p95_ms),
        Check("synced", synced_pct, ">=", t.min_synced_pct, "%", n > 0 and synced_pct >= t.min_synced_pct),
        Check("dropped", dropped_pct, "<=", t.max_dropped_pct, "%", dropped_pct <= t.max_dropped_pct),
    ]
    return Figures(n, int(complete.sum()), gap_ms, synced_pct, dropped_pct, cameras, checks)
