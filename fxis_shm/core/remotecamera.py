"""A camera of another service, as the request engine reads it: its frames as the
service's ``frames`` op last described them, with every time moved into the caller's
clock, so one engine can choose frames across services whose clocks differ.

Pure: a ``frames`` reply and a clock offset in; snapshots and camera states out.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fxis_shm.core.snapshot import SLOT, Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import CameraState

_TIMES = ("t_capture", "t_stored", "t_available")


class RemoteCamera:
    """One camera of one service (``service``: its endpoint, for messages)."""

    def __init__(self, name: str, service: str):
        self.name, self.service = name, service
        self.offset_ns = 0  # the service's clock minus the caller's, when last described
        self._info: dict[str, Any] = {"alive": False, "reason": f"camera {name!r} was not described yet", "frames": []}
        self._snapshot = _snapshot_of([], [], 0)

    def describe(self, info: dict[str, Any], columns: list[str], offset_ns: int) -> None:
        """Take the service's latest description of the camera (one ``frames`` entry)."""
        self._info, self.offset_ns = info, offset_ns
        self._snapshot = _snapshot_of(info.get("frames", []), columns, offset_ns)

    def unreachable(self, why: str) -> None:
        """The service did not answer: the camera counts as down until it does."""
        self._info = {
            **self._info,
            "alive": False,
            "reason": f"camera {self.name!r} is down: its service {self.service} {why}",
        }

    def service_row(self, i: int) -> dict[str, int]:
        """Frame ``i`` of the last snapshot: its id, generation and times (the caller's clock)."""
        rec = self._snapshot.frame_meta(i)  # logical index i is slot i here
        return {k: int(getattr(rec, k)) for k in ("frame_id", "generation", *_TIMES)}

    # ---- what the request engine reads (fxis_shm.core.engine.CameraSource) ----

    def down_reason(self, now: int) -> str | None:
        if self._info.get("alive"):
            return None
        return self._info.get("reason") or f"camera {self.name!r} of {self.service} is down"

    def snapshot(self) -> Snapshot:
        return self._snapshot

    def state(self, snapshot: Snapshot) -> CameraState:
        return CameraState(
            newest=snapshot.newest,
            period_ns=self.period_ns,
            delay_ns=int(self._info.get("delay_ns", 0)),
            newest_stored=snapshot.newest_stored,
            triggered=self.triggered,
        )

    @property
    def period_ns(self) -> int:
        return int(self._info.get("period_ns", 0))

    @property
    def triggered(self) -> bool:
        return bool(self._info.get("triggered", False))

    @property
    def slots(self) -> int | None:
        return self._info.get("slots")

    def next_stored(self) -> int | None:
        """When (caller's clock) the camera's next frame should be stored, if it streams."""
        n = len(self._snapshot.timeline)
        if not n or self.period_ns <= 0:
            return None
        return int(self._snapshot.frame_meta(n - 1).t_stored) + self.period_ns


def _snapshot_of(rows: list[list[int]], columns: list[str], offset_ns: int) -> Snapshot:
    """A snapshot over the described frames (oldest first), times in the caller's clock.
    Its slot table holds exactly these frames, so logical index i is slot i."""
    meta = np.zeros(len(rows), dtype=SLOT)
    if rows:
        table = np.asarray(rows, dtype=np.int64)
        for k, column in enumerate(columns):
            meta[column] = table[:, k] - (offset_ns if column in _TIMES else 0)
    meta["seq"] = 2 * np.arange(len(rows)) + 2
    return Snapshot.of_table(Timeline(meta["t_capture"].tolist(), 0, len(rows)), 0, meta)
