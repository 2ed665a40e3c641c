"""The camera worker process: one camera, one ring. It owns the ring's writer
side and stores every frame the camera delivers (after the camera's processing
hook, if it has one); it never waits for readers. Between two frames it applies
the coordinator's commands (workers/commands.py, workers/tuning.py)."""

from __future__ import annotations

import functools
import logging
import threading
import time

import posix_ipc

from fxis_shm.core import timebase
from fxis_shm.errors import RingError
from fxis_shm.service import realtime, rtpolicy
from fxis_shm.service.childspec import CameraWorkerSpec
from fxis_shm.shm import history, naming
from fxis_shm.shm.ring import FrameLayout, RingWriter, segment_size
from fxis_shm.shm.ringheader import FLAG_TRIGGERED
from fxis_shm.wire import commands

from . import processing, tuning
from ._child import Ready, child_main
from .backends import backend_class
from .backends.base import Camera, CameraLost
from .commands import CommandServer, serve_pending
from .triggers import TriggerLog, TriggerTimer

log = logging.getLogger("camera")
_GRAB_TIMEOUT_S = 0.1  # also the heartbeat interval while no frames come
_RESULT_POLL_S = 0.005  # how often results of processing processes are collected
_FIRST_FRAME_TIMEOUT_S = 10.0
_RECONNECT_FIRST_S, _RECONNECT_MAX_S = 0.5, 10.0


class Stream:
    """What the capture loop holds: the camera, its processing, its ring, and the command
    server. A change of size or pixel format replaces the camera and the ring (``restart``)."""

    def __init__(self, spec: CameraWorkerSpec, stop: threading.Event):
        self.spec, self.stop = spec, stop
        # changes made while the service runs, if this worker restarts after a crash
        self.kept, self.named = tuning.remembered(spec)  # named: features set by name, set again after restarts
        self.camera = backend_class(spec.kind)(spec.camera, {**spec.options, **self.kept}, spec.time_origin_ns)
        self.process = processing.pipeline(self.camera.options)
        self.ring: RingWriter | None = None
        self.commands: CommandServer | None = None
        self.first: processing.Processed | None = None  # the first frame to store, if finding the layout took one
        # triggers for a moment (capture at T, lockstep), fired by a timer thread of their own
        self.triggers = TriggerLog(_tolerance_ns(self.camera))
        self.timer: TriggerTimer | None = None

    def start(self) -> None:
        try:
            self.camera.open()
            if self.named:
                self.camera.set_live(self.named)
        except Exception as exc:
            if not (self.kept or self.named):
                raise
            log.warning(
                "camera %s: the settings changed at run time fail (%s); back to its configured ones",
                self.spec.camera,
                exc,
            )
            tuning.forget(self.spec)
            self.camera.close()
            self.kept, self.named = {}, {}
            spec = self.spec
            self.camera = backend_class(spec.kind)(spec.camera, spec.options, spec.time_origin_ns)
            self.camera.open()
        if self.kept or self.named:
            log.info(
                "camera %s: with the settings changed at run time %s", self.spec.camera, {**self.kept, **self.named}
            )
        self.first, layout, hook_errors = _layout(self.camera, self.process, self.stop)
        spec = self.spec
        lockstep = None if spec.lockstep_hz is None else (spec.lockstep_hz, spec.lockstep_phase_ns)
        self.timer = TriggerTimer(
            lambda: self.camera.trigger(),
            lambda: self.camera.supports_trigger,
            self.triggers,
            lockstep,
            self.timed,
            spec.lockstep_clock,
            functools.partial(realtime.raise_this_thread, rtpolicy.TIMER, spec.realtime),
        )
        direct = {commands.TRIGGER_AT: self.timer.trigger_at, commands.LOCKSTEP: self.timer.set_lockstep}
        # before the ring: a coordinator that sees the ring's new generation finds the commands
        self.commands = CommandServer(self.spec.service, self.spec.camera, threading.Event(), direct)
        self.ring = self._ring(layout)
        self.ring.count("hook_errors", hook_errors)
        self.timed()

    @property
    def writer(self) -> RingWriter:
        """The ring ``start`` made (RingError before it has)."""
        if self.ring is None:
            raise RingError(f"camera {self.spec.camera}: the stream has no ring before it starts")
        return self.ring

    def _ring(self, layout: FrameLayout) -> RingWriter:
        spec, period = self.spec, self.camera.nominal_period_ns
        slots = history.slots_for(spec.history_s, period, spec.slots)
        ring = RingWriter(spec.service, spec.camera, layout, slots, period)
        log.info(
            "camera %s (%s) streaming %s into %s (%d slots, %s), generation %d",
            spec.camera,
            spec.kind,
            layout,
            ring.name,
            slots,
            history.mib(segment_size(layout, slots)[0]),
            ring.generation,
        )
        return ring

    def restart(self, options: dict[str, object]) -> None:
        """The stream again with ``options``: a new camera object, a new ring if the layout or
        the slots differ (readers re-open it by name), the generation + 1 either way. If the
        new camera fails, the old one is opened again as it was and the failure raised."""
        old = self.camera
        old.close()
        try:
            camera = backend_class(self.spec.kind)(self.spec.camera, options, self.spec.time_origin_ns)
            camera.open()
        except Exception:
            old.open()
            raise
        try:
            first, layout, _ = _layout(camera, self.process, self.stop)
        except Exception:
            camera.close()
            old.open()
            raise
        self.camera, self.first = camera, first
        self.triggers.tolerance_ns = _tolerance_ns(camera)
        ring = self.ring
        assert ring is not None
        slots = history.slots_for(self.spec.history_s, camera.nominal_period_ns, self.spec.slots)
        if layout == ring.layout and slots == ring.slots:
            ring.new_generation()
            ring.set_period(camera.nominal_period_ns)
        else:  # the new writer retires the old segment; the old writer's mapping is then closed
            new = self.ring = self._ring(layout)
            for counter in ("frames_captured", "frames_dropped", "hook_errors"):
                new.count(counter, ring.field(counter) - new.field(counter))
            ring.close()
        self.timed()  # read by the next request
        log.info("camera %s restarted its stream (generation %d)", self.spec.camera, self.writer.generation)

    def timed(self) -> None:
        """Tell readers how the camera's frames come: on triggers of the requests (FLAG_TRIGGERED),
        or on their own, free-running or on the lockstep grid (whose period the ring then shows)."""
        ring, lockstep = self.ring, self.timer.lockstep if self.timer is not None else None
        if ring is None:
            return
        triggered = self.camera.supports_trigger
        ring.set_flags(FLAG_TRIGGERED if triggered and lockstep is None else 0)
        if triggered:
            ring.set_period(0 if lockstep is None else round(1e9 / lockstep[0]))

    def close(self) -> None:
        if self.commands is not None:
            self.commands.close()
        if self.timer is not None:
            self.timer.close()
        if self.ring is not None:
            self.ring.close()
        self.process.close()
        self.camera.close()


