"""The range of every number a user can type (docs/cli.md, "Ranges"): one table, checked where
the number is read, by the ``fxis`` flags (argparse's ``type``), the config file and the Python
API alike, before any work starts. A number out of its range is InvalidArgument (exit code 2)
naming the setting and the range, never a plan of 10^9 steps or a wait of years."""

from __future__ import annotations

import math
from dataclasses import dataclass

from fxis_shm.errors import InvalidArgument

HOUR_S = 3600.0
WEEK_S = 7 * 24 * HOUR_S


@dataclass(frozen=True)
class Range:
    """Numbers from ``lowest`` to ``highest`` (``lowest`` itself left out when ``above``), said
    as ``noun`` ("seconds", "a whole number of ns"); ``whole``: integers only."""

    lowest: float
    highest: float
    noun: str = "a number"
    above: bool = False
    whole: bool = False

    @property
    def words(self) -> str:
        """E.g. "seconds > 0 and at most 3600"."""
        low, high = (f"{int(v)}" if self.whole else f"{v:.12g}" for v in (self.lowest, self.highest))
        return f"{self.noun} {'>' if self.above else '>='} {low} and at most {high}"

    def holds(self, value: float) -> bool:
        if not math.isfinite(value) or value > self.highest:
            return False
        return value > self.lowest if self.above else value >= self.lowest

    def check(self, value: object, setting: str) -> float:
        """``value`` if it is a number of this range (an ``int`` where ``whole``); else
        InvalidArgument naming ``setting`` and the range."""
        number_types = (int,) if self.whole else (int, float)
        if isinstance(value, bool) or not isinstance(value, number_types) or not self.holds(value):
            raise InvalidArgument(f"{setting} must be {self.words}, got {value!r}")
        return value

    def parse(self, text: str, setting: str) -> float:
        """A flag's or a file's text as a number of this range (InvalidArgument if not)."""
        kind = int if self.whole else float
        try:
            value = kind(text)
        except (TypeError, ValueError):
            raise InvalidArgument(f"{setting} must be {self.words}, got {text!r}") from None
        return self.check(value, setting)


# seconds a client waits for a reply (Client(timeout=), a request's timeout=, --timeout)
TIMEOUT_S = Range(0, HOUR_S, "seconds", above=True)
# seconds of a snapshot's window before and after t (the rings' history bounds `before` further)
WINDOW_S = Range(0, HOUR_S, "seconds")
# how long a recording or a sync report runs (record --seconds, sync-report --seconds)
DURATION_S = Range(0, WEEK_S, "seconds", above=True)
# a rate a user asks for: tuples or frames a second (sync-report --rate, record --rate)
RATE_HZ = Range(0, 1000, "a number of Hz", above=True)
# slots a sync report plans (its --seconds times its --rate): the plan is an array of this many
MAX_TUPLES = 10_000_000
# a count of frames or tuples (record --frames, sequence count)
FRAMES = Range(1, 1e9, "a whole number", whole=True)
SEQUENCE_COUNT = Range(1, 100_000, "a whole number", whole=True)
# a time in ns of a clock (at, start, end): since boot or the epoch, within 2^62 ns (146 years)
AT_NS = Range(0, 2**62, "a whole number of ns", whole=True)
# milliseconds (max_skew_ms, interval_ms, sync-report thresholds)
MILLISECONDS = Range(0, HOUR_S * 1000, "a number of ms", above=True)
PERCENT = Range(0, 100, "a percentage")
JPEG_QUALITY = Range(1, 100, "a whole number", whole=True)
# frames a ring holds (slots), a ring's history in seconds, restarts of a crashed process
SLOTS = Range(2, 1_000_000, "a whole number", whole=True)
HISTORY_S = Range(0, HOUR_S, "seconds", above=True)
RESTART_LIMIT = Range(0, 1000, "a whole number", whole=True)
