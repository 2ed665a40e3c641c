"""One look at a camera's ring: the valid frames' timeline and what identifies each frame.

The slot record's layout (``SLOT``) is the ring's (fxis_shm.shm.ring), declared here so that
the request engine and the selection read snapshots, of a local ring or of another service's
frame list (fxis_shm.core.remotecamera), without importing shared memory.
"""

from __future__ import annotations

from dataclasses import dataclass

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
    ]
)


@dataclass(frozen=True)
class SlotMeta:
    frame_id: int
    t_capture: int
    t_stored: int
    t_available: int
    generation: int


@dataclass(frozen=True)
class Snapshot:
    """The valid frames of a ring at one moment: a timeline plus what identifies each frame."""

    timeline: Timeline  # over t_capture, oldest valid frame first
    first_write: int  # global write index of the timeline's logical index 0
    meta: np.ndarray  # copy of the slot table (SLOT records)

    def slot(self, i: int) -> int:
        return (self.first_write + i) % len(self.meta)  # logical index i is write first_write + i

    def seq(self, i: int) -> int:
        """The seq value the slot of logical index ``i`` must show for a valid copy."""
        return 2 * (self.first_write + i) + 2

    def frame_meta(self, i: int) -> SlotMeta:
        rec = self.meta[self.slot(i)]
        return SlotMeta(
            int(rec["frame_id"]),
            int(rec["t_capture"]),
            int(rec["t_stored"]),
            int(rec["t_available"]),
            int(rec["generation"]),
        )

    @property
    def newest(self) -> int | None:
        return self.timeline.at(len(self.timeline) - 1) if len(self.timeline) else None