def _tolerance_ns(camera: Camera) -> int:
    """How far from T a frame captured for T may land before it is marked late."""
    tolerance_ms: float = camera.options["capture_tolerance_ms"]
    return round(tolerance_ms * 1e6)


def run(spec: CameraWorkerSpec, ready: Ready, stop: threading.Event) -> None:
    stream = Stream(spec, stop)
    try:
        stream.start()
        triggers = _TriggerListener(spec.service, stream, stop)  # also for a camera set to trigger=software later
        if spec.realtime is not None:
            _realtime(stream)
            why = realtime.lock_memory()
            if why:
                log.warning("camera %s: --realtime: %s", spec.camera, why)
        ready.ok()
        try:
            _stream(stream)
        finally:
            if triggers:
                triggers.close()
    finally:
        stream.close()


def _layout(
    camera: Camera, process: processing.Direct | processing.Pool, stop: threading.Event
) -> tuple[processing.Processed | None, FrameLayout, int]:
    """The ring's layout: the camera's, or that of the first frame its hook returns
    (frames the hook fails on are counted and skipped, as later ones are).
    Returns (the first frame to store or None, the layout, hook errors so far)."""
    if process.hook is None and camera.layout is not None:
        return None, camera.layout, 0
    deadline = time.monotonic() + _FIRST_FRAME_TIMEOUT_S
    errors, last_error = 0, "no frame"
    while not stop.is_set() and time.monotonic() < deadline:
        capture = camera.grab(_GRAB_TIMEOUT_S)
        if capture is None:
            continue
        t_available = timebase.now()
        image, error = (
            (capture.image, None) if process.hook is None else processing.run_hook(process.hook, capture.image)
        )
        if error:
            errors, last_error = errors + 1, f"the process hook failed: {error}"
            continue
        if image is not None:
            first = processing.Processed(image, capture.frame_id, capture.t_capture, t_available)
            return first, FrameLayout.of(image), errors
    raise TimeoutError(
        f"camera {camera.name!r} gave no frame to store in {_FIRST_FRAME_TIMEOUT_S:.0f} s ({last_error})"
    )


