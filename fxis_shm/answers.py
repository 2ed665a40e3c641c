"""Building replies from the rings: snapshots, selection and the copies out.

Raises Reject (an error reply) or NotReady (the frames are not there yet).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from . import protocol, sequences
from .cameras import CameraHandle
from .bufferpool import BufferPool
from .errors import Code
from .ring import Overwritten
from .selection import INDEPENDENT, select
from .timesearch import Timeline
from .waitpolicy import AUTO, waiting_for

COPY_ATTEMPTS = 3


class Reject(Exception):
    """Ends a request with an error reply."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code, self.message = code, message


class NotReady(Exception):
    """Frames the request needs are not stored yet: keep waiting."""


@dataclass
class Pending:
    """A request on its way to a reply; ``respond`` sends the reply frames."""

    respond: Callable[[list], None]
    request: dict
    cameras: list[str]
    t_received: int
    t_star: int
    deadline: int = 0
    ready_at: dict[str, int] = field(default_factory=dict)
    wake_at: int = 0
    missing: list = field(default_factory=list)  # cameras down, left out of a partial tuple
    triggered: frozenset = frozenset()  # software-triggered cameras this request triggered
    t_trigger: int | None = None
    local: bool = False  # the client shares our kernel: reply with where the frames are (fast path)

    @property
    def op(self) -> str:
        return self.request["op"]


