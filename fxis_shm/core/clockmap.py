"""The caller's clock against a service's: offset, drift and how sure we are, from
NTP-style exchanges of four timestamps.

An exchange is: the caller sends at ``sent`` (its clock), the service receives it at
``received`` and replies at ``replied`` (its clock), the caller has the reply at ``back``.
Then ``offset = ((received - sent) + (replied - back)) / 2`` (service minus caller) and the
error of that offset is at most half the round trip ``(back - sent) - (replied - received)``.
Queueing only ever adds delay, so the exchanges with the shortest round trips are the
truest: each burst of exchanges gives its shortest one, and the estimate rests on the
bursts whose round trips are near the shortest seen. Over a long enough span a straight
line through them gives the drift (crystals differ by tens of ppm: 1.5 ms in 30 s).

Pure: exchanges in, an estimate out; no clock is read here.
"""

from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass

SAME_CLOCK = "same clock"  # the service reads this very clock: offset 0, exactly
SHARED = "shared"  # both read a clock kept in step by PTP/NTP (realtime, tai): offset 0 by construction
ESTIMATED = "estimated"  # from exchanges


@dataclass(frozen=True)
class Exchange:
    sent: int  # caller's clock
    received: int  # service's clock
    replied: int  # service's clock
    back: int  # caller's clock

    @property
    def round_trip(self) -> int:
        return (self.back - self.sent) - (self.replied - self.received)

    @property
    def offset(self) -> int:
        return ((self.received - self.sent) + (self.replied - self.back)) // 2

    @property
    def at(self) -> int:
        """When it happened, in the caller's clock."""
        return (self.sent + self.back) // 2


@dataclass(frozen=True)
class ClockEstimate:
    """``service = caller + offset_ns + drift * (caller - at_ns)``, give or take ``uncertainty_ns``."""

    offset_ns: int
    drift_ppm: float = 0.0
    uncertainty_ns: int = 0
    method: str = SAME_CLOCK
    at_ns: int = 0  # caller's clock at which offset_ns holds
    samples: int = 0  # exchanges the estimate rests on (0: none were needed)

    def to_service(self, t_caller: int) -> int:
        return t_caller + self.offset_ns + round(self.drift_ppm * 1e-6 * (t_caller - self.at_ns))

    def to_caller(self, t_service: int) -> int:
        return self.at_ns + round((t_service - self.offset_ns - self.at_ns) / (1 + self.drift_ppm * 1e-6))

    def as_dict(self) -> dict[str, object]:
        return {
            "method": self.method,
            "offset_ns": self.offset_ns,
            "drift_ppm": round(self.drift_ppm, 3),
            "uncertainty_ns": self.uncertainty_ns,
            "samples": self.samples,
        }


IDENTITY = ClockEstimate(0)


class ClockEstimator:
    """Bursts of exchanges in, the current estimate out.

    ``window_ns``: how far back bursts count (drift changes slowly, with temperature);
    ``drift_span_ns``: the least span of good bursts a drift is fitted over (shorter: 0);
    ``slack``: a burst is good when its round trip is at most ``slack`` times the shortest
    in the window plus ``slack_ns`` (its queueing delay then hardly moves the offset)."""

    def __init__(
        self,
        window_ns: int = 120_000_000_000,
        drift_span_ns: int = 10_000_000_000,
        slack: float = 1.5,
        slack_ns: int = 20_000,
        max_bursts: int = 512,
    ):
        self.window_ns, self.drift_span_ns = window_ns, drift_span_ns
        self.slack, self.slack_ns = slack, slack_ns
        self._best: deque[Exchange] = deque(maxlen=max_bursts)  # the shortest exchange of each burst

    def __len__(self) -> int:
        return len(self._best)

    def add_burst(self, exchanges: list[Exchange]) -> None:
        valid = [e for e in exchanges if e.round_trip >= 0]  # a negative one is a broken stamp
        if valid:
            self._best.append(min(valid, key=lambda e: e.round_trip))
            while self._best and self._best[-1].at - self._best[0].at > self.window_ns:
                self._best.popleft()

    def estimate(self) -> ClockEstimate | None:
        if not self._best:
            return None
        shortest = min(e.round_trip for e in self._best)
        good = [e for e in self._best if e.round_trip <= shortest * self.slack + self.slack_ns]
        newest = good[-1].at
        uncertainty = int(statistics.median(e.round_trip for e in good)) // 2
        if len(good) >= 3 and newest - good[0].at >= self.drift_span_ns:
            base = good[-1].offset  # fitted around it: offsets near 2**63 would lose ns in a float
            offset, slope = _line([e.at - newest for e in good], [e.offset - base for e in good])
            return ClockEstimate(base + round(offset), slope * 1e6, uncertainty, ESTIMATED, newest, len(good))
        recent = [e for e in good if newest - e.at <= self.drift_span_ns]  # no drift to speak of yet
        offset = statistics.median_low(e.offset for e in recent)
        return ClockEstimate(offset, 0.0, uncertainty, ESTIMATED, newest, len(recent))


def _line(xs: list[int], ys: list[int]) -> tuple[float, float]:
    """Least squares ``y = a + b x``: (a, b), with x centred first."""
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else 0.0
    return my - b * mx, b
