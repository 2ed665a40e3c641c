"""The coordinator's view of one camera: its ring (opened, and re-opened when
the worker replaces it), whether its worker is alive, and its status."""

from __future__ import annotations

import posix_ipc

from fxis_shm.core import timebase
from fxis_shm.core.schedule import GRID_CLOCKS
from fxis_shm.core.snapshot import Snapshot
from fxis_shm.core.waitpolicy import CameraState
from fxis_shm.errors import RingError
from fxis_shm.shm import naming, procstat
from fxis_shm.shm.history import held_seconds
from fxis_shm.shm.ring import RingReader
from fxis_shm.shm.ringheader import FLAG_TRIGGERED, STATE_RETIRED, SYNC_FIELDS

# The columns of the ``frames`` op's rows, one row per frame.
FRAME_FIELDS = ("frame_id", "t_capture", "t_stored", "t_available", "generation")
# A worker heartbeats at least every 0.1 s; silence this long means it hangs.
STALE_HEARTBEAT_NS = 2_000_000_000
# How long a look at /proc that found the worker running stays good: requests
# need not pay a file read each, and a death is still seen within this time.
ALIVE_CHECK_NS = 20_000_000


def process_alive(pid: int) -> bool:
    """True if ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    stat = procstat.read(pid) if pid > 0 else None
    return stat is not None and stat.running


RATE_WINDOW_NS = 5_000_000_000  # the measured rate: frames stored over the last 5 s


def measured_rate(snap: Snapshot, now: int) -> dict[str, float | None]:
    """``measured_fps``: the frames the ring holds that were captured in the last
    ``measured_over_s`` seconds, per second; 5 s, or as far back as the ring reaches. A
    camera that drops frames or stalls shows it here, whatever its set rate."""
    n = len(snap.timeline)
    window = min(RATE_WINDOW_NS, now - snap.timeline.at(0)) if n else RATE_WINDOW_NS
    if window <= 0:
        return {"measured_fps": None, "measured_over_s": 0.0}
    count = n - snap.timeline.bisect_right(now - window)
    return {"measured_fps": round(count * 1e9 / window, 2), "measured_over_s": round(window / 1e9, 2)}


class CameraHandle:
    def __init__(self, service: str, name: str, kind: str, history_s: float | None = None):
        self.service, self.name, self.kind = service, name, kind
        self.history_s = history_s  # the seconds asked for (history=), None: sized in slots
        self.reader: RingReader | None = None
        self.torn_reads = 0
        self.last_error = ""
        self._trigger: posix_ipc.Semaphore | None = None
        self._seen_alive = (0, 0, 0)  # (pid, when, write count) of the last look that found it running

    def ring(self) -> RingReader | None:
        """The ring, opened or re-opened if the worker created a new one; None if absent."""
        if self.reader is not None and self.reader.retired:
            self.reader.close()
            self.reader = None
        if self.reader is None:
            try:
                self.reader = RingReader(self.service, self.name, with_semaphore=False)
            except RingError as exc:
                self.last_error = str(exc)
                return None
        return self.reader

    def down_reason(self, now: int) -> str | None:
        """Why the camera cannot serve now, or None if its worker is alive."""
        ring = self.reader
        look = ring.liveness() if ring is not None else None
        if look is None or look[0] == STATE_RETIRED:  # (re)open it
            ring = self.ring()
            if ring is None:
                return f"camera {self.name!r} has no ring: {self.last_error}"
            look = ring.liveness()
        _, pid, write_count, heartbeat_ns = look
        if not self._alive(pid, write_count):
            return f"camera {self.name!r} is down: its worker is not running"
        if now - heartbeat_ns > STALE_HEARTBEAT_NS:
            return f"camera {self.name!r} is down: its worker has not reported for over 2 s"
        return None

    def _alive(self, pid: int, write_count: int) -> bool:
        checked = timebase.now()
        seen_pid, seen_at, seen_count = self._seen_alive
        if pid == seen_pid and (checked - seen_at < ALIVE_CHECK_NS or write_count != seen_count):
            # a frame stored since the last look is as good a sign of life as /proc
            self._seen_alive = (pid, checked if write_count != seen_count else seen_at, write_count)
            return True
        alive = process_alive(pid)
        self._seen_alive = (pid, checked, write_count) if alive else (0, 0, 0)
        return alive

    @property
    def triggered(self) -> bool:
        """True if the camera captures on software triggers rather than free-running (the ring
        opened if it was not: a capture at T may be the first request the coordinator reads)."""
        ring = self.ring()
        return ring is not None and bool(ring.field("flags") & FLAG_TRIGGERED)

    # ---- what the request engine reads (fxis_shm.core.engine.CameraSource) ----

    def snapshot(self) -> Snapshot:
        """The ring's frames now (call after ``down_reason`` found the ring there)."""
        return self.ring_open().snapshot()

    def ring_open(self) -> RingReader:
        """The ring ``down_reason`` or ``ring`` opened (RingError if none was)."""
        if self.reader is None:
            raise RingError(f"camera {self.name!r} has no ring open: ask down_reason first")
        return self.reader

    @property
    def period_ns(self) -> int:
        return self.reader.field("period_ns") if self.reader is not None else 0

    @property
    def slots(self) -> int | None:
        ring = self.ring()
        return ring.slots if ring is not None else None

    def fire_trigger(self) -> None:
        """Ask the camera's worker to trigger one capture now."""
        if self._trigger is None:
            self._trigger = posix_ipc.Semaphore(naming.trigger_name(self.service, self.name))
        self._trigger.release()

    def state(self, snapshot: Snapshot) -> CameraState:
        period_ns, delay_ns = self.ring_open().timing()
        return CameraState(
            newest=snapshot.newest,
            period_ns=period_ns,
            delay_ns=max(0, delay_ns),
            newest_stored=snapshot.newest_stored,
            triggered=self.triggered,
        )

    def status(self, now: int) -> dict[str, object]:
        ring = self.ring()
        down = self.down_reason(now)
        info: dict[str, object] = {"kind": self.kind, "alive": down is None, "torn_reads": self.torn_reads}
        if down:
            info["reason"] = down
        if ring is None:
            return info
        snap = ring.snapshot()
        period = ring.field("period_ns")
        triggered = self.triggered
        # a triggered camera's measured period is only the spacing of the triggers so far: its set
        # rate is the nominal one, if any (the coordinator adds the configured one)
        set_period = ring.field("nominal_period_ns") if triggered else period
        newest_stored = snap.newest_stored
        held = held_seconds(ring.slots, period)
        note = ring.header["status_text"].item().decode(errors="replace")
        if self.history_s and held is not None and held < self.history_s * 0.98:
            # the ring was sized at the camera's nominal rate; it runs faster now
            short = f"holds {held:.2f} s of the {self.history_s:g} s asked: the camera runs faster than its ring's size"
            note = f"{note}; {short}" if note else short
        info.update(
            shape=list(ring.layout.shape),
            dtype=ring.layout.dtype,
            fps=round(1e9 / set_period, 3) if set_period > 0 else None,  # the camera's set rate
            **measured_rate(snap, now),
            frames_stored=ring.field("write_count"),
            frames_dropped=ring.field("frames_dropped"),
            # a frame stored after ``now`` was read (between it and the snapshot) is 0 ms old, not negative
            last_frame_age_ms=round(max(0, now - newest_stored) / 1e6, 3) if newest_stored else None,
            ring_slots=ring.slots,
            history_s=held,
            ring=ring.name,
            instance=str(ring.instance),  # uint64: a decimal string on the wire (docs/protocol.md)
            generation=ring.field("generation"),
            writer_pid=ring.field("writer_pid"),
            delay_ms=round(ring.field("delay_ns") / 1e6, 3),
            trigger="software" if triggered else "free",
            hook_errors=ring.field("hook_errors"),
            note=note,
            sync=sync_status(ring),
        )
        return info

    def timeline(self, now: int) -> dict[str, object]:
        """What a caller elsewhere needs to choose frames itself (the ``frames`` op): the
        camera's liveness, timing and every valid frame's identity and times, oldest first."""
        down = self.down_reason(now)
        info: dict[str, object] = {"alive": down is None, "reason": down, "frames": []}
        if self.reader is None:
            return info
        snap = self.reader.snapshot()
        rows = [snap.frame_meta(i) for i in range(len(snap.timeline))]
        info.update(
            period_ns=self.period_ns,
            delay_ns=max(0, self.reader.field("delay_ns")),
            slots=self.reader.slots,
            triggered=self.triggered,
            frames=[[int(getattr(row, k)) for k in FRAME_FIELDS] for row in rows],
        )
        return info

    def close(self) -> None:
        if self._trigger is not None:
            self._trigger.close()
            self._trigger = None
        if self.reader is not None:
            self.reader.close()
            self.reader = None


