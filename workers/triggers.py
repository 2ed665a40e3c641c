"""Triggers for a moment: a capture at T (``trigger_at``) and the lockstep grid (``lockstep``).

A thread of its own (``TriggerTimer``) fires the camera's software trigger at T minus the
camera's learned trigger latency, or on every point of the grid k/HZ + PHASE of CLOCK_REALTIME or
CLOCK_TAI (the cell's common clocks: emulated hosts share them, not CLOCK_MONOTONIC). It sleeps to 2 ms
before the moment, then spins on the clock: a sleep alone wakes up to a scheduler tick late.
Every trigger fired, also the coordinator's "now" triggers, goes into the ``TriggerLog``; each
frame stored takes from it which trigger it answers (so its slot record says scheduled or
lockstep, and for which moment), and the log learns the latency trigger -> t_capture from them.
The arithmetic is fxis_shm.core.schedule's. The timer reads its clock and waits on ``clock``
(fxis_shm.core.timebase.Clock): the real one in a worker; the virtual-time tests run it without
its thread (``threaded=False``), firing each trigger (``fire_next``) at the moment ``next_fire``
names, or as late as their script says.
"""

from __future__ import annotations

import heapq
import logging
import threading
from collections import deque
from collections.abc import Callable

from fxis_shm.core import schedule, timebase
from fxis_shm.core.snapshot import CAPTURE_FREE, CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED
from fxis_shm.errors import Code, ProtocolError

log = logging.getLogger("camera")
_SPIN_NS = 2 * schedule.MS  # spin on the clock for the last 2 ms before a trigger
_IDLE_S = 0.1  # how often an idle timer looks at its stop event
_KEPT = 512  # lockstep residuals kept for the percentiles, and fired triggers kept unanswered
_MARGIN_NS = schedule.MS // 2  # a lockstep trigger is planned at least this far ahead


class TriggerLog:
    """The triggers fired and not yet answered by a frame; the learned latency; the figures."""

    def __init__(self, tolerance_ns: int = round(schedule.CAPTURE_TOLERANCE_MS * schedule.MS)) -> None:
        """``tolerance_ns``: a frame captured for T further from T than this is marked late."""
        self._lock = threading.Lock()
        self.tolerance_ns = tolerance_ns
        self._fired: deque[tuple[int, int, int]] = deque(maxlen=_KEPT)  # (t_fired, t_target, capture)
        self.latency_ns = 0
        self.samples = 0
        self.scheduled = 0  # frames captured for a trigger_at
        self.lockstep_frames = 0
        self.missed = 0  # lockstep and scheduled triggers that got no frame
        self.residuals: deque[int] = deque(maxlen=_KEPT)  # t_capture - t_target of lockstep frames
        self.grid: tuple[float, int] | None = None  # the lockstep grid (hz, phase_ns), for status
        self.grid_clock = schedule.GRID_CLOCKS[0]  # the clock it is counted in
        self.lateness: deque[int] = deque(maxlen=_KEPT)  # how late the timer fired: its jitter here

    def fired(self, t_fired: int, t_target: int = 0, capture: int = CAPTURE_FREE, late_ns: int = 0) -> None:
        """A trigger fired at ``t_fired``, for ``t_target`` (``late_ns`` after the timer's moment)."""
        with self._lock:
            self._fired.append((t_fired, t_target, capture))
            if capture != CAPTURE_FREE:
                self.lateness.append(late_ns)

    def answer(self, t_capture: int) -> tuple[int, int]:
        """(t_target, capture) of a frame captured at ``t_capture``: the trigger it answers (a
        scheduled one answered too far from its T: late)."""
        with self._lock:
            fired = [t for t, _, _ in self._fired]
            k = schedule.answered_trigger(fired, t_capture, self.latency_ns)
            if k is None:
                return 0, CAPTURE_FREE
            for _ in range(k):  # older triggers that got no frame
                _, _, capture = self._fired.popleft()
                self.missed += capture != CAPTURE_FREE
            t_fired, t_target, capture = self._fired.popleft()
            self.samples += 1
            self.latency_ns = schedule.learn_latency(self.latency_ns, t_capture - t_fired, self.samples)
            if capture == CAPTURE_LOCKSTEP:
                self.lockstep_frames += 1
                self.residuals.append(t_capture - t_target)
            elif capture == CAPTURE_SCHEDULED:
                self.scheduled += 1
            return t_target, schedule.captured_as(capture, t_capture, t_target, self.tolerance_ns)

    def skipped(self, points: int) -> None:
        """Lockstep grid points the timer gave up (it woke too late for them)."""
        with self._lock:
            self.missed += points

    def figures(self) -> dict[str, int]:
        """What the ring's header shows of it (fxis_shm.shm.ringheader.SYNC_FIELDS)."""
        with self._lock:
            residuals, lateness = list(self.residuals), list(self.lateness)
        hz, phase = self.grid or (0.0, 0)
        return {
            "trigger_latency_ns": self.latency_ns,
            "trigger_samples": self.samples,
            "frames_scheduled": self.scheduled,
            "frames_lockstep": self.lockstep_frames,
            "triggers_missed": self.missed,
            "lockstep_mhz": round(hz * 1000),
            "lockstep_phase_ns": phase,
            "lockstep_clock": schedule.GRID_CLOCKS.index(self.grid_clock),
            "residual_p50_ns": schedule.percentile(residuals, 50) or 0,
            "residual_p99_ns": schedule.percentile(residuals, 99) or 0,
            "timer_late_p50_ns": schedule.percentile(lateness, 50) or 0,
            "timer_late_p99_ns": schedule.percentile(lateness, 99) or 0,
        }

    def reset_lockstep(self, grid: tuple[float, int] | None, clock: str = schedule.GRID_CLOCKS[0]) -> None:
        with self._lock:
            self.residuals.clear()
            self.lockstep_frames = self.missed = 0
            self.grid, self.grid_clock = grid, clock


