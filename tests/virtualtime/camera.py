"""One camera of a virtual-time cell: the real SyntheticCamera (its frame schedule, its driver's
buffers, its software trigger), the real trigger timer's schedule (TriggerTimer without its
thread) and log, and a real ring written as the camera worker writes it, all on the cell's
virtual clock. What goes wrong is scripted (``Script``): when the worker stores a frame, which
frames are lost, when the worker stalls, how late the trigger timer wakes."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from fxis_shm.service.camerakinds import camera_options
from fxis_shm.shm.ring import RingWriter
from fxis_shm.shm.ringheader import FLAG_TRIGGERED
from fxis_shm.workers.backends.synthetic import SyntheticCamera
from fxis_shm.workers.triggers import TriggerLog, TriggerTimer

MS = 1_000_000


@dataclass(frozen=True)
class Script:
    """What happens to one camera's frames and triggers, exactly."""

    store_ns: int = MS // 2  # capture -> stored, for every frame the worker is not held up for
    stored_late: Mapping[int, int] = field(default_factory=dict)  # frame id -> stored this long after capture
    dropped: Collection[int] = ()  # frame ids lost before they are stored (the worker counts them)
    stalls: Sequence[tuple[int, int]] = ()  # (from, until): the worker neither grabs nor stores
    timer_late: Callable[[int], int] = lambda wake: 0  # how late the trigger timer's n-th wake-up is

    def stalled_until(self, t: int) -> int:
        """``t``, or the end of the stall ``t`` falls in."""
        for start, end in self.stalls:
            if start <= t < end:
                return end
        return t


class VirtualCamera:
    def __init__(
        self,
        service: str,
        name: str,
        options: Mapping,
        script: Script,
        clock,
        origin_ns: int,
        slots: int,
        lockstep: tuple[float, int] | None = None,
    ):
        self.name, self.script, self.clock = name, script, clock
        self.camera = SyntheticCamera(name, camera_options(name, "synthetic", dict(options)), origin_ns, clock=clock)
        self.camera.open()
        self.triggered = self.camera.supports_trigger
        self.ring = RingWriter(service, name, self.camera.layout, slots, self.camera.nominal_period_ns, clock=clock)
        self.log = TriggerLog()
        self.timer: TriggerTimer | None = None
        if self.triggered:
            trigger = self.camera.trigger
            self.timer = TriggerTimer(trigger, lambda: True, self.log, lockstep, clock=clock, threaded=False)
            # as the worker says how its frames come (workers/camera.py, Stream.timed)
            self.ring.set_flags(FLAG_TRIGGERED if lockstep is None else 0)
            self.ring.set_period(0 if lockstep is None else round(1e9 / lockstep[0]))
        self._latency_ns = round(self.camera.options["trigger_latency_ms"] * MS)
        self._exposures: deque[int] = deque()  # when the frames of the triggers fired are exposed
        self._captured: deque[tuple[int, np.ndarray, int, int]] = deque()  # (ready, image, id, t_capture)
        self._wake: int | None = None  # when the trigger timer wakes next (its lateness added)
        self.wakes = 0  # the trigger timer's wake-ups so far
        self._dropped_seen = 0

    # ---- the cell's scheduler asks ----

    def next_time(self) -> int | None:
        """The next moment something happens to this camera."""
        times = [self._timer_wake(), self._next_grab()]
        if self._captured:
            times.append(self._captured[0][0])
        due = [t for t in times if t is not None]
        return self.script.stalled_until(min(due)) if due else None

    def step(self, now: int) -> bool:
        """Do what is due at ``now``; True if frames were stored."""
        if self.script.stalled_until(now) != now:
            return False
        if self._timer_wake() is not None and self._wake <= now:
            self._wake_timer(now)
        while (t := self._next_grab()) is not None and t <= now:
            self._grab()
        stored = False
        while self._captured and self._captured[0][0] <= now:
            stored = self._store(*self._captured.popleft()[1:]) or stored
        return stored

    def trigger_at(self, t: int) -> None:
        """A capture at ``t`` (the coordinator's TRIGGER_AT command); the timer plans again, as
        the command's notify makes its thread."""
        self.timer.trigger_at({"t": t})
        self._wake = None

    def trigger_now(self) -> None:
        """A request's software trigger (the worker's trigger listener)."""
        self.log.fired(self.clock.now_ns())
        self.camera.trigger()
        self._exposures.append(self.clock.now_ns() + self._latency_ns)

    # ---- the worker ----

    def _timer_wake(self) -> int | None:
        if self.timer is None:
            return None
        if self._wake is None:
            planned = self.timer.next_fire()
            if planned is not None:
                self._wake = planned + self.script.timer_late(self.wakes)
        return self._wake

    def _wake_timer(self, now: int) -> None:
        """The timer's thread woke: it fires what is due, or plans again (a lockstep point whose
        moment is half a period gone is given up)."""
        self.wakes += 1
        self._wake = None
        planned = self.timer.next_fire()
        if planned is not None and planned <= now:
            self.timer.fire_next()
            self._exposures.append(now + self._latency_ns)

    def _next_grab(self) -> int | None:
        if self.triggered:
            return self._exposures[0] if self._exposures else None
        return self.camera.next_due()

    def _grab(self) -> None:
        if self.triggered:
            self._exposures.popleft()
        capture = self.camera.grab(0.0)
        dropped = self.camera.frames_dropped - self._dropped_seen  # lost out of its driver's buffers
        if dropped:
            self.ring.count("frames_dropped", dropped)
            self._dropped_seen += dropped
        assert capture is not None, f"camera {self.name!r} had no frame due"
        ready = capture.t_capture + self.script.stored_late.get(capture.frame_id, self.script.store_ns)
        ready = max(ready, self._captured[-1][0]) if self._captured else ready  # stored in order
        self._captured.append((ready, capture.image.copy(), capture.frame_id, capture.t_capture))

    def _store(self, image: np.ndarray, frame_id: int, t_capture: int) -> bool:
        if frame_id in self.script.dropped:
            self.ring.count("frames_dropped")
            return False
        t_target, capture = self.log.answer(t_capture) if self.triggered else (0, 0)
        self.ring.write(image, frame_id, t_capture, t_target=t_target, capture=capture)
        if self.triggered:
            self.ring.set_sync(self.log.figures())
        return True

    def close(self) -> None:
        if self.timer is not None:
            self.timer.close()
        self.ring.close()
