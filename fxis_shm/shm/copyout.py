"""The coordinator's access to the rings: snapshots of the cameras that are up, and
copies of chosen frames out of them: each straight into the ZeroMQ message that carries it
(MESSAGES), into pooled buffers (COPY), or, for a client on this kernel, where each frame is,
so that it copies the frame itself (REFS)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fxis_shm.core import timebase
from fxis_shm.core.decisions import Reject, check_not_empty
from fxis_shm.core.engine import Reply
from fxis_shm.core.selection import Selection, radius_for, select, tolerance_for
from fxis_shm.core.snapshot import Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.errors import Code, Overwritten
from fxis_shm.shm import ordering
from fxis_shm.shm.bufferpool import BufferPool
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.ring import RingReader
from fxis_shm.wire import protocol
from fxis_shm.wire.encodecache import EncodeCache
from fxis_shm.wire.encoding import RAW
from fxis_shm.wire.framemeta import CameraFrames, encoded_meta, ring_place
from fxis_shm.wire.headers import FrameMeta
from fxis_shm.wire.protocol import Buffer

COPY, REFS, VIEWS, MESSAGES = "copy", "refs", "views", "messages"  # how a reply carries its frames


def copied_by(reader: RingReader, slot: int, seq: int, make: Callable[[NDArray[Any]], Buffer]) -> Buffer:
    """``make(the slot's bytes)``: whatever copy of them it makes (a ZeroMQ message, say), kept
    only if the slot held the frame of ``seq`` from before the copy to after it (the seqlock
    check of ``RingReader.copy_slot``, with the copy made by ``make``); else Overwritten."""
    reader.check_slot(slot, seq, "before")
    copy = make(reader.data[slot])
    ordering.fence_acquire()  # every byte was read before the seq is read again
    reader.check_slot(slot, seq, "during")
    return copy


class CopyOut:
    def __init__(
        self,
        cameras: dict[str, CameraHandle],
        settings: Mapping[str, Any],
        buffers: BufferPool | None = None,
        message: Callable[[NDArray[Any]], Buffer] | None = None,
    ):
        """``message(bytes)``: a copy of the bytes into a message of the transport (for
        MESSAGES: the coordinator's zmq.Frame, copied once out of the ring, sent as it is), for
        frames of up to ``message_max`` bytes; larger ones go in pooled buffers."""
        self.cameras = cameras
        self.settings = settings
        self.buffers = buffers or BufferPool()
        self.message = message
        self.message_max = 1 << 62
        self.encoded = EncodeCache()
        self._headers: dict[str, tuple[RingReader, CameraFrames]] = {}

    def header(self, cam: str) -> CameraFrames:
        """What every frame of ``cam`` says alike in a reply, made again only when its ring is."""
        reader = self.cameras[cam].ring_open()
        known = self._headers.get(cam)
        if known is None or known[0] is not reader:
            known = (reader, CameraFrames(cam, reader.layout.shape, reader.layout.dtype))
            self._headers[cam] = known
        return known[1]

    def period(self, cam: str) -> int:
        return self.cameras[cam].period_ns

    def snapshots(self, names: list[str], now: int) -> dict[str, Snapshot]:
        """Each camera's frames now; Reject if one is down or has none."""
        snaps = {}
        for cam in names:
            reason = self.cameras[cam].down_reason(now)
            if reason:
                raise Reject(Code.CAMERA_DOWN, reason)
            snaps[cam] = self.cameras[cam].snapshot()
        check_not_empty(snaps)
        return snaps

    def select_frames(self, mode: str, timelines: dict[str, Timeline], t: int) -> Selection:
        periods = {c: self.period(c) for c in timelines}
        return select(
            mode, timelines, t, radius_for(periods), tolerance_for(periods, self.settings["sync_tolerance_ms"])
        )

    def reply(self, reply: Reply, how: str | None = None) -> tuple[dict[str, object], list[Buffer]]:
        """The body and images of the reply ``reply`` plans; raises Overwritten if a chosen
        slot was overwritten before its copy was complete. ``how``: COPY (pooled buffers),
        MESSAGES (the transport's messages, see ``message``), REFS (where each frame is, for
        a client on this kernel) or VIEWS (read-only views of the slots, for a reader in this
        process); default REFS for a local client."""
        p, plan = reply.pending, reply.plan
        searched = timebase.now()
        how = how or (REFS if p.local else COPY)
        frames, images, position = self.copy(
            reply.snapshots, plan.picks, how, p.request.get("encoding") or RAW, p.request.get("quality")
        )
        body: dict[str, object] = {**plan.body, "frames": frames}
        if plan.groups is not None:
            body["groups"] = [[position[pick] for pick in group] for group in plan.groups]
        body["timing"] = {
            "searched": searched,
            "received": p.t_received,
            "waited": reply.t_decided,
            "copied": timebase.now(),
            "cameras": {c: {"waited": p.ready_at.get(c, reply.t_decided)} for c in p.cameras},
        }
        if how == REFS:
            body["delivery"] = protocol.LOCAL
        return body, images

    def copy(
        self,
        snaps: Mapping[str, Snapshot],
        picks: list[tuple[str, int]],
        how: str = COPY,
        encoding: str = RAW,
        quality: int | None = None,
    ) -> tuple[list[FrameMeta], list[Buffer], dict[tuple[str, int], int]]:
        """Copy each distinct (camera, snapshot index) once: metadata, images (in ``encoding``),
        and each pick's position. With REFS nothing is copied: the metadata says where each frame is."""
        frames: list[FrameMeta] = []
        images: list[Buffer] = []
        position: dict[tuple[str, int], int] = {}
        for cam, i in picks:
            if (cam, i) in position:
                continue
            position[(cam, i)] = len(frames)
            if how == REFS:
                frames.append(self._reference(cam, snaps[cam], i))
            elif encoding != RAW and how in (COPY, MESSAGES):
                frames.append(self._encoded(cam, snaps[cam], i, len(images), images, encoding, quality))
            else:
                frames.append(self._copied(cam, snaps[cam], i, len(images), images, how))
        return frames, images, position

    def _encoded(
        self, cam: str, snap: Snapshot, i: int, buffer: int, images: list[Buffer], encoding: str, quality: int | None
    ) -> FrameMeta:
        """A frame in ``encoding``: copied out of the ring (and checked whole) only if no reply or
        stream has encoded it so yet."""
        meta = snap.frame_meta(i)

        def pixels() -> NDArray[Any]:
            copied: list[Buffer] = []
            self._copied(cam, snap, i, buffer, copied, COPY)
            image = copied[0]
            assert isinstance(image, np.ndarray)  # (COPY copies into a pooled array)
            return image

        data = self.encoded.get((cam, meta.generation, meta.frame_id), pixels, encoding, quality)
        images.append(data)
        return encoded_meta(self.header(cam).recorded(meta, buffer=buffer), encoding, len(data))

    def _copied(self, cam: str, snap: Snapshot, i: int, buffer: int, images: list[Buffer], how: str) -> FrameMeta:
        handle = self.cameras[cam]
        reader = handle.ring_open()
        slot, seq = snap.slot(i), snap.seq(i)
        try:
            if how == VIEWS:
                image: Buffer = reader.view_slot(slot, seq)
            elif how == MESSAGES and self.message is not None and reader.layout.nbytes <= self.message_max:
                image = copied_by(reader, slot, seq, self.message)
            else:
                image = reader.copy_slot(slot, seq, self.buffers.take(reader.layout.shape, reader.layout.dtype))
        except Overwritten:
            handle.torn_reads += 1
            raise
        images.append(image)
        return self.header(cam).recorded(snap.frame_meta(i), buffer=buffer)

    def encode(
        self, meta: FrameMeta, image: NDArray[Any], encoding: str, quality: int | None
    ) -> tuple[FrameMeta, bytes]:
        """A copied frame (checked whole) in ``encoding``, encoded once for every reply and stream."""
        data = self.encoded.get(
            (meta["camera"], meta["generation"], meta["frame_id"]), lambda: image, encoding, quality
        )
        return encoded_meta(meta, encoding, len(data)), data

    def _reference(self, cam: str, snap: Snapshot, i: int) -> FrameMeta:
        reader = self.cameras[cam].ring_open()
        slot, seq = snap.slot(i), snap.seq(i)
        reader.check_slot(slot, seq, "before")  # already gone: choose again rather than send it
        return self.header(cam).recorded(snap.frame_meta(i), place=ring_place(reader.name, reader.instance, slot, seq))
