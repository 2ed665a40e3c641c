"""Which clock times are in. A service stamps frames and reads "now" in one clock for
all its processes (``fxis run --clock``): CLOCK_MONOTONIC by default (never steps;
shared by every process of a host), or CLOCK_REALTIME / CLOCK_TAI where PTP (linuxptp's
ptp4l + phc2sys) or chrony keeps the hosts of a cell in step, so that a caller on another
host reading the same clock needs no estimate of the offset.

A caller names its own clock the same way (``Client(clock="realtime")``) or passes a
function returning int ns.

Everything the service says names its clock one way, the POSIX name ("CLOCK_MONOTONIC"):
every reply's header, ``status`` (and the dashboard's /status.json), the lockstep grid, bag
metadata. What a user types may be either spelling, and what a peer's status says is read
in either (services before issue 43 said "monotonic" in ``status``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Protocol

from fxis_shm.errors import InvalidArgument

_CLOCK_TAI = getattr(time, "CLOCK_TAI", 11)  # Linux's number, for Pythons that lack the name
CLOCK_IDS = {"monotonic": time.CLOCK_MONOTONIC, "realtime": time.CLOCK_REALTIME, "tai": _CLOCK_TAI}
WIRE_NAMES = {"monotonic": "CLOCK_MONOTONIC", "realtime": "CLOCK_REALTIME", "tai": "CLOCK_TAI"}
DEFAULT = "monotonic"


_BY_WIRE_NAME = {wire: name for name, wire in WIRE_NAMES.items()}


def short_name(name: str) -> str:
    """``name`` as the short name ("monotonic") if it is a POSIX one ("CLOCK_MONOTONIC"); else as given."""
    return _BY_WIRE_NAME.get(name, name) if isinstance(name, str) else name


def check(name: str) -> str:
    """The clock's short name ("monotonic") for ``name`` in either spelling ("CLOCK_MONOTONIC" too)."""
    name = short_name(name)
    if name not in CLOCK_IDS:
        raise InvalidArgument(f"unknown clock {name!r}: use one of {', '.join(CLOCK_IDS)}")
    return name


def of_status(status: dict[str, Any]) -> str:
    """The short name of the clock a ``status`` reply names (either spelling; none: the default)."""
    return check(status.get("clock") or DEFAULT)


def reader(name: str) -> Callable[[], int]:
    """A function reading clock ``name`` in int ns."""
    name = check(name)
    if name == "monotonic":
        return time.monotonic_ns
    if name == "realtime":
        return time.time_ns
    clock_id = CLOCK_IDS[name]
    return lambda: time.clock_gettime_ns(clock_id)


def name_of(clock: Callable[[], int] | str | None) -> str | None:
    """The name of a caller's clock given as a name or as one of the readers above (None:
    some other function, whose relation to any service clock must be estimated)."""
    if clock is None:
        return DEFAULT
    if isinstance(clock, str):
        return check(clock)
    return {time.monotonic_ns: "monotonic", time.time_ns: "realtime"}.get(clock)


# The clock of this process's service (set once at the start of each service process).
_service_clock = DEFAULT
now: Callable[[], int] = time.monotonic_ns


def use(name: str) -> None:
    """Make ``now`` read clock ``name``: the service's processes call it first thing."""
    global _service_clock, now
    _service_clock, now = check(name), reader(name)


def service_clock() -> str:
    return _service_clock


def wire_name() -> str:
    """The service's clock as replies name it ("CLOCK_MONOTONIC", ...)."""
    return WIRE_NAMES[_service_clock]


def service_and_tai() -> tuple[int, int]:
    """This process's service clock and CLOCK_TAI, read together (for PTP camera timestamps)."""
    first = now()
    tai = time.clock_gettime_ns(CLOCK_IDS["tai"])
    return (first + now()) // 2, tai


def offset(to_clock: str, from_clock: str, reads: int = 5) -> int:
    """``to_clock`` minus ``from_clock`` now, in ns: the two read back to back ``reads`` times and
    the closest pair kept (a pair split by a preemption would be off by the preemption)."""
    read_to, read_from = reader(to_clock), reader(from_clock)
    best_gap, best = None, 0
    for _ in range(reads):
        before = read_from()
        target = read_to()
        after = read_from()
        if best_gap is None or after - before < best_gap:
            best_gap, best = after - before, target - (before + after) // 2
    return best


class StopEvent(Protocol):
    """What a sleep may be cut short by (a threading.Event)."""

    def is_set(self) -> bool: ...

    def wait(self, timeout: float | None = None) -> bool: ...


class Clock(Protocol):
    """Where the code that keeps time (the synthetic camera, the trigger timer, the coordinator's
    loop, the ring's writer) reads "now" and waits: ``REAL`` in a service; a virtual clock in the
    tests that run the sync logic in virtual time (tests/virtualtime), as trio's MockClock."""

    def now_ns(self) -> int:
        """The service's clock now, int ns."""
        ...

    def read(self, name: str) -> int:
        """Clock ``name`` (CLOCK_IDS) now, int ns: a lockstep grid is counted in another clock."""
        ...

    def sleep_until(self, t_ns: int, stop: StopEvent | None = None) -> bool:
        """Return at ``t_ns`` of the service's clock (at once if it has passed); False if ``stop``
        was set first."""
        ...


class RealClock:
    """The clocks themselves: ``now`` as ``use`` set it, and real sleeps."""

    def now_ns(self) -> int:
        return now()

    def read(self, name: str) -> int:
        return reader(name)()

    def sleep_until(self, t_ns: int, stop: StopEvent | None = None) -> bool:
        wait_s = (t_ns - now()) / 1e9
        if stop is not None:
            return not (stop.wait(wait_s) if wait_s > 0 else stop.is_set())
        if wait_s > 0:
            time.sleep(wait_s)
        return True


REAL = RealClock()
