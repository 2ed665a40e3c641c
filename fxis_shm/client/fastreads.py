"""The same-host client's compiled read: ``image``, ``tuple`` at a given t* and ``latest``
answered by one C call (fxis_shm.shm.fastpick) that looks at the rings, decides as the engine
would and copies the frames, with little Python around it.

The request must be one the C twin of the engine's decision takes (``at`` given as int ns of the
service's clock, wait "auto" or "none", sync "joint" or "independent", no skew limit, no
encoding); anything else, and whatever the C call does not settle (a wait, an error to word,
a camera down, a ring replaced, a torn copy), returns None: the caller asks the engine
(fxis_shm.client.localreads), which answers as before.

A copy lands in an array of the C reader's pool, reused once nothing refers to it any more
(``Frame.release()`` drops the frame's reference): never while anyone can still read it.
"""

from __future__ import annotations

import builtins
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

from fxis_shm.client.frames import LOCAL, Frame, FrameTuple, FrameView, Validity
from fxis_shm.core.snapshot import CAPTURES
from fxis_shm.shm import fastpick
from fxis_shm.shm.ring import RingReader
from fxis_shm.wire.headers import CameraTiming, TimingRecord

POOLED_BYTES = 128 << 20  # the copies' arrays kept for reuse, at most (over all cameras)


class FastReads:
    """The rings of one service as the C reader sees them, with the engine's settings."""

    def __init__(self, names: Sequence[str], readers: Sequence[RingReader], settings: Mapping[str, Any], clock: str):
        self.picker = fastpick.Picker(names, readers, settings, clock, POOLED_BYTES)
        self.views = [r.slot_views() for r in readers]
        self._torn_told = 0

    def torn_since(self) -> int:
        """The copies found torn since the last call (the engine answered those requests)."""
        torn, self._torn_told = self.picker.torn - self._torn_told, self.picker.torn
        return torn

    @property
    def retired(self) -> bool:
        """A ring was replaced: make a new FastReads."""
        return self.picker.retired

    def image(self, camera: str, at: int | None, wait: str | None, copy: bool) -> Frame | None:
        got = self._frames((camera,), fastpick.IMAGE, at, None, wait, copy)
        return None if got is None else next(iter(got[0].values()))

    def tuple(
        self, cameras: list[str] | None, at: int | None, sync: str | None, wait: str | None, copy: bool
    ) -> FrameTuple[Frame] | None:
        got = self._frames(cameras, fastpick.TUPLE, at, sync, wait, copy)
        return None if got is None else FrameTuple(got[0], at, got[1])

    def latest(self, cameras: list[str] | None, copy: bool) -> FrameTuple[Frame] | None:
        got = self._frames(cameras, fastpick.LATEST, 0, None, None, copy)
        return None if got is None else FrameTuple(got[0], None, got[1])

    def _frames(
        self, cameras: Sequence[str] | None, op: int, at: int | None, sync: str | None, wait: str | None, copy: bool
    ) -> builtins.tuple[dict[str, Frame], TimingRecord] | None:
        """The frames by camera and the timing they share, or None: the engine must answer."""
        got = self.picker.pick(cameras, op, at, sync, wait, copy)
        if got is None:
            return None
        t_received, t_decided, t_copied, _, picked, indices, names = got
        ready: dict[str, CameraTiming] = {}
        timing: TimingRecord = {
            "received": t_received,
            "waited": t_received,
            "searched": t_decided,
            "copied": t_copied,
            "sent": t_copied,  # nothing is sent: the frames are the caller's once copied
            "cameras": ready,
        }
        frames: dict[str, Frame] = {}
        for k, name, picked_frame in zip(indices, names, picked):
            slot, seq, frame_id, t_capture, t_stored, t_available, generation, t_target, capture, ready_at, image = (
                picked_frame
            )
            ready[name] = {"waited": ready_at}
            still_valid: Validity | None = None
            if not copy:
                image = self.views[k][slot].view()
                still_valid = partial(self.picker.readers[k].slot_holds, slot, seq)
            frames[name] = (Frame if copy else FrameView)(
                image,
                name,
                frame_id,
                t_capture,
                t_stored,
                generation,
                timing,
                t_available,
                LOCAL,
                still_valid,
                "raw",
                t_capture,
                t_stored,
                t_available,
                CAPTURES[capture],
                t_target or None,
            )
        return frames, timing
