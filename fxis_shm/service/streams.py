"""Streams on the PUB socket: each camera's frames and synchronized tuples as
they arrive, optionally decimated to a rate.

Only streams someone subscribes to are encoded (the XPUB socket reports the
subscriptions). Every message carries the same metadata as a reply plus a
per-stream ``seq``, so a subscriber that fell behind (its bounded queue lost
messages) can tell what it missed from seq and frame_id gaps.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from fxis_shm.core.decimation import Decimator, every_frame
from fxis_shm.core.decisions import Reject
from fxis_shm.core.selection import JOINT
from fxis_shm.core.snapshot import Snapshot
from fxis_shm.errors import Overwritten
from fxis_shm.service.outbox import Part
from fxis_shm.shm.copyout import CopyOut
from fxis_shm.wire import protocol
from fxis_shm.wire.encoding import RAW
from fxis_shm.wire.headers import FrameMeta
from fxis_shm.wire.protocol import StreamTopic, parse_stream_topic
from fxis_shm.wire.statusdoc import StreamCount

log = logging.getLogger("streams")

_Meta = dict[str, object]  # a frame's metadata, a message's body
_Copied = tuple[FrameMeta, Part]  # a frame copied (or encoded): its metadata and its image
_Copies = dict[tuple[str, int], _Copied]  # (camera, write index) -> the frame copied


@dataclass
class _StreamState:
    topic: StreamTopic
    seq: int = 0
    last_write: int = -1  # frames: write index of the last frame published
    last_key: tuple[int, ...] = ()  # tuples: the frames of the last tuple published
    last_t_max: int = 0  # tuples: the newest capture time in the last tuple published
    decimator: Decimator = field(init=False)

    def __post_init__(self) -> None:
        self.decimator = Decimator(self.topic.rate_hz)


class Streams:
    def __init__(self, copyout: CopyOut, publish: Callable[[str, Sequence[Part]], None]):
        self.copyout = copyout
        self.publish = publish
        self.active: dict[str, _StreamState] = {}

    def subscription(self, topic: str, subscribed: bool) -> None:
        stream = parse_stream_topic(topic)
        if stream is None or (stream.camera and stream.camera not in self.copyout.cameras):
            return  # not a stream (an event reply topic, or a prefix): nothing to produce
        if subscribed:
            self.active.setdefault(topic, _StreamState(stream))
            log.info("stream %s subscribed", topic)
        else:
            self.active.pop(topic, None)
            log.info("stream %s unsubscribed", topic)

    def status(self) -> dict[str, StreamCount]:
        return {topic: {"published": s.seq} for topic, s in self.active.items()}

    def on_frames(self, updated: set[str], now: int) -> None:
        if not self.active:
            return
        copies: _Copies = {}  # (camera, write index) -> (meta, image), shared by every stream this round
        for topic, state in self.active.items():
            try:
                camera = state.topic.camera
                if state.topic.kind == "frames" and camera is not None and camera in updated:
                    self._frames(topic, state, camera, now, copies)
                elif state.topic.kind == "tuples":
                    self._tuple(topic, state, now, copies)
            except (Reject, Overwritten) as exc:
                log.debug("stream %s skipped a round: %s", topic, exc)

    def _copy(self, snap: Snapshot, cam: str, i: int, copies: _Copies, topic: StreamTopic) -> _Copied:
        key = (cam, snap.first_write + i)
        if key not in copies:
            frames, images, _ = self.copyout.copy({cam: snap}, [(cam, i)])
            copies[key] = (frames[0], images[0])
        if topic.encoding != RAW:
            meta, image = copies[key]
            assert isinstance(image, np.ndarray)  # (copy() copies into a pooled array)
            return self.copyout.encode(meta, image, topic.encoding, topic.quality)
        return copies[key]

    def _send(
        self,
        topic: str,
        state: _StreamState,
        metas: Sequence[FrameMeta],
        images: list[Part],
        extra: _Meta,
        period_ns: int,
    ) -> None:
        state.seq += 1
        frames = [{**m, "buffer": n} for n, m in enumerate(metas)]
        body: _Meta = {"stream": topic[:-1], "seq": state.seq, "frames": frames, **extra}
        if state.seq == 1 and state.topic.rate_hz:  # what rate the subscriber will get
            body["rate"] = _rate_note(state.topic.rate_hz, period_ns)
        self.publish(topic, protocol.encode_reply(None, body, images))

    def _frames(self, topic: str, state: _StreamState, cam: str, now: int, copies: _Copies) -> None:
        snap = self.copyout.snapshots([cam], now)[cam]
        period = self.copyout.period(cam)
        first_new = max(0, state.last_write + 1 - snap.first_write)
        for i in range(first_new, len(snap.timeline)):
            if not state.decimator.offer(snap.timeline.at(i), period):
                continue
            meta, image = self._copy(snap, cam, i, copies, state.topic)
            self._send(topic, state, [meta], [image], {}, period)
        state.last_write = snap.first_write + len(snap.timeline) - 1

    def _tuple(self, topic: str, state: _StreamState, now: int, copies: _Copies) -> None:
        cams = list(self.copyout.cameras)
        snaps = self.copyout.snapshots(cams, now)
        t_ref = min(t for t in (snaps[c].newest for c in cams) if t is not None)  # every camera has frames up to here
        period = max(self.copyout.period(c) for c in cams)
        sel = self.copyout.select_frames(
            self.copyout.settings["sync"] or JOINT, {c: snaps[c].timeline for c in cams}, t_ref
        )
        key = tuple(snaps[c].first_write + sel.index[c] for c in cams)
        if key == state.last_key or (state.last_key and max(sel.t.values()) <= state.last_t_max):
            return  # no tuple newer than the last one
        state.last_key, state.last_t_max = key, max(sel.t.values())
        if not state.decimator.offer(t_ref, period):
            return
        pairs = [self._copy(snaps[c], c, sel.index[c], copies, state.topic) for c in cams]
        self._send(
            topic,
            state,
            [m for m, _ in pairs],
            [img for _, img in pairs],
            {"t_request": t_ref, "skew_ns": sel.skew_ns},
            period,
        )


def _rate_note(rate_hz: float, period_ns: int) -> _Meta:
    fps = round(1e9 / period_ns, 3) if period_ns > 0 else None
    note: _Meta = {"asked_hz": rate_hz, "camera_fps": fps, "every_frame": every_frame(rate_hz, period_ns)}
    if note["every_frame"]:
        note["message"] = f"asked for {rate_hz} Hz; the camera gives {fps} fps: every frame is sent"
    return note