def _stream(stream: Stream) -> None:
    stop, generation = stream.stop, -1
    while not stop.is_set():
        if stream.writer.generation != generation:  # started, or restarted by a command
            camera, process, ring = stream.camera, stream.process, stream.writer
            generation = ring.generation
            dropped, note = camera.frames_dropped, ""
            _realtime(stream)  # the new camera's own threads too
            if stream.first is not None:
                _store(stream, stream.first)
                stream.first = None
        try:
            capture = camera.grab(_RESULT_POLL_S if process.in_flight else _GRAB_TIMEOUT_S)
        except CameraLost as exc:
            _reconnect(camera, ring, stop, str(exc))
            _realtime(stream)  # the reopened camera's own threads
            generation = ring.generation  # the same camera and ring, a new generation
            dropped, note = camera.frames_dropped, ""  # _reconnect cleared the status
            continue
        if capture is None:
            ring.heartbeat()
        else:
            ring.count("frames_captured")
            if not process.submit(capture, timebase.now()):
                ring.count("frames_dropped")  # every processing process is busy
        for item in process.ready():
            _store(stream, item)
        if camera.frames_dropped != dropped:
            ring.count("frames_dropped", camera.frames_dropped - dropped)
            dropped = camera.frames_dropped
        if camera.note != note:  # what the camera says about itself ("end of file", ...)
            note = camera.note
            ring.set_status(note)
        serve_pending(stream.commands, lambda command: tuning.handle(stream, command.body))


def _realtime(stream: Stream) -> None:
    """The worker's threads at SCHED_FIFO by their roles (--realtime; service.rtpolicy)."""
    priority = stream.spec.realtime
    if priority is None:
        return
    options = stream.camera.options
    inline = bool(options.get("process")) and (options.get("process_workers") or 1) == 1

    def role(name: str | None, comm: str) -> str:
        return rtpolicy.camera_thread_role(name, comm, inline)

    for line in realtime.raise_threads(role, priority):
        log.warning("camera %s: --realtime: %s", stream.spec.camera, line)


def _reconnect(camera: Camera, ring: RingWriter, stop: threading.Event, reason: str) -> None:
    """Reopen a lost camera with backoff, heartbeating meanwhile so the service
    knows the worker lives; the frames after the outage get a new generation."""
    backoff = _RECONNECT_FIRST_S
    log.warning("camera %s lost: %s", camera.name, reason)
    while not stop.is_set():
        ring.set_status(f"camera lost ({reason}); retrying every {backoff:.1f} s")
        try:
            camera.close()
        except Exception:
            log.debug("closing the lost camera failed", exc_info=True)
        _sleep_heartbeating(ring, stop, backoff)
        try:
            camera.open()
        except Exception as exc:
            reason = f"{type(exc).__name__}: {exc}"
            backoff = min(backoff * 2, _RECONNECT_MAX_S)
            continue
        generation = ring.new_generation()
        ring.set_status("")
        log.info("camera %s is back (generation %d)", camera.name, generation)
        return


def _sleep_heartbeating(ring: RingWriter, stop: threading.Event, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not stop.is_set() and time.monotonic() < deadline:
        ring.heartbeat()
        stop.wait(min(_GRAB_TIMEOUT_S, max(0.0, deadline - time.monotonic())))


def _store(stream: Stream, item: processing.Processed) -> None:
    ring = stream.writer
    if item.error is None and item.image is not None and FrameLayout.of(item.image) != ring.layout:
        item.error = f"returned {FrameLayout.of(item.image)}, but the ring holds {ring.layout}"
    if item.error is not None:
        ring.count("hook_errors")
        ring.set_status(f"process hook: {item.error}")
        log.warning("frame %d not stored: process hook %s", item.frame_id, item.error)
    elif item.image is not None:  # None: the hook skipped the frame
        t_target, capture = stream.triggers.answer(item.t_capture) if stream.camera.supports_trigger else (0, 0)
        ring.write(item.image, item.frame_id, item.t_capture, item.t_available, t_target, capture)
        if stream.camera.supports_trigger:
            ring.set_sync(stream.triggers.figures())


class _TriggerListener:
    """Fires the camera's software trigger each time the coordinator posts its semaphore (the
    stream's camera of the moment: a restart of the stream replaces it)."""

    def __init__(self, service: str, stream: Stream, stop: threading.Event):
        self._sem = posix_ipc.Semaphore(
            naming.trigger_name(service, stream.spec.camera), posix_ipc.O_CREAT, mode=0o600, initial_value=0
        )
        self._stop = stop
        self._thread = threading.Thread(target=self._listen, args=(stream,), daemon=True, name="trigger")
        self._thread.start()

    def _listen(self, stream: Stream) -> None:
        while not self._stop.is_set():
            try:
                self._sem.acquire(0.2)
            except posix_ipc.BusyError:
                continue
            try:
                if stream.camera.supports_trigger:  # (a post racing a change to trigger=free)
                    stream.triggers.fired(timebase.now())  # for "now": its frame is free
                    stream.camera.trigger()
            except Exception:
                log.exception("software trigger of camera %r failed", stream.spec.camera)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self._sem.close()


def main() -> None:
    """``python -m fxis_shm.workers.camera '<json spec>' READY_FD``, or a fork of the supervisor."""
    child_main(CameraWorkerSpec, run)


if __name__ == "__main__":
    main()
