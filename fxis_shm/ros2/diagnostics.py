"""``/diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``), as ROS camera drivers publish it:
one status a camera, once a second, with its level decided by the rules below (docs/ros2.md,
"Diagnostics"). ``diagnose`` is pure: a camera's status and its recent counters in, a status out.

Rules, first that holds wins:
  ERROR  the camera's worker is not running, or (free-running) its newest frame is older than
         10 frame periods and 1 s;
  WARN   (free-running) the rate measured over the window is below 90 % of the configured one;
         frames were dropped in the window; the worker restarted in the window;
  OK     otherwise.
A triggered camera has no rate to meet: only the ERROR rule about its worker applies to it.
STALE (3) is every camera's level when the service itself does not answer.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

from fxis_shm.formats import cdr
from fxis_shm.service.rtpolicy import sched_text

OK, WARN, ERROR, STALE = 0, 1, 2, 3
WINDOW_S = 5.0  # the rate and the drops are measured over the last this many seconds
RATE_FLOOR = 0.9  # below this share of the configured rate: WARN
STALE_PERIODS, STALE_MIN_S = 10, 1.0


@dataclass(frozen=True)
class Sample:
    """A camera's counters at one moment (monotonic seconds)."""

    t: float
    stored: int
    dropped: int
    restarts: int


def diagnose(service: str, camera: str, status: dict[str, Any], window: list[Sample]) -> cdr.DiagnosticStatus:
    """The DiagnosticStatus of ``camera`` from its entry in the service's status and the
    samples of the last ``WINDOW_S`` (oldest first, the newest being now)."""
    configured = float(status.get("fps") or 0.0)
    free = status.get("trigger", "free") == "free" and configured > 0
    first, last = window[0], window[-1]
    span = last.t - first.t
    measured = (last.stored - first.stored) / span if span > 0 else None
    age_ms = status.get("last_frame_age_ms")
    dropped, restarts = last.dropped - first.dropped, last.restarts - first.restarts
    problems: list[tuple[int, str]] = []
    if not status.get("alive", False):
        problems.append((ERROR, f"worker not running{': ' + status['note'] if status.get('note') else ''}"))
    elif free and age_ms is not None and age_ms / 1000 > max(STALE_MIN_S, STALE_PERIODS / configured):
        problems.append((ERROR, f"no frame for {age_ms / 1000:.1f} s"))
    if free and measured is not None and measured < RATE_FLOOR * configured:
        problems.append((WARN, f"{measured:.1f} frames/s of {configured:g} over {span:.0f} s"))
    if dropped > 0:
        problems.append((WARN, f"{dropped} frames dropped in {span:.0f} s"))
    if restarts > 0:
        problems.append((WARN, f"worker restarted {restarts} times in {span:.0f} s"))
    level = max((lvl for lvl, _ in problems), default=OK)
    message = "; ".join(text for _, text in problems) or "streaming"
    values = [
        ("rate_measured_hz", "" if measured is None else f"{measured:.2f}"),
        ("rate_configured_hz", f"{configured:g}"),
        ("rate_window_s", f"{span:.1f}"),
        ("frames_dropped", str(last.dropped)),
        ("newest_frame_age_ms", "" if age_ms is None else f"{age_ms:.1f}"),
        ("restarts", str(last.restarts)),
        ("worker", "running" if status.get("alive") else "down"),
        ("trigger", str(status.get("trigger", "free"))),
        ("generation", str(status.get("generation", ""))),
        ("scheduling", sched_text(status.get("sched"))),  # its worker's (fxis run --realtime)
    ]
    return cdr.DiagnosticStatus(level, f"fxis {service}: {camera}", message, f"{status.get('kind', '')}", values)


def unanswered(service: str, cameras: list[str], why: str) -> list[cdr.DiagnosticStatus]:
    """Every camera STALE: the service did not answer (``why``)."""
    return [
        cdr.DiagnosticStatus(STALE, f"fxis {service}: {camera}", f"service not answering: {why}") for camera in cameras
    ]


class Windows:
    """Each camera's samples of the last ``WINDOW_S``, a new one at each ``add``."""

    def __init__(self) -> None:
        self._samples: dict[str, deque[Sample]] = {}

    def add(self, camera: str, now: float, status: dict[str, Any]) -> list[Sample]:
        samples = self._samples.setdefault(camera, deque())
        stored = int(status.get("frames_stored", 0))
        if samples and stored < samples[-1].stored:  # a new ring (a restart): its counters start at 0
            last = samples[-1]
            samples.clear()
            samples.append(Sample(last.t, 0, 0, last.restarts))  # so the window still shows the restart
        samples.append(Sample(now, stored, int(status.get("frames_dropped", 0)), int(status.get("restarts", 0))))
        while len(samples) > 2 and now - samples[1].t >= WINDOW_S:
            samples.popleft()
        return list(samples)
