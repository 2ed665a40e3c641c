"""A synchronized tuple as files: one lossless PNG per camera and ``tuple.json`` with what
the service knows of every frame. ``fxis grab`` writes them into a folder; the dashboard's
save button sends them as a zip. Pure: a tuple in, file names and bytes out."""

from __future__ import annotations

import json

from fxis_shm.wire import encoding

META_FILE = "tuple.json"


def tuple_files(frames) -> dict[str, bytes]:
    """``{file name: bytes}`` of a FrameTuple: NAME.png per camera, then tuple.json."""
    files: dict[str, bytes] = {}
    meta = {
        "t_request": frames.t_request,
        "skew_ns": frames.skew_ns,
        "clock": "CLOCK_MONOTONIC",
        "timing": frames.timing,
        "frames": {},
        "missing": list(getattr(frames, "missing", [])),
    }
    for name, frame in frames.items():
        files[f"{name}.png"] = encoding.encode(frame.image, encoding.PNG)
        meta["frames"][name] = {
            "file": f"{name}.png",
            "frame_id": frame.frame_id,
            "t_capture": frame.t_capture,
            "t_stored": frame.t_stored,
            "generation": frame.generation,
            "shape": list(frame.image.shape),
            "dtype": frame.image.dtype.name,
        }
    files[META_FILE] = json.dumps(meta, indent=2).encode()
    return files
