"""Each frame is encoded at most once however many clients and streams ask for it: a
small cache of encoded frames keyed by camera, generation, frame id and encoding.
(ROS's image_transport does the same: one compressed variant per frame, not per
subscriber.) A frame leaves the cache after ``size`` newer encodings; by then the ring
has usually moved on too."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from numpy.typing import NDArray

from fxis_shm.wire import encoding as codec


class EncodeCache:
    def __init__(self, size: int = 64):
        self.size = size
        self._entries: OrderedDict[tuple[object, ...], bytes] = OrderedDict()
        self.encoded = self.reused = 0

    def get(
        self, frame: tuple[str, int, int], pixels: Callable[[], NDArray[Any]], encoding: str, quality: int | None
    ) -> bytes:
        """The frame ``frame`` = (camera, generation, frame_id) in ``encoding``; ``pixels()`` gives
        its image (checked whole), and is called only when the frame is not encoded yet."""
        quality = codec.DEFAULT_JPEG_QUALITY if quality is None else quality
        key = (*frame, encoding, quality if encoding == codec.JPEG else None)
        data = self._entries.get(key)
        if data is not None:
            self._entries.move_to_end(key)
            self.reused += 1
            return data
        data = codec.encode(pixels(), encoding, quality)
        self._entries[key] = data
        self.encoded += 1
        if len(self._entries) > self.size:
            self._entries.popitem(last=False)
        return data

    def status(self) -> dict[str, int]:
        return {"encoded": self.encoded, "reused": self.reused}
