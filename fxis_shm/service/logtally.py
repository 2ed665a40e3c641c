"""Log lines of one kind at most once an interval, with a count of the others (issue 42: a
client sending a bad request in a loop made 13.5 MB of log a minute, one line each).

The first line of a kind is logged at once; the next ones in the interval are only counted,
and when it ends one line says how many there were and the last of them. Pure: the caller
passes the time (the service's clock, ns) and logs the lines returned.
"""

from __future__ import annotations

from dataclasses import dataclass

INTERVAL_NS = 10 * 1_000_000_000


@dataclass
class _Kind:
    since: int  # when its first line was logged
    more: int = 0  # lines of it counted since, not logged
    last: str = ""


class LogTally:
    def __init__(self, interval_ns: int = INTERVAL_NS):
        self.interval_ns = interval_ns
        self._kinds: dict[str, _Kind] = {}

    def note(self, kind: str, text: str, now: int) -> list[str]:
        """The lines to log now for one more ``text`` of ``kind``: it, if it is the first of its
        kind in the interval, and the counts of the intervals that ended."""
        lines = self.flush(now)
        seen = self._kinds.get(kind)
        if seen is None:
            self._kinds[kind] = _Kind(now)
            return [*lines, text]
        seen.more, seen.last = seen.more + 1, text
        return lines

    def flush(self, now: int) -> list[str]:
        """The counts of the intervals that ended by ``now`` (call it now and then: the
        coordinator does from its loop)."""
        lines = []
        for kind, seen in list(self._kinds.items()):
            if now - seen.since < self.interval_ns:
                continue
            del self._kinds[kind]
            if seen.more:
                lines.append(
                    f"{seen.more} more of {kind} in the last {self.interval_ns / 1e9:g} s, the last: {seen.last}"
                )
        return lines
