"""One look at a camera's ring: the valid frames' timeline and what identifies each frame.

The slot record's layout (``SLOT``) is the ring's (fxis_shm.shm.ring), declared here so that
the request engine and the selection read snapshots, of a local ring or of another service's
frame list (fxis_shm.core.remotecamera), without importing shared memory.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fxis_shm.core.timesearch import Timeline

SLOT = np.dtype(
    [
        ("seq", "<u8"),
        ("frame_id", "<u8"),
        ("t_capture", "<i8"),
        ("t_stored", "<i8"),
        ("t_available", "<i8"),
        ("generation", "<u8"),
        ("t_target", "<i8"),  # the moment the frame was triggered for (service clock), 0 if none
        ("capture", "<u8"),  # how it was captured: an index of CAPTURES
    ]
)
# Slot record ``capture`` values, by index: free-running (or triggered for "now"), triggered
# for a moment a caller named (trigger_at), triggered on the service's lockstep grid, triggered
# for a named moment and captured further from it than the camera's capture_tolerance_ms
# (core.schedule.captured_as).
CAPTURES = ("free", "scheduled", "lockstep", "late")
CAPTURE_FREE, CAPTURE_SCHEDULED, CAPTURE_LOCKSTEP, CAPTURE_LATE = range(4)


@dataclass(frozen=True)
class SlotMeta:
    frame_id: int
    t_capture: int
    t_stored: int
    t_available: int
    generation: int
    t_target: int = 0  # 0: not captured for a target moment (capture free)
    capture: int = CAPTURE_FREE


@dataclass(frozen=True)
class Snapshot:
    """The valid frames of a ring at one moment: a timeline plus what identifies each frame."""

    timeline: Timeline  # over t_capture, oldest valid frame first
    first_write: int  # global write index of the timeline's logical index 0
    rows: Sequence[SlotMeta | None]  # by physical slot: the frame each valid slot holds

    @classmethod
    def of_table(cls, timeline: Timeline, first_write: int, meta: Any) -> Snapshot:
        """A snapshot over a copy of a slot table (SLOT records; slots outside the timeline unread)."""
        count, slots = len(timeline), len(meta)
        rows: list[SlotMeta | None] = [None] * slots
        for w in range(first_write, first_write + count):
            rec = meta[w % slots]
            rows[w % slots] = SlotMeta(
                int(rec["frame_id"]),
                int(rec["t_capture"]),
                int(rec["t_stored"]),
                int(rec["t_available"]),
                int(rec["generation"]),
                int(rec["t_target"]),
                int(rec["capture"]),
            )
        return cls(timeline, first_write, rows)

    def slot(self, i: int) -> int:
        return (self.first_write + i) % len(self.rows)  # logical index i is write first_write + i

    def seq(self, i: int) -> int:
        """The seq value the slot of logical index ``i`` must show for a valid copy."""
        return 2 * (self.first_write + i) + 2

    def frame_meta(self, i: int) -> SlotMeta:
        row = self.rows[self.slot(i)]
        if row is None:
            raise IndexError(f"no frame at logical index {i} of a snapshot of {len(self.timeline)}")
        return row

    @property
    def newest(self) -> int | None:
        return self.timeline.at(len(self.timeline) - 1) if len(self.timeline) else None

    @property
    def newest_stored(self) -> int | None:
        """t_stored of the newest frame, None if there is none."""
        n = len(self.timeline)
        return self.frame_meta(n - 1).t_stored if n else None
