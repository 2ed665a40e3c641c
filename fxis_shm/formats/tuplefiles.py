"""A synchronized tuple as files: one lossless PNG per camera and ``tuple.json`` with what
the service knows of every frame. ``fxis grab`` writes them into a folder; the dashboard's
save button sends them as a zip. Pure: a tuple in, file names and bytes out."""

from __future__ import annotations

import json
from collections.abc import Iterator

from fxis_shm.wire import encoding

META_FILE = "tuple.json"


def tuple_files(frames) -> dict[str, bytes]:
    """``{file name: bytes}`` of a FrameTuple: NAME.png per camera, then tuple.json."""
    files = dict(image_files(frames))
    files[META_FILE] = tuple_json(frames, list(frames))
    return files


def image_files(frames) -> Iterator[tuple[str, bytes]]:
    """(NAME.png, its bytes) per camera of a FrameTuple, each encoded when asked for."""
    for name, frame in frames.items():
        yield f"{name}.png", encoding.encode(frame.image, encoding.PNG)


def tuple_json(frames, saved: list[str], ended: str = "complete") -> bytes:
    """tuple.json of the cameras ``saved`` (those whose PNG is there); ``ended`` says whether
    the saving was complete or interrupted, and ``not_saved`` which frames it left out."""
    meta = {
        "t_request": frames.t_request,
        "skew_ns": frames.skew_ns,
        "clock": "CLOCK_MONOTONIC",
        "timing": frames.timing,
        "frames": {},
        "missing": list(getattr(frames, "missing", [])),
    }
    if ended != "complete":
        meta["ended"] = ended
        meta["not_saved"] = [name for name in frames if name not in saved]
    for name in saved:
        frame = frames[name]
        meta["frames"][name] = {
            "file": f"{name}.png",
            "frame_id": frame.frame_id,
            "t_capture": frame.t_capture,
            "t_stored": frame.t_stored,
            "generation": frame.generation,
            "capture": frame.capture,  # free, scheduled or lockstep (docs/sync.md)
            "t_target": frame.t_target,  # the moment it was to be captured at (None: free)
            "residual_ns": frame.residual_ns,  # t_capture - t_target (None: free)
            "shape": list(frame.image.shape),
            "dtype": frame.image.dtype.name,
        }
    return json.dumps(meta, indent=2).encode()
