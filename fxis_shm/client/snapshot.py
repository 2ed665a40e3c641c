"""Snapshots: every frame of the chosen cameras captured in [t - before, t + after] into a
rosbag2/MCAP bag (the recorder's format, fxis_shm.formats.bagfile), for the event that arrives
late and asks what the cameras saw around it.

t is in the caller's clock, and so is every stamp in the bag (``Client(clock=...)``). The
window's past is taken from the rings at the first look; its future as the frames arrive,
each camera polled about twice a frame period, its frames copied out long before its ring
comes round. A frame the window should hold but the bag does not (the camera skipped its
id, or the ring came round first) is listed by id in the bag's metadata; a ring that no
longer held the window's start says how much of it was gone. Nothing is lost silently.

The bag is written under ``OUT.partial`` and renamed to ``OUT`` once complete, so a bag
named ``OUT`` is always whole. Any number of snapshots may run at once (each reads the rings
like any client), also while the service serves at full rate.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import queue
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fxis_shm.errors import CameraDown, DiskFull, InvalidArgument, Overwritten, ServiceError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagWriter
from fxis_shm.formats.outfolder import check_out_folder
from fxis_shm.wire import encoding as codec

ID, T_CAPTURE, GENERATION = 0, 1, 4  # columns of a ``frames`` row
CHUNK = 16  # frames copied per request: bounds the memory a long window takes at once
GRACE_S = 2.0  # after t + after, how long a camera may take to show a frame past the window


@dataclass
class _Camera:
    """One camera's part of a snapshot, in its service's clock."""

    name: str
    client: Any  # a single-service client (its frame_times, sequence, clock_estimate)
    start: int
    end: int
    last_t: int | None = None  # the newest capture time looked at
    last: tuple[int, int] | None = None  # (generation, frame id) of the newest frame looked at
    taken: int = 0
    missing: list[int] = field(default_factory=list)
    gone_ms: float = 0.0  # the window's start the ring no longer held
    period_ns: int = 0
    past_end: bool = False  # a frame after the window was seen: nothing more to come

    def new_rows(self, info: dict) -> list[list[int]]:
        self.period_ns = info.get("period_ns") or self.period_ns
        rows = info.get("frames") or []
        if self.last_t is None and rows and rows[0][T_CAPTURE] > self.start:
            self.gone_ms = (rows[0][T_CAPTURE] - self.start) / 1e6
        if rows and rows[-1][T_CAPTURE] > self.end:
            self.past_end = True
        fresh = [r for r in rows if self.start <= r[T_CAPTURE] <= self.end]
        fresh = [r for r in fresh if self.last_t is None or r[T_CAPTURE] > self.last_t]
        for row in fresh:  # ids the camera or the ring skipped inside the window
            if self.last is not None and self.last[0] == row[GENERATION]:
                self.missing += range(self.last[1] + 1, row[ID])
            self.last, self.last_t = (row[GENERATION], row[ID]), row[T_CAPTURE]
        return fresh


def take(
    owners: dict[str, Any],
    clock: Callable[[], int],
    out: str,
    at: int | None = None,
    before: float = 2.0,
    after: float = 1.0,
    encoding: str = codec.RAW,
    quality: int | None = None,
) -> dict:
    """The snapshot of the cameras ``owners`` names (camera -> the client of its service)
    around ``at`` (ns of ``clock``, default now) into the bag ``out``; what it holds."""
    t = clock() if at is None else at
    _check(at, before, after, out, encoding)
    partial = os.path.normpath(out) + ".partial"
    shutil.rmtree(partial, ignore_errors=True)  # an earlier snapshot that did not finish
    window = (t - round(before * 1e9), t + round(after * 1e9))
    cameras = {name: _Camera(name, c, *map(c.clock_estimate().to_service, window)) for name, c in owners.items()}
    custom = {"clock": "the caller's (Client(clock=...))", "stamps": "header.stamp: capture time in that clock"}
    custom.update(event_ns=t, before_s=before, after_s=after, window_ns=f"{window[0]} {window[1]}")
    bag = BagWriter(partial, {**custom, "cameras": ",".join(cameras), "encoding": encoding})
    writer = _Writer(bag, time.time_ns() - clock(), encoding, quality)  # MCAP log times: wall-clock
    try:
        give_up = window[1] + round(GRACE_S * 1e9)
        while True:  # at least one look: a window long past is taken from the rings at once
            began = time.monotonic()
            for cam in cameras.values():
                _poll(cam, writer)
            if all(c.past_end for c in cameras.values()) or clock() >= give_up:
                break
            time.sleep(max(0.0, _poll_s(cameras) - (time.monotonic() - began)))
        writer.finish()
    except BaseException as exc:
        with contextlib.suppress(BaseException):
            writer.finish()  # stops the writer; its own error is the one being raised
        if isinstance(exc, DiskFull) and exc.valid:  # the bag was closed whole up to its last message
            os.rename(partial, out)
            kept = ", ".join(f"{topic} {n}" for topic, n in exc.kept.items())
            raise DiskFull(
                f"{exc.reason or 'the disk is full'}: the snapshot stopped and kept {kept} in {out}, a valid bag",
                folder=out,
                reason=exc.reason,
                kept=exc.kept,
                seconds=exc.seconds,
                file_bytes=exc.file_bytes,
            ) from None
        bag.close()
        shutil.rmtree(partial, ignore_errors=True)
        raise
    summary = {
        name: {"frames": c.taken, "missing": c.missing, "gone_before_ms": round(c.gone_ms, 3), "complete": c.past_end}
        for name, c in cameras.items()
    }
    bag.custom_data["missing"] = json.dumps({n: s["missing"] for n, s in summary.items()})
    bag.custom_data["gone_before_ms"] = json.dumps({n: s["gone_before_ms"] for n, s in summary.items()})
    bag.close()
    os.rename(partial, out)
    return {"out": out, "event_ns": t, "window_ns": window, "cameras": summary}


def _check(at, before, after, out, encoding) -> None:
    for name, value in (("before", before), ("after", after)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise InvalidArgument(f"{name} must be seconds >= 0, got {value!r}")
    if before + after <= 0:
        raise InvalidArgument("a snapshot needs a window: before + after must be > 0")
    if at is not None and (isinstance(at, bool) or not isinstance(at, int)):
        raise InvalidArgument(f"at must be int ns of the caller's clock, got {at!r}")
    if encoding not in (codec.RAW, codec.JPEG):
        raise InvalidArgument(f"encoding must be raw or jpeg, got {encoding!r}")
    check_out_folder(out)


def _poll_s(cameras: dict[str, _Camera]) -> float:
    """About half the shortest frame period, within 5 ms .. 100 ms."""
    periods = [c.period_ns / 1e9 for c in cameras.values() if c.period_ns > 0]
    return min(0.1, max(0.005, min(periods, default=0.1) / 2))


class _Writer:
    """Writes the copied frames into the bag in a thread of its own, so that copying the
    window's past out of every camera's ring never waits for the disk: each ring is emptied
    of the window's frames within milliseconds, long before it comes round."""

    def __init__(self, bag: BagWriter, to_realtime: int, encoding: str, quality: int | None):
        self.bag, self.to_realtime, self.encoding, self.quality = bag, to_realtime, encoding, quality
        self._frames: queue.Queue = queue.Queue()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="snapshot-writer", daemon=True)
        self._thread.start()

    def put(self, frame) -> None:
        if self._error is not None:
            raise self._error
        self._frames.put(frame)

    def finish(self) -> None:
        """Every frame put is in the bag (or the writer's error is raised)."""
        self._frames.put(None)
        self._thread.join()
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        while (frame := self._frames.get()) is not None:
            if self._error is not None:
                continue  # drain: the error is raised to the caller
            try:
                with frame:
                    topic, msgtype, message, size = rosmsgs.frame_message(
                        frame, frame.t_capture, self.encoding, self.quality
                    )
                    self.bag.write(topic, msgtype, message, frame.t_capture + self.to_realtime, size)
            except BaseException as exc:  # a full disk: the snapshot stops and says so
                self._error = exc


def _poll(cam: _Camera, writer: _Writer) -> None:
    if cam.past_end:
        return
    try:
        info = cam.client.frame_times([cam.name])["cameras"][cam.name]
    except CameraDown:
        return  # its worker restarts it; the frames after the outage are taken then
    rows = cam.new_rows(info)
    mapping = cam.client.clock_estimate()
    for i in range(0, len(rows), CHUNK):
        chunk = rows[i : i + CHUNK]
        wanted = {r[ID] for r in chunk}
        try:
            frames = cam.client.sequence(
                "range",
                camera=cam.name,
                start=mapping.to_caller(chunk[0][T_CAPTURE]),
                end=mapping.to_caller(chunk[-1][T_CAPTURE]),
            )
        except (Overwritten, ServiceError) as exc:
            if not (isinstance(exc, (Overwritten, CameraDown)) or getattr(exc, "code", None) == "OUT_OF_RANGE"):
                raise
            frames = []  # the ring came round between the listing and the copy
        got = {f.frame_id for f in frames if f.frame_id in wanted}
        cam.missing += sorted(wanted - got)
        for frame in frames:
            if frame.frame_id in got:
                writer.put(frame)
                cam.taken += 1
