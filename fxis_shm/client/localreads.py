"""Same-host reads without a round trip: a client that answers frame requests itself.

On the service's host (the same kernel and time namespace, so the same
CLOCK_MONOTONIC; the rings readable; each ring the very segment the service
reports) the client runs the service's own request engine (fxis_shm.core.engine) over
read-only mappings of the rings: the same selection and wait policy, and no
message to the coordinator. It copies the chosen frames under the seqlock, or
hands out read-only views of the slots.

Waiting for a frame that is not stored yet costs no CPU until just before it is
due: the client sleeps until the camera's next frame is expected (its newest
frame's capture time plus its period, plus the usual delay to storage, all in the
ring) less a margin, then watches the rings' write counters. Any number of readers can wait this way; a
reader leaves nothing behind in the ring, and the writer never knows it exists.

What only the coordinator can do (software triggers) still goes to it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, cast

from fxis_shm.client.fastreads import FastReads
from fxis_shm.client.frames import Answer, Images
from fxis_shm.core import timebase
from fxis_shm.core.engine import Action, Failure, Reply, RequestEngine
from fxis_shm.core.snapshot import CAPTURES
from fxis_shm.errors import Overwritten, RequestTimeout, service_error
from fxis_shm.shm import fastpick, slotio
from fxis_shm.shm.bufferpool import BufferPool
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.localpath import LocalUnavailable, boot_id, time_namespace
from fxis_shm.shm.ring import RingReader
from fxis_shm.shm.slotio import CopyJob
from fxis_shm.wire import protocol
from fxis_shm.wire.headers import FrameMeta, ReplyHeader

WAKE_MARGIN_NS = 1_500_000  # stop sleeping this long before a frame is due
POLL_S = 0.0001  # then look at the write counters this often
_DELAY_FRAMES = 4  # the newest frames whose least capture-to-storage delay says when the next is stored
_TIMES = ("at", "t_call")  # checked on every call; the other fields once per form of request
_UNCHECKED = (*_TIMES, "encoding", "quality")  # encoding, quality: the frames stay raw here
_REQUEST_FORMS = 256  # validated forms kept


def same_clock(status: dict[str, Any], our_boot_id: str | None = None) -> str | None:
    """Why this process cannot read the service's clock as its own (None: it can)."""
    ours = boot_id() if our_boot_id is None else our_boot_id
    if status.get("boot_id") is None or status.get("boot_id") != ours:
        return "the service runs on another kernel"
    if timebase.of_status(status) != "monotonic":
        return None  # time namespaces set CLOCK_MONOTONIC (and BOOTTIME) apart, not REALTIME or TAI
    namespace = time_namespace()
    if namespace is None or status.get("time_namespace") != namespace:
        return "the service runs in another time namespace (its CLOCK_MONOTONIC is not ours)"
    return None


