"""Frame ids from the block ids GigE Vision and USB3 Vision cameras number their frames with."""

from __future__ import annotations

import logging

log = logging.getLogger("camera")

MAX_ID_GAP = 10_000  # a larger jump of the frame ids is a restarted count, not lost frames


class FrameCounter:
    """64-bit frame ids from a camera's block ids, and the frames missing before each.

    GigE Vision 1.x block ids are 16-bit and run 1..65535 (0 is reserved), so
    after 65535 comes 1. Ids that go back without wrapping, or jump by more than
    MAX_ID_GAP, restart the count: the ids keep increasing by one and nothing is
    counted as missing. Pure: no camera, no clock.
    """

    def __init__(self, wrap: int | None = 0xFFFF):
        self.wrap = wrap
        self._last_raw: int | None = None
        self.value = 0

    def next(self, raw: int) -> tuple[int, int]:
        """(64-bit id of the frame with block id ``raw``, frames missing just before it)."""
        last, self._last_raw = self._last_raw, raw
        if last is None:
            self.value = raw
            return raw, 0
        step = raw - last
        if self.wrap and step < -(self.wrap // 2) and raw <= self.wrap and last <= self.wrap:
            step += self.wrap  # 65535 -> 1 is one step
        if step <= 0 or step > MAX_ID_GAP:
            log.warning("frame ids jumped from %d to %d: the camera restarted its count", last, raw)
            step = 1
        self.value += step
        return self.value, step - 1
