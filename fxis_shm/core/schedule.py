"""The arithmetic of triggering cameras for a moment (capture at T, lockstep): when to fire, whether
a T can be kept, which fired trigger a stored frame answers, the learned trigger latency, the
lockstep grid and the residuals' figures. Pure: numbers in, decisions out (the worker's timer
thread, workers/triggers.py, does the waiting and the firing)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

from fxis_shm.core.snapshot import CAPTURE_LATE, CAPTURE_SCHEDULED
from fxis_shm.errors import Code

MS = 1_000_000
# How soon a T may be: the command's way to the worker, the timer's wake-up and its spin
# (workers/triggers.py sleeps to 2 ms before the firing moment, then spins) plus the camera's
# latency. Below this the trigger cannot be fired before T minus the latency.
MIN_LEAD_NS = 5 * MS
MAX_AHEAD_NS = 10_000 * MS  # the request engine's horizon: a T further ahead is refused
LATENCY_SMOOTHING = 8  # EWMA weight 1/8 of the trigger latency, after a plain mean of the first 8
MATCH_SLACK_NS = 2 * MS  # a frame up to this much before its trigger still answers it (clock mapping)
MAX_LOCKSTEP_HZ = 1000.0
# how far from T a frame captured for T may land and still count as captured at T (a camera's
# capture_tolerance_ms): the timer's 2 ms of spinning; later, it was held up (or the camera's
# latency changed) and its frame is marked late
CAPTURE_TOLERANCE_MS = 2.0
# the clocks a lockstep grid may be counted in: the cell's common clocks (CLOCK_MONOTONIC is not
# common to hosts); the index is what the ring's header says (lockstep_clock)
GRID_CLOCKS = ("realtime", "tai")


@dataclass(frozen=True)
class Refusal:
    code: str
    message: str


def fire_time(t_target: int, latency_ns: int) -> int:
    """When to fire the trigger so that the capture lands on ``t_target``."""
    return t_target - max(0, latency_ns)


def check_target(t_target: int, now: int, latency_ns: int, min_lead_ns: int = MIN_LEAD_NS) -> Refusal | None:
    """None if a trigger for ``t_target`` can be fired in time, else why not (in the past, too near, too far)."""
    lead = t_target - now
    if lead < 0:
        return Refusal(
            Code.OUT_OF_RANGE, f"T is {-lead / MS:.1f} ms in the past: a capture can only be scheduled ahead"
        )
    nearest = min_lead_ns + max(0, latency_ns)
    if lead < nearest:
        return Refusal(
            Code.OUT_OF_RANGE,
            f"T is only {lead / MS:.1f} ms ahead: the nearest T this camera can be triggered for is "
            f"{nearest / MS:.1f} ms ahead ({min_lead_ns / MS:.0f} ms to schedule + {max(0, latency_ns) / MS:.1f} ms "
            "trigger latency)",
        )
    if lead > MAX_AHEAD_NS:
        return Refusal(
            Code.OUT_OF_RANGE,
            f"T is {lead / 1e9:.1f} s ahead: at most {MAX_AHEAD_NS / 1e9:.0f} s ahead can be scheduled",
        )
    return None


def learn_latency(old_ns: int, sample_ns: int, samples: int) -> int:
    """The trigger latency after one more sample (``samples`` counts it): a plain mean of the
    first LATENCY_SMOOTHING, then an exponential average."""
    weight = min(max(samples, 1), LATENCY_SMOOTHING)
    return sample_ns if samples <= 1 else old_ns + (sample_ns - old_ns) // weight


def answered_trigger(fired: list[int], t_capture: int, latency_ns: int, slack_ns: int = MATCH_SLACK_NS) -> int | None:
    """Which of the triggers fired at ``fired`` (oldest first, not yet answered) a frame captured
    at ``t_capture`` answers: of those fired before it (within ``slack_ns``), the one whose
    expected capture (fired + the learned latency) is nearest; the older ones got no frame.
    None: the frame came before any of them (a trigger not kept here)."""
    best, best_miss = None, 0
    for k, t_fired in enumerate(fired):
        if t_fired - slack_ns > t_capture:
            break
        miss = abs(t_fired + latency_ns - t_capture)
        if best is None or miss < best_miss:
            best, best_miss = k, miss
    return best


def parse_lockstep(text: str) -> tuple[float, int]:
    """``HZ[,PHASE_MS]`` as (hz, phase_ns); ValueError saying what is wrong."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) > 2:
        raise ValueError(f"lockstep {text!r}: give HZ or HZ,PHASE_MS")
    try:
        hz = float(parts[0])
        phase_ms = float(parts[1]) if len(parts) == 2 else 0.0
    except ValueError:
        raise ValueError(f"lockstep {text!r}: HZ and PHASE_MS are numbers (e.g. 20 or 20,5)") from None
    check_lockstep(hz)
    return hz, round(phase_ms * MS)


def check_lockstep(hz: float) -> None:
    if not 0 < hz <= MAX_LOCKSTEP_HZ:
        raise ValueError(f"lockstep rate {hz} Hz: it must be above 0 and at most {MAX_LOCKSTEP_HZ:.0f} Hz")


def check_grid_clock(name: str) -> str:
    if name not in GRID_CLOCKS:
        raise ValueError(f"lockstep clock {name!r}: use {' or '.join(GRID_CLOCKS)} (a clock the hosts of a cell share)")
    return name


def grid_period(hz: float) -> Fraction:
    """The lockstep grid's period in ns, exact (a float period would drift on a grid counted from 1970)."""
    return Fraction(10**9) / Fraction(hz).limit_denominator(10**6)


def next_grid_point(now: int, hz: float, phase_ns: int, lead_ns: int = 0) -> int:
    """The first point of the grid k/hz + phase (ns of the grid's clock) at or after ``now + lead_ns``."""
    period = grid_period(hz)
    k = math.ceil((now + lead_ns - phase_ns) / period)
    return phase_ns + math.ceil(k * period)


def grid_target(now: int, grid_offset: int, hz: float, phase_ns: int, lead_ns: int = 0) -> int:
    """The next grid point at or after ``now + lead_ns``, ``now`` in the service's clock and the grid
    counted in another clock (``grid_offset`` = that clock minus the service's): in the service's clock."""
    return next_grid_point(now + grid_offset, hz, phase_ns, lead_ns) - grid_offset


def percentile(values: list[int], q: float) -> int | None:
    """The q-th percentile (0-100) by nearest rank; None without values."""
    if not values:
        return None
    ordered = sorted(values)
    rank = min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))
    return ordered[rank]


def captured_as(capture: int, t_capture: int, t_target: int, tolerance_ns: int) -> int:
    """A stored frame's ``capture`` (core.snapshot.CAPTURES): a frame captured for a named moment
    that missed it by more than ``tolerance_ns`` either way is late, never just scheduled."""
    if capture == CAPTURE_SCHEDULED and abs(t_capture - t_target) > tolerance_ns:
        return CAPTURE_LATE
    return capture