class LocalReads:
    """The service's rings as this client maps them, and the engine that answers from them."""

    def __init__(self, status: dict[str, Any], our_boot_id: str | None = None, max_pooled_bytes: int = 128 << 20):
        reason = same_clock(status, our_boot_id)
        if reason:
            raise LocalUnavailable(reason)
        self.cameras: dict[str, CameraHandle] = {}
        try:
            for name, info in status["cameras"].items():
                self.cameras[name] = handle = CameraHandle(status["service"], name, info["kind"])
                ring = handle.ring()
                if ring is None:
                    raise LocalUnavailable(handle.last_error)
                if info.get("instance") is not None and ring.instance != int(info["instance"]):
                    raise LocalUnavailable(
                        f"{ring.name} here is not the service's ring (another IPC namespace, or the ring was replaced)"
                    )
        except BaseException:
            self.close()
            raise
        self.clock = timebase.of_status(status)  # the service's clock
        self.now = timebase.reader(self.clock)
        self.wire_clock = timebase.WIRE_NAMES[self.clock]
        self.engine = RequestEngine(self.cameras, status.get("settings"))
        self.buffers = BufferPool(max_pooled_bytes)
        # validated requests by form (protocol.request_of)
        self._requests: dict[tuple[object, ...], protocol.Request] = {}
        self.torn = 0  # copies found torn (and made again)

    def fast_reads(self) -> FastReads | None:
        """The compiled read of these rings (None: not built, or a ring is not open now)."""
        readers = [handle.reader for handle in self.cameras.values() if handle.reader is not None]
        if not fastpick.AVAILABLE or len(readers) < len(self.cameras):
            return None
        return FastReads(list(self.cameras), readers, self.engine.settings, self.clock)

    def serves(self, op: str, fields: Mapping[str, Any]) -> bool:
        """False for requests only the coordinator can answer: those that fire software triggers,
        now or for a capture at T."""
        if fields.get("capture"):
            return False
        if op not in ("image", "tuple") or fields.get("at") is not None:
            return True
        names = [fields["camera"]] if fields.get("camera") else fields.get("cameras") or list(self.cameras)
        return not any(c in self.cameras and self.cameras[c].slots and self.cameras[c].triggered for c in names)

    def answer(self, op: str, fields: Mapping[str, Any], deadline_ns: int, copy: bool = True) -> Answer:
        """The reply header, images and (for views) a validity check, as the coordinator would
        send them. Raises the service's errors, or RequestTimeout at ``deadline_ns``."""
        actions = self.engine.submit(self._request(op, fields), self.now(), ticket=op)
        seen: dict[str, int] = {}
        while True:
            reply = settled(actions)
            if reply is not None:
                try:
                    return self._reply(reply, copy)
                except Overwritten:  # the ring came round during the copy: plan again
                    actions = self.engine.retry(reply, self.now())
                    continue
            now = self.now()
            if now >= deadline_ns:
                self.engine.cancel_all()
                raise RequestTimeout(f"no answer to {op!r} from the rings within the client's timeout")
            waiting = {c for p in self.engine.pending for c in p.cameras}
            for c in waiting:  # the write counts the engine's last look read, before it looked
                reader = self.cameras[c].reader
                if reader is not None:
                    seen[c] = max(seen.get(c, -1), reader.seen_count)
            updated = self._wait_for_frames(waiting, min(deadline_ns, self.engine.next_wake() or now), seen)
            actions = self.engine.on_frames(updated, self.now())

    def _request(self, op: str, fields: Mapping[str, Any]) -> protocol.Request:
        """The request as the service would validate it (protocol.request_of), without its
        encoding (nothing travels, so the frames stay raw). Validated once per form: only the
        times, which change with every call, are checked each time."""
        rest = {k: v for k, v in fields.items() if k not in _UNCHECKED}
        # each value with its type: 1 and True are equal keys, but not equally valid
        key = (op, *rest, *((type(v), tuple(v) if type(v) is list else v) for v in rest.values()))
        try:
            checked = self._requests.get(key)
        except TypeError:  # a value that cannot be a key (so not a valid one): validation says why
            return protocol.request_of(op, id=None, **fields)
        if checked is None:
            if len(self._requests) >= _REQUEST_FORMS:
                self._requests.clear()
            checked = self._requests[key] = protocol.request_of(op, id=None, **rest)
        request = dict(checked)
        schema = protocol.OPS[op]
        for name in _TIMES:
            value = fields.get(name)
            if value is not None and name in schema:
                request[name] = schema[name][0](name, value)
        return request

    def _reply(self, reply: Reply, copy: bool) -> Answer:
        """The plan's frames: their metadata, then their pixels (copies, checked whole in one
        call, or views), then the header. Raises Overwritten (counted as a torn read)."""
        searched = self.now()
        frames: list[FrameMeta] = []
        images: Images = []
        jobs: list[CopyJob] = []
        held: list[tuple[str, RingReader, int, int]] = []
        position: dict[tuple[str, int], int] = {}
        for pick in reply.plan.picks:
            if pick in position:
                continue
            position[pick] = len(frames)
            cam, i = pick
            snap, reader = reply.snapshots[cam], self._reader(cam)
            slot, seq, meta = snap.slot(i), snap.seq(i), snap.frame_meta(i)
            frames.append(
                {
                    "camera": cam,
                    "frame_id": meta.frame_id,
                    "t_capture": meta.t_capture,
                    "t_stored": meta.t_stored,
                    "generation": meta.generation,
                    "t_available": meta.t_available,
                    "capture": CAPTURES[meta.capture],
                    "t_target": meta.t_target or None,
                }
            )
            held.append((cam, reader, slot, seq))
            if copy:
                out = self.buffers.take(reader.layout.shape, reader.layout.dtype)
                jobs.append(reader.copy_job(slot, seq, out))
                images.append(out)
            else:
                try:
                    images.append(reader.view_slot(slot, seq))
                except Overwritten:
                    self.cameras[cam].torn_reads += 1
                    self.torn += 1
                    raise
        torn = slotio.copies(jobs) if jobs else None
        if torn is not None:
            cam, reader, slot, _ = held[torn[0]]
            self.cameras[cam].torn_reads += 1
            self.torn += 1
            raise reader.overwritten(slot, torn[1])
        copied = self.now()
        p = reply.pending
        # the plan's body is the engine's JSON-bound dict: the fields of a reply (docs/protocol.md 7)
        header = cast(ReplyHeader, {"ok": True, "clock": self.wire_clock, **reply.plan.body, "frames": frames})
        if reply.plan.groups is not None:
            header["groups"] = [[position[pick] for pick in group] for group in reply.plan.groups]
        header["timing"] = {
            "searched": searched,
            "received": p.t_received,
            "waited": reply.t_decided,
            "copied": copied,
            "sent": copied,  # nothing is sent: the frames are the caller's once copied
            "cameras": {c: {"waited": p.ready_at.get(c, reply.t_decided)} for c in p.cameras},
        }
        if copy:
            return header, images, None
        views = [(reader, slot, seq) for _, reader, slot, seq in held]
        return header, images, lambda: all(reader.slot_holds(slot, seq) for reader, slot, seq in views)

    def _reader(self, camera: str) -> RingReader:
        """The ring of a camera the engine chose frames of (so open: the engine saw them)."""
        reader = self.cameras[camera].reader
        assert reader is not None
        return reader

    def _wait_for_frames(self, cameras: set[str], until_ns: int, seen: dict[str, int]) -> set[str]:
        """The cameras whose write count moved on from ``seen`` before ``until_ns`` (empty: none
        did); ``seen`` is updated to the counts found."""
        readers = {c: r for c in cameras if (r := self.cameras[c].reader) is not None}
        counts = {c: seen.get(c, -1) for c in readers}
        due = min((_next_due(r) for r in readers.values()), default=until_ns)  # before the look below
        if all(r.field("write_count") == counts[c] for c, r in readers.items()):  # else: no nap
            nap_ns = min(due - WAKE_MARGIN_NS, until_ns) - self.now()
            if nap_ns > 0:
                time.sleep(nap_ns / 1e9)
        while True:
            now_counts = {c: r.field("write_count") for c, r in readers.items()}
            updated = {c for c, n in now_counts.items() if n != counts[c]}
            if updated or self.now() >= until_ns:
                seen.update(now_counts)
                return updated
            time.sleep(POLL_S)

    def close(self) -> None:
        for handle in self.cameras.values():
            handle.close()


def settled(actions: list[Action]) -> Reply | None:
    """The reply the engine's actions settle on, None if they are waits; raises a failure."""
    for action in actions:
        if isinstance(action, Failure):
            raise service_error(action.code, action.message)
        if isinstance(action, Reply):
            return action
    return None


def _next_due(reader: RingReader) -> int:
    """When the ring's next frame should be stored: its newest frame's capture time plus a
    period, plus the shortest capture-to-storage delay of the last few frames. Not the newest
    frame's storage time plus a period: a frame its worker stored late (held up by the
    machine) does not hold the camera's next capture back, and a nap planned from that
    storage slept past the next frame, by up to a period (issue 41)."""
    count = reader.field("write_count")
    if count == 0:
        return 0
    captured, stored, slots = reader.table["t_capture"], reader.table["t_stored"], reader.slots
    # slots the writer is not filling (it fills write count's), read plainly: only a nap's length rests on them
    recent = [w % slots for w in range(max(0, count - min(_DELAY_FRAMES, slots - 1)), count)]
    usual_delay = max(0, min(int(stored[s]) - int(captured[s]) for s in recent))
    return int(captured[recent[-1]]) + reader.field("period_ns") + usual_delay