def sync_status(ring: RingReader) -> dict[str, object]:
    """How the camera was triggered for moments (docs/sync.md): its learned trigger latency, the
    frames captured for a trigger_at and on the lockstep grid, the triggers that got no frame, and
    the grid with the residuals t_capture - grid point (None while there is no grid)."""
    f = {name: ring.field(name) for name in SYNC_FIELDS}
    lockstep: dict[str, object] | None = None
    if f["lockstep_mhz"]:
        lockstep = {
            "hz": f["lockstep_mhz"] / 1000,
            "phase_ms": f["lockstep_phase_ns"] / 1e6,
            "clock": timebase.WIRE_NAMES[GRID_CLOCKS[f["lockstep_clock"]]],
            "frames": f["frames_lockstep"],
            "residual_p50_ms": round(f["residual_p50_ns"] / 1e6, 4),
            "residual_p99_ms": round(f["residual_p99_ns"] / 1e6, 4),
        }
    return {
        "trigger_latency_ms": round(f["trigger_latency_ns"] / 1e6, 4),
        "latency_samples": f["trigger_samples"],
        "frames_scheduled": f["frames_scheduled"],
        "triggers_missed": f["triggers_missed"],
        "timer_late_p50_ms": round(f["timer_late_p50_ns"] / 1e6, 4),
        "timer_late_p99_ms": round(f["timer_late_p99_ns"] / 1e6, 4),
        "lockstep": lockstep,
    }