class TriggerTimer:
    """Fires ``trigger()`` at scheduled moments of the service's clock and on a lockstep grid."""

    def __init__(
        self,
        trigger: Callable[[], None],
        can_trigger: Callable[[], bool],
        triggers: TriggerLog,
        lockstep: tuple[float, int] | None = None,
        on_grid: Callable[[], None] = lambda: None,
        lockstep_clock: str = schedule.GRID_CLOCKS[0],
        on_start: Callable[[], None] = lambda: None,
        clock: timebase.Clock = timebase.REAL,
        threaded: bool = True,
    ):
        """``on_grid``: called when the lockstep grid was set or stopped (the ring says so);
        ``lockstep_clock``: the clock the grid is counted in (schedule.GRID_CLOCKS); ``on_start``:
        called first in the timer's thread (--realtime raises its priority there, before any
        trigger); ``threaded`` False: no thread of its own (its caller fires the triggers, see the
        module's doc)."""
        self._trigger, self._can_trigger, self.log = trigger, can_trigger, triggers
        self.clock = clock
        self._on_grid, self._on_start = on_grid, on_start
        self._due: list[tuple[int, int]] = []  # heap of (t_fire, t_target), service clock
        self._targets: set[int] = set()
        self.lockstep: tuple[float, int] | None = None  # (hz, phase_ns) of grid_clock
        self.grid_clock = lockstep_clock
        self._last_point: int | None = None  # the last lockstep grid point fired for (service clock)
        self._planned: tuple[int, int] | None = None  # the next lockstep (t_fire, t_target)
        self._wake = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True, name="trigger-timer")
        if lockstep is not None:  # the service's --lockstep: fired whenever the camera is triggerable
            self.lockstep = lockstep
            triggers.reset_lockstep(lockstep, lockstep_clock)
        if threaded:
            self._thread.start()

    # ---- the commands (answered in the command thread) ----

    def trigger_at(self, command: dict) -> dict:
        """``{"t": T}``: fire for a capture at T (service clock); answers when it will fire."""
        t_target = command.get("t")
        if not isinstance(t_target, int):
            raise ProtocolError("trigger_at needs an integer t (ns of the service clock)")
        self._check_triggerable()
        refusal = schedule.check_target(t_target, self.clock.now_ns(), self.log.latency_ns)
        if refusal is not None:
            raise ProtocolError(refusal.message, refusal.code)
        t_fire = schedule.fire_time(t_target, self.log.latency_ns)
        with self._wake:
            if t_target not in self._targets:  # two requests for one T share its frame
                self._targets.add(t_target)
                heapq.heappush(self._due, (t_fire, t_target))
                self._wake.notify()
        return {"fire_at": t_fire, "latency_ns": self.log.latency_ns}

    def set_lockstep(self, command: dict) -> dict:
        """``{"hz": HZ, "phase_ns": P, "clock": "realtime" or "tai"}``: fire on the grid from now on
        (the clock defaults to the one the service was started with); ``{"hz": None}``: stop."""
        hz = command.get("hz")
        if hz is None:
            with self._wake:
                self.lockstep = None
                self._wake.notify()
            self.log.reset_lockstep(None)
            self._on_grid()
            return {"lockstep": None}
        if not isinstance(hz, (int, float)) or not isinstance(command.get("phase_ns", 0), int):
            raise ProtocolError("lockstep needs hz (a number) and phase_ns (an integer)")
        try:
            schedule.check_lockstep(float(hz))
            clock = schedule.check_grid_clock(str(command.get("clock", self.grid_clock)))
        except ValueError as exc:
            raise ProtocolError(str(exc)) from None
        self._check_triggerable()
        grid = (float(hz), int(command.get("phase_ns", 0)))
        self.log.reset_lockstep(grid, clock)
        with self._wake:
            self.lockstep, self.grid_clock, self._last_point, self._planned = grid, clock, None, None
            self._wake.notify()
        self._on_grid()
        return {"lockstep": {"hz": float(hz), "phase_ns": grid[1], "clock": clock}}

    def _check_triggerable(self) -> None:
        if not self._can_trigger():
            raise ProtocolError(
                "the camera is free-running (trigger=free): it cannot be triggered for a moment", Code.BAD_REQUEST
            )

    # ---- the thread ----

    def _next(self) -> tuple[int, int, int] | None:
        """(t_fire in the service clock, t_target, capture) of the next trigger due, or None."""
        nxt = None
        if self._due:
            t_fire, t_target = self._due[0]
            nxt = (t_fire, t_target, CAPTURE_SCHEDULED)
        if self.lockstep is not None:
            t_fire, t_target = self._grid_point(self.lockstep)
            if nxt is None or t_fire < nxt[0]:
                nxt = (t_fire, t_target, CAPTURE_LOCKSTEP)
        return nxt

    def _grid_point(self, grid: tuple[float, int]) -> tuple[int, int]:
        """(t_fire, t_target) of the lockstep point planned next, in the service's clock. Chosen
        once: a timer that wakes late fires late (its lateness shows), and only a point whose
        moment is half a period gone is given up (a frame missed)."""
        hz, phase = grid
        now = self.clock.now_ns()
        if self._planned is not None and now - self._planned[0] < 5e8 / hz:
            return self._planned
        # the first point whose trigger is still ahead
        offset = _grid_offset(self.clock, self.grid_clock)
        t_target = schedule.grid_target(now, offset, hz, phase, self.log.latency_ns + _MARGIN_NS)
        self._planned = (schedule.fire_time(t_target, self.log.latency_ns), t_target)
        return self._planned

    def _run(self) -> None:
        self._on_start()
        while True:
            with self._wake:
                if self._stop:
                    return
                nxt = self._next()
                wait_ns = _IDLE_S * 1e9 if nxt is None else nxt[0] - _SPIN_NS - self.clock.now_ns()
                if wait_ns > 0:
                    self._wake.wait(min(wait_ns / 1e9, _IDLE_S))
                    continue  # look again: a command may have come meanwhile
            while self.clock.now_ns() < nxt[0]:  # the last 2 ms: spin
                pass
            self._fire_planned(nxt)

    def next_fire(self) -> int | None:
        """When the next trigger is due (service clock), None if none is planned."""
        with self._wake:
            nxt = self._next()
        return None if nxt is None else nxt[0]

    def fire_next(self) -> None:
        """Fire the next trigger now (at or after ``next_fire``; the lateness is counted)."""
        with self._wake:
            nxt = self._next()
        if nxt is not None:
            self._fire_planned(nxt)

    def _fire_planned(self, nxt: tuple[int, int, int]) -> None:
        t_fire, t_target, capture = nxt
        with self._wake:
            if capture == CAPTURE_SCHEDULED:
                heapq.heappop(self._due)
                self._targets.discard(t_target)
            elif self.lockstep is None:
                return  # stopped meanwhile
            else:
                self._planned = None
        self._fire(t_target, capture, self.clock.now_ns() - t_fire)

    def _fire(self, t_target: int, capture: int, late_ns: int) -> None:
        if not self._can_trigger():
            return
        if capture == CAPTURE_LOCKSTEP and self.lockstep is not None:
            if self._last_point is not None:  # grid points passed unfired (the thread was held up)
                skipped = round((t_target - self._last_point) * self.lockstep[0] / 1e9) - 1
                self.log.skipped(max(0, skipped))
            self._last_point = t_target
        self.log.fired(self.clock.now_ns(), t_target, capture, late_ns)
        try:
            self._trigger()
        except Exception:
            log.exception("the trigger for %d failed", t_target)

    def close(self) -> None:
        with self._wake:
            self._stop = True
            self._wake.notify()
        if self._thread.is_alive():
            self._thread.join(1.0)


def _grid_offset(clock: timebase.Clock, grid_clock: str, tries: int = 3, good_ns: int = 20_000) -> int:
    """The grid's clock minus the service's clock, from the read whose two service-clock reads
    around the grid clock's one were nearest: a thread preempted between them would move every
    grid point by the preemption."""
    best: tuple[int, int] | None = None
    for _ in range(tries):
        before = clock.now_ns()
        grid_now = clock.read(grid_clock)
        after = clock.now_ns()
        if best is None or after - before < best[0]:
            best = (after - before, grid_now - (before + after) // 2)
        if after - before <= good_ns:
            break
    return best[1]
