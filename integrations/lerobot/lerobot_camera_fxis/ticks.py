"""One client and one tuple per control tick for all the fxis cameras of a robot.

A ``TupleSource`` is shared by the cameras with the same endpoints, keys and sync mode (the
registry ``source_for``). The first camera read in a tick fetches one joint tuple of every
camera of the source; the others answer from it. A camera that already took its frame of the
current tuple starts the next tick: so a robot that reads its cameras in turn gets, for each
observation, frames chosen together by fxis (within its skew bound), across hosts too."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fxis_shm import Client, ClientKeys, FrameTuple

SourceKey = tuple[tuple[str, ...], str | None, str | None, str, float | None, float, float]


@dataclass(frozen=True)
class TickRecord:
    """What one tick's tuple was: each camera's capture time and frame id (capture times in
    the caller's clock, time.monotonic_ns), how it was captured, the tuple's skew and request
    time, and its number."""

    tick: int
    t_request: int | None
    skew_ns: int
    t_capture: dict[str, int] = field(default_factory=dict)
    frame_id: dict[str, int] = field(default_factory=dict)
    capture: dict[str, str] = field(default_factory=dict)  # "free", "scheduled" (capture at T) or "lockstep"
    t_target: dict[str, int | None] = field(default_factory=dict)  # the moment a scheduled frame was due


def capture_time_features(record: TickRecord, prefix: str = "observation.fxis") -> dict[str, int]:
    """The record as flat features for a LeRobot observation (int64 ns, caller's clock):
    ``observation.fxis.t_capture.CAM`` per camera and ``observation.fxis.skew_ns``."""
    features = {f"{prefix}.t_capture.{cam}": t for cam, t in record.t_capture.items()}
    features[f"{prefix}.skew_ns"] = record.skew_ns
    return features


class TupleSource:
    """The shared client of some fxis cameras and the tuple of the current tick."""

    def __init__(self, key: SourceKey, on_empty: Callable[[SourceKey], None]):
        self.key = key
        endpoints, server_key, client_key, self.sync, self.max_skew_ms, lead_ms, timeout_s = key
        keys = ClientKeys.from_files(server_key, client_key) if server_key and client_key else None
        target: str | list[str] = endpoints[0] if len(endpoints) == 1 else list(endpoints)
        self.client: Any = Client(target, timeout=timeout_s, keys=keys)
        self.capture_lead_ns = int(lead_ms * 1e6)
        self.members: set[str] = set()
        self._periods: dict[str, int] = {}  # each member's frame period, ns
        self.current: FrameTuple | None = None
        self.record: TickRecord | None = None
        self._taken: set[str] = set()
        self._ticks = 0
        self._lock = threading.Lock()
        self._on_empty = on_empty

    def join(self, camera: str, period_ns: int) -> None:
        """``camera`` is in every tuple from the next tick on, which starts with the next read."""
        with self._lock:
            self.members.add(camera)
            self._periods[camera] = period_ns
            self.current = None

    def leave(self, camera: str) -> None:
        with self._lock:
            self.members.discard(camera)
            self._periods.pop(camera, None)
            empty = not self.members
        if empty:
            self._on_empty(self.key)
            self.client.close()

    def take(self, camera: str, *, stored: bool, timeout_s: float | None) -> tuple[Any, TickRecord]:
        """``camera``'s frame of the current tick's tuple, fetching the next tuple first when
        ``camera`` already took its frame of this one (or there is none yet). ``stored``: the
        best tuple among the frames already stored (t* one period of the slowest camera ago:
        its frames are in the rings, so the request does not wait, and the skew is the least
        the phases allow); else the tuple of new frames nearest now (waits for them)."""
        with self._lock:
            if self.current is None or camera in self._taken or camera not in self.current:
                self._fetch(stored, timeout_s)
            self._taken.add(camera)
            assert self.current is not None and self.record is not None
            return self.current[camera], self.record

    def _fetch(self, stored: bool, timeout_s: float | None) -> None:
        cameras = sorted(self.members)
        now = self.client.clock()
        at, wait = (now - max(self._periods.values(), default=0), "auto") if stored else (now, "next")
        if self.sync == "capture":
            tuple_ = self.client.tuple(
                cameras, at=now + self.capture_lead_ns, capture=True, timeout=timeout_s, max_skew_ms=self.max_skew_ms
            )
        else:
            tuple_ = self.client.tuple(
                cameras, at=at, sync="joint", wait=wait, timeout=timeout_s, max_skew_ms=self.max_skew_ms
            )
        self._ticks += 1
        self.current = tuple_
        self._taken = set()
        self.record = TickRecord(
            tick=self._ticks,
            t_request=tuple_.t_request,
            skew_ns=tuple_.skew_ns,
            t_capture={cam: tuple_[cam].t_capture for cam in tuple_},
            frame_id={cam: tuple_[cam].frame_id for cam in tuple_},
            capture={cam: tuple_[cam].capture for cam in tuple_},
            t_target={cam: tuple_[cam].t_target for cam in tuple_},
        )


_SOURCES: dict[SourceKey, TupleSource] = {}
_SOURCES_LOCK = threading.Lock()


def source_for(key: SourceKey) -> TupleSource:
    """The source of ``key``, made by its first camera and closed when its last one leaves."""
    with _SOURCES_LOCK:
        if key not in _SOURCES:
            _SOURCES[key] = TupleSource(key, _forget)
        return _SOURCES[key]


def _forget(key: SourceKey) -> None:
    with _SOURCES_LOCK:
        _SOURCES.pop(key, None)