class Answers:
    def __init__(self, cameras: dict[str, CameraHandle], settings: dict):
        self.cameras = cameras
        self.settings = settings
        self.buffers = BufferPool()

    def setting(self, request: dict, key: str):
        value = request.get(key)
        return self.settings[key] if value is None else value

    def period(self, cam: str) -> int:
        return self.cameras[cam].reader.field("period_ns")

    # ---- reading the rings ----

    def snapshots(self, names: list[str], now: int) -> dict:
        return self.check_not_empty(self.snapshots_allowing_empty(names, now))

    @staticmethod
    def check_not_empty(snaps: dict) -> dict:
        empty = [c for c, snap in snaps.items() if not len(snap.timeline)]
        if empty:
            raise Reject(Code.NO_FRAMES, f"camera(s) {empty} have stored no frame yet")
        return snaps

    def snapshots_allowing_empty(self, names: list[str], now: int) -> dict:
        snaps = {}
        for cam in names:
            handle = self.cameras[cam]
            reason = handle.down_reason(now)
            if reason:
                raise Reject(Code.CAMERA_DOWN, reason)
            snaps[cam] = handle.reader.snapshot()
        return snaps

    def copy(self, snaps: dict, picks: list[tuple[str, int]], refs: bool = False) -> tuple[list, list, dict]:
        """Copy each distinct (camera, logical index) once: metadata, images, and each pick's position.
        With ``refs`` (a local client) nothing is copied: the metadata says where each frame is."""
        frames, images, position = [], [], {}
        for cam, i in picks:
            if (cam, i) in position:
                continue
            position[(cam, i)] = len(frames)
            frames.append(self._reference(cam, snaps[cam], i) if refs else
                          self._copied(cam, snaps[cam], i, len(images), images))
        return frames, images, position

    def _copied(self, cam: str, snap, i: int, buffer: int, images: list) -> dict:
        handle = self.cameras[cam]
        layout = handle.reader.layout
        try:
            image = handle.reader.copy(snap, i, self.buffers.take(layout.shape, layout.dtype))
        except Overwritten:
            handle.torn_reads += 1
            raise
        images.append(image)
        meta = snap.frame_meta(i)
        return protocol.frame_meta(cam, meta.frame_id, meta.t_capture, meta.t_stored,
                                   meta.generation, image, buffer, meta.t_available)

    def _reference(self, cam: str, snap, i: int) -> dict:
        reader = self.cameras[cam].reader
        slot, seq = snap.slot(i), snap.seq(i)
        reader.check_slot(slot, seq, "before")  # already gone: choose again rather than send it
        meta = snap.frame_meta(i)
        return protocol.frame_ref(cam, meta.frame_id, meta.t_capture, meta.t_stored, meta.generation,
                                  reader.layout.shape, reader.layout.dtype, meta.t_available,
                                  ring=reader.name, instance=reader.instance, slot=slot, seq=seq)

    def with_retries(self, names: list[str], now: int, build: Callable[[dict], tuple],
                     taken: dict | None = None):
        """Run ``build(snapshots)``, re-snapshotting if a chosen slot was overwritten meanwhile.
        ``taken``: snapshots of ``names`` just taken, used for the first attempt."""
        for attempt in range(COPY_ATTEMPTS):
            if attempt == 0 and taken is not None:
                snaps = self.check_not_empty(taken)
            else:
                snaps = self.snapshots(names, now if attempt == 0 else time.monotonic_ns())
            try:
                return build(snaps)
            except Overwritten:
                continue
        raise Reject(Code.INTERNAL, f"frames were overwritten {COPY_ATTEMPTS} times while being copied")

    # ---- the ops ----

    def check_history(self, cam: str, snap, t_earliest: int, t_received: int) -> None:
        oldest = snap.timeline.at(0)
        if t_earliest < oldest - self.period(cam):
            raise Reject(Code.OUT_OF_RANGE,
                         f"asks for frames {(oldest - t_earliest) / 1e6:.1f} ms older than the oldest "
                         f"frame of camera {cam!r}; its ring holds {len(snap.timeline)} frames, the "
                         f"oldest from {(t_received - oldest) / 1e6:.1f} ms before the request")

    def radius(self, cameras) -> int:
        """How far from t* a tuple's frames may lie: the longest frame period."""
        return max(self.period(c) for c in cameras)

    def tolerance(self, cameras) -> int:
        """The sync tolerance: tuples this much more skewed than the least count as
        equally synchronized. Capped at a quarter of the shortest frame period, so it
        never lets a tuple of another skew class (a period apart) through."""
        periods = [self.period(c) for c in cameras if self.period(c) > 0]
        cap = min(periods) // 4 if periods else None
        tolerance = int(self.settings["sync_tolerance_ms"] * 1e6)
        return tolerance if cap is None else min(tolerance, cap)

    def select_frames(self, mode: str, timelines: dict, t: int, tolerance_ns: int | None = None):
        radius = self.radius(timelines)
        if tolerance_ns is None:
            tolerance_ns = self.tolerance(timelines)
        return select(mode, timelines, t, radius, tolerance_ns)

    def frames_near(self, p: Pending, snaps: dict) -> tuple[dict, list]:
        """image and tuple: one frame per camera near t*."""
        explicit = p.request.get("at") is not None  # "now" is never too old: the ring moved on
        for cam in p.cameras:
            if explicit and cam not in p.triggered:
                self.check_history(cam, snaps[cam], p.t_star, p.t_received)
        mode = self.sync_mode(p)
        usable = {c: self.usable_frames(p, c, snaps[c]) for c in p.cameras}
        timelines = {c: tl for c, (tl, _) in usable.items()}
        sel = self.select_frames(mode, timelines, p.t_star)
        max_skew = self.setting(p.request, "max_skew_ms")
        if p.op == "tuple" and max_skew is not None and sel.skew_ns > max_skew * 1e6:
            if sel.best_skew_ns <= max_skew * 1e6:  # the least-skew tuple meets the limit
                sel = self.select_frames(mode, timelines, p.t_star, tolerance_ns=0)
        searched = time.monotonic_ns()
        picks = [(c, usable[c][1] + i) for c, i in sel.index.items()]  # back to snapshot indices
        if p.op == "tuple" and max_skew is not None and sel.skew_ns > max_skew * 1e6:
            raise Reject(Code.SKEW_EXCEEDED,
                         f"the best tuple near t* has a skew of {sel.best_skew_ns / 1e6:.3f} ms, "
                         f"more than max_skew_ms={max_skew}")
        frames, images, _ = self.copy(snaps, picks, p.local)
        body = {"op": p.op, "t_request": p.t_star, "frames": frames,
                "timing": {"searched": searched}}
        if p.op == "tuple":
            body.update(skew_ns=sel.skew_ns, sync=mode)
            if p.missing:
                body["missing"] = p.missing
        return body, images

    def usable_frames(self, p: Pending, cam: str, snap) -> tuple[Timeline, int]:
        """The camera's frames a request may use, and the snapshot index of the first:
        for a camera the request triggered, only those stored after the trigger."""
        tl = snap.timeline
        if cam not in p.triggered:
            return tl, 0
        first = len(tl)
        while first > 0 and snap.frame_meta(first - 1).t_stored >= p.t_trigger:
            first -= 1
        if first == len(tl):
            raise NotReady(f"camera {cam!r} has not stored its triggered frame yet")
        return Timeline(tl.times, tl.physical(first), len(tl) - first), first

    def sync_mode(self, p: Pending) -> str:
        return INDEPENDENT if p.op == "image" else self.setting(p.request, "sync")

    def latest(self, p: Pending, snaps: dict) -> tuple[dict, list]:
        frames, images, _ = self.copy(snaps, [(c, len(snaps[c].timeline) - 1) for c in p.cameras], p.local)
        return {"op": "latest", "frames": frames, "timing": {}}, images

    def sequence_spec(self, p: Pending) -> sequences.SequenceSpec:
        r = p.request
        return sequences.SequenceSpec(
            kind=r["kind"], t_star=p.t_star, count=r["count"] or 1, direction=r["direction"],
            interval_ns=int((r["interval_ms"] or 0) * 1e6),
            start=r["start"] or 0, end=r["end"] or 0,
        )

    def sequence(self, p: Pending, snaps: dict) -> tuple[dict, list]:
        spec = self.sequence_spec(p)
        ref = p.cameras[0]
        if spec.kind != sequences.CONSECUTIVE:  # consecutive frames are checked exactly, by index
            for cam in p.cameras:
                self.check_history(cam, snaps[cam], sequences.earliest_needed(spec, self.period(cam)),
                                   p.t_received)
        mode = self.setting(p.request, "sync")
        timelines = {c: snaps[c].timeline for c in p.cameras}
        groups: list[dict[str, int]] = []
        if spec.kind == sequences.INTERVAL:
            targets = sequences.target_times(spec)
            for t in targets:
                groups.append(dict(self.select_frames(mode, timelines, t).index))
        else:
            try:
                indices = sequences.reference_indices(spec, timelines[ref])
            except sequences.NotYet as exc:
                raise NotReady(str(exc)) from None
            except sequences.NotHeld as exc:
                raise Reject(Code.OUT_OF_RANGE, f"camera {ref!r}: {exc}") from None
            targets = [timelines[ref].at(i) for i in indices]
            self._others_caught_up(p, snaps, targets[-1] if targets else p.t_star)
            for i, t in zip(indices, targets):
                only_this = {ref: _single(timelines[ref], i)}
                chosen = self.select_frames(mode, {**timelines, **only_this}, t).index
                groups.append({**chosen, ref: i})
        self.check_size(len(groups) * len(p.cameras))
        searched = time.monotonic_ns()
        frames, images, position = self.copy(snaps, [(c, g[c]) for g in groups for c in p.cameras], p.local)
        body = {
            "op": "sequence", "t_request": p.t_star, "targets": targets, "frames": frames,
            "groups": [[position[(c, g[c])] for c in p.cameras] for g in groups],
            "timing": {"searched": searched},
        }
        return body, images

    def _others_caught_up(self, p: Pending, snaps: dict, t_last: int) -> None:
        """NotReady while another camera's frame for the last reference time may still come."""
        now = time.monotonic_ns()
        for cam in p.cameras[1:]:
            state = self.cameras[cam].state(snaps[cam])
            if waiting_for(AUTO, t_last, now, {cam: state}):
                raise NotReady(f"camera {cam!r} has not stored its frame near the last reference time")

    def check_size(self, n_frames: int) -> None:
        limit = self.settings["max_sequence_frames"]
        if n_frames > limit:
            raise Reject(Code.TOO_LARGE, f"the sequence names {n_frames} frames; the limit is {limit}")


def _single(tl: Timeline, i: int) -> Timeline:
    """A timeline holding only frame ``i`` of ``tl``."""
    return Timeline(tl.times, tl.physical(i), 1)
