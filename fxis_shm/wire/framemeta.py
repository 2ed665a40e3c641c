"""The metadata of each frame in a reply's header (docs/protocol.md): what it is, when it was
captured and stored, and where its pixels are: a buffer of the reply, or a ring slot (the local
fast path). Pure, like the rest of the codec (fxis_shm.wire.protocol names these too)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from numpy.typing import NDArray

from fxis_shm.core.snapshot import CAPTURES, SlotMeta
from fxis_shm.wire import encoding as codec
from fxis_shm.wire.headers import FrameMeta, RingPlace

_CAPTURE_JSON = {name: json.dumps(name) for name in CAPTURES}  # each ``capture`` as JSON text


def _literal(value: object) -> str:
    """``value`` as JSON text, to stand as it is in a %-template."""
    return json.dumps(value).replace("%", "%%")


class CameraFrames:
    """What every frame of one camera says alike in a reply's header (its name, shape and
    dtype), checked once per camera rather than once per frame, and written as JSON once."""

    __slots__ = ("camera", "shape", "dtype", "name_json", "_frame_json")

    def __init__(self, camera: str, shape: Sequence[int], dtype: str):
        self.camera, self.shape, self.dtype = camera, tuple(int(n) for n in shape), str(dtype)
        self.name_json = json.dumps(camera)  # the name as JSON text
        self._frame_json = (
            '{"camera": '
            + self.name_json.replace("%", "%%")
            + ', "frame_id": %d, "t_capture": %d, "t_available": %d, "t_stored": %d, '
            '"generation": %d, "capture": %s, "t_target": %s, "shape": '
            + _literal(list(self.shape))
            + ', "dtype": '
            + _literal(self.dtype)
            + ', "buffer": %d}'
        )

    def frame_json(
        self,
        frame_id: int,
        t_capture: int,
        t_stored: int,
        generation: int,
        t_available: int | None,
        buffer: int,
        t_target: int | None = None,
        capture: str = CAPTURES[0],
    ) -> str:
        """``frame(..., buffer=buffer)`` as the JSON text the codec writes of it, without making
        the dict (see fxis_shm.wire.replytext)."""
        t_available = t_capture if t_available is None else t_available
        target = f"{t_target:d}" if t_target else "null"
        return self._frame_json % (
            frame_id,
            t_capture,
            t_available,
            t_stored,
            generation,
            _CAPTURE_JSON[capture],
            target,
            buffer,
        )

    def frame(
        self,
        frame_id: int,
        t_capture: int,
        t_stored: int,
        generation: int,
        t_available: int | None,
        t_target: int | None = None,
        capture: str = CAPTURES[0],
        *,
        buffer: int | None = None,
        place: RingPlace | None = None,
    ) -> FrameMeta:
        """One frame's metadata (ints as they are), then where its pixels are: ``buffer`` of
        the reply, or ``place`` in a ring (a local reply). ``capture`` free, scheduled or
        lockstep, ``t_target`` the moment it was triggered for (None or 0: none; a ring's slot
        record says 0)."""
        meta: FrameMeta = {
            "camera": self.camera,
            "frame_id": frame_id,
            "t_capture": t_capture,
            "t_available": t_capture if t_available is None else t_available,
            "t_stored": t_stored,
            "generation": generation,
            "capture": capture,
            "t_target": t_target or None,
            "shape": list(self.shape),
            "dtype": self.dtype,
        }
        if buffer is not None:
            meta["buffer"] = buffer
        if place is not None:
            meta["ring"], meta["instance"], meta["slot"], meta["seq"] = (
                place["ring"],
                place["instance"],
                place["slot"],
                place["seq"],
            )
        return meta

    def recorded(self, record: SlotMeta, *, buffer: int | None = None, place: RingPlace | None = None) -> FrameMeta:
        """``frame`` of a ring's slot record, its fields as the record has them."""
        return self.frame(
            record.frame_id,
            record.t_capture,
            record.t_stored,
            record.generation,
            record.t_available,
            record.t_target,
            CAPTURES[record.capture],
            buffer=buffer,
            place=place,
        )


def frame_meta(
    camera: str,
    frame_id: int,
    t_capture: int,
    t_stored: int,
    generation: int,
    image: NDArray[Any],
    buffer: int,
    t_available: int | None = None,
    t_target: int | None = None,
    capture: str = CAPTURES[0],
) -> FrameMeta:
    """A frame whose pixels travel in buffer frame number ``buffer`` of the reply (numbers of
    numpy's integer types are written as Python ints)."""
    return CameraFrames(camera, image.shape, image.dtype.name).frame(
        int(frame_id),
        int(t_capture),
        int(t_stored),
        int(generation),
        None if t_available is None else int(t_available),
        None if t_target is None else int(t_target),
        capture,
        buffer=buffer,
    )


def frame_ref(camera: str, record: SlotMeta, shape: Sequence[int], dtype: str, place: RingPlace) -> FrameMeta:
    """A frame of a local reply: the client copies it out of ``place`` (see ``ring_place``).
    ``record`` is the frame's slot record, as the ring's snapshot reads it."""
    return CameraFrames(camera, shape, dtype).recorded(record, place=place)


def ring_place(ring: str, instance: int, slot: int, seq: int) -> RingPlace:
    """Where a frame of a local reply is: ``slot`` of the ring segment ``ring`` (whose header
    carries ``instance``) while the slot shows ``seq``. ``instance`` is an unsigned 64-bit
    number, so it travels as a decimal string: a JSON parser that reads numbers as doubles
    would lose its low bits."""
    return {"ring": ring, "instance": str(int(instance)), "slot": int(slot), "seq": int(seq)}


def encoded_meta(meta: FrameMeta, encoding: str, nbytes: int) -> FrameMeta:
    """A frame's metadata when its buffer holds the image in ``encoding`` (``nbytes`` long)."""
    if encoding == codec.RAW:
        return meta
    coded = meta.copy()
    coded["encoding"], coded["bytes"] = encoding, int(nbytes)
    return coded
