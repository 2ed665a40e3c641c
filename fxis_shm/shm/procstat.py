"""What Linux says of a process in ``/proc/PID/stat``, read in one place.

The command name in the second field may hold spaces and parentheses, so the
fields are counted from the last ``)``. Used by the library (is a camera worker
alive?), the tests (which processes belong to a service?) and the benches (CPU).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

CLOCK_TICKS_PER_S = os.sysconf("SC_CLK_TCK")


@dataclass(frozen=True)
class ProcStat:
    pid: int
    state: str  # R, S, D, Z (zombie), X (dead), ...
    ppid: int
    cpu_ticks: int  # user + system time of every thread, in clock ticks
    name: str = ""  # the command name (/proc/PID/comm): "python3", or a forked worker's "fxis camera"

    @property
    def running(self) -> bool:
        """True unless the process is a zombie (dead, not yet reaped) or dead."""
        return self.state not in ("Z", "X", "x")

    @property
    def cpu_seconds(self) -> float:
        return self.cpu_ticks / CLOCK_TICKS_PER_S


def read(pid: int) -> ProcStat | None:
    """The process's stat, or None if there is no such process (any more)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            raw = f.read()
    except OSError:
        return None
    end = raw.rfind(b")")
    fields = raw[end + 2 :].split()
    # fields[0] is the state (field 3 of proc(5)), [1] the ppid, [11] utime, [12] stime
    name = raw[raw.find(b"(") + 1 : end].decode(errors="replace")
    return ProcStat(pid, fields[0].decode(), int(fields[1]), int(fields[11]) + int(fields[12]), name)


def children(ppid: int) -> list[ProcStat]:
    """Every process whose parent is ``ppid``."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = read(int(entry))
            if stat is not None and stat.ppid == ppid:
                found.append(stat)
    return found


def descendants(root: int) -> list[int]:
    """Every process below ``root`` (children, their children, ...)."""
    parent_of = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = read(int(entry))
            if stat is not None:
                parent_of[stat.pid] = stat.ppid
    found, frontier = [], [root]
    while frontier:
        frontier = [pid for pid, ppid in parent_of.items() if ppid in frontier]
        found += frontier
    return found


def cmdline(pid: int) -> list[str]:
    """The process's arguments ([] if it is gone)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return [a.decode(errors="replace") for a in f.read().split(b"\0") if a]
    except OSError:
        return []
