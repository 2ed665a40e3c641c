"""The metadata of each frame in a reply's header (docs/protocol.md): what it is, when it was
captured and stored, and where its pixels are: a buffer of the reply, or a ring slot (the local
fast path). Pure, like the rest of the codec (fxis_shm.wire.protocol names these too)."""

from __future__ import annotations

import json

import numpy as np

from fxis_shm.core.snapshot import CAPTURES
from fxis_shm.wire import encoding as codec

_CAPTURE_JSON = {name: json.dumps(name) for name in CAPTURES}  # each ``capture`` as JSON text


def _literal(value) -> str:
    """``value`` as JSON text, to stand as it is in a %-template."""
    return json.dumps(value).replace("%", "%%")


class CameraFrames:
    """What every frame of one camera says alike in a reply's header (its name, shape and
    dtype), checked once per camera rather than once per frame, and written as JSON once."""

    __slots__ = ("camera", "shape", "dtype", "name_json", "_frame_json")

    def __init__(self, camera: str, shape, dtype: str):
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
        t_available,
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
        t_available,
        t_target: int | None = None,
        capture: str = CAPTURES[0],
        **more,
    ) -> dict:
        """One frame's metadata (ints as they are), then ``more`` (its buffer, or where it is):
        ``capture`` free, scheduled or lockstep, ``t_target`` the moment it was triggered for
        (None or 0: none; a ring's slot record says 0)."""
        return {
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
            **more,
        }


def described(
    camera,
    frame_id,
    t_capture,
    t_stored,
    generation,
    shape,
    dtype: str,
    t_available,
    t_target: int | None = None,
    capture: str = CAPTURES[0],
) -> dict:
    return CameraFrames(camera, shape, dtype).frame(
        int(frame_id),
        int(t_capture),
        int(t_stored),
        int(generation),
        None if t_available is None else int(t_available),
        None if t_target is None else int(t_target),
        capture,
    )


def frame_meta(
    camera: str,
    frame_id: int,
    t_capture: int,
    t_stored: int,
    generation: int,
    image: np.ndarray,
    buffer: int,
    t_available: int | None = None,
    t_target: int | None = None,
    capture: str = CAPTURES[0],
) -> dict:
    """A frame whose pixels travel in buffer frame number ``buffer`` of the reply."""
    return {
        **described(
            camera,
            frame_id,
            t_capture,
            t_stored,
            generation,
            image.shape,
            image.dtype.name,
            t_available,
            t_target,
            capture,
        ),
        "buffer": buffer,
    }


def frame_ref(
    camera: str,
    frame_id: int,
    t_capture: int,
    t_stored: int,
    generation: int,
    shape,
    dtype: str,
    t_available: int | None,
    *,
    ring: str,
    instance: int,
    slot: int,
    seq: int,
) -> dict:
    """A frame of a local reply: the client copies it out of ``slot`` of the ring
    segment ``ring`` (whose header carries ``instance``) while the slot shows ``seq``.
    ``instance`` is an unsigned 64-bit number, so it travels as a decimal string: a JSON
    parser that reads numbers as doubles would lose its low bits."""
    return {
        **described(camera, frame_id, t_capture, t_stored, generation, shape, dtype, t_available),
        **ring_place(ring, instance, slot, seq),
    }


def ring_place(ring: str, instance: int, slot: int, seq: int) -> dict:
    """Where a frame of a local reply is (see ``frame_ref``)."""
    return {"ring": ring, "instance": str(int(instance)), "slot": int(slot), "seq": int(seq)}


def encoded_meta(meta: dict, encoding: str, nbytes: int) -> dict:
    """A frame's metadata when its buffer holds the image in ``encoding`` (``nbytes`` long)."""
    return meta if encoding == codec.RAW else {**meta, "encoding": encoding, "bytes": int(nbytes)}
