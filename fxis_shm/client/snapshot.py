"""Snapshots: every frame of the chosen cameras captured in [t - before, t + after] into a
rosbag2/MCAP bag (the recorder's format, fxis_shm.formats.bagfile), for the event that arrives
late and asks what the cameras saw around it.

t is in the caller's clock, and so is every stamp in the bag (``Client(clock=...)``). The
window's past is taken from the rings at the first look; its future as the frames arrive,
each camera polled about twice a frame period, its frames copied out long before its ring
comes round. A frame the window should hold but the bag does not (the camera skipped its
id, or the ring came round first) is listed by id in the bag's metadata; a ring that no
longer held the window's start says how much of it was gone (and its frames, by the ids
the camera's period gives them, are missing too). Nothing is lost silently.

The bag is written under ``OUT.partial``, a folder this snapshot makes itself and locks
while it writes (one found there is never touched: a second snapshot to the same ``OUT``
refuses), and renamed to ``OUT`` when it ends, so a bag named ``OUT`` is always valid. Its
metadata's ``ended`` says whether it is complete or was interrupted (Ctrl-C:
``Interrupted``, a KeyboardInterrupt) or stopped by an error; either way it holds every
frame copied until then. A snapshot killed outright leaves ``OUT.partial``, which
``fxis snapshot --recover`` makes a bag. A window of which the rings held no frame writes
no bag (``out`` None): an empty one would say nothing more than the result does. Any number
of snapshots may run at once (each reads the rings like any client), also while the service
serves at full rate.

With ``video`` (``client.snapshot(codec="h264")``) each camera's frames are encoded by the
recorder's encoders (fxis_shm.formats.videoencoder) in the writer's thread, the window's
first frame a keyframe: the clip starts exactly at t - before.
"""

from __future__ import annotations

import fcntl
import json
import os
import queue
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol

from fxis_shm.client.frames import Frame
from fxis_shm.client.requestkeywords import SequenceKeywords
from fxis_shm.core import timebase
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import (
    CameraDown,
    Code,
    DiskFull,
    FxisError,
    InvalidArgument,
    Overwritten,
    ServiceError,
    UnknownCamera,
)
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagWriter
from fxis_shm.formats.outfolder import check_out_folder
from fxis_shm.formats.videoencoder import StreamEncoder
from fxis_shm.formats.videotracks import VideoPlan, VideoSettings, write_packets
from fxis_shm.wire import encoding as codec, ranges

if TYPE_CHECKING:
    from typing_extensions import Unpack  # (typing's own from Python 3.11)


class ServiceClient(Protocol):
    """What a snapshot asks of the client of a camera's service (a SingleClient: the clients
    import this module, so it is named by what it does)."""

    def frame_times(self, cameras: list[str] | None = None) -> dict[str, Any]: ...

    def clock_estimate(self) -> ClockEstimate: ...

    def status(self) -> dict[str, Any]: ...

    def sequence(
        self, kind: str, *, camera: str, copy: Literal[True] = True, **keywords: Unpack[SequenceKeywords]
    ) -> list[Frame]: ...


ID, T_CAPTURE, GENERATION = 0, 1, 4  # columns of a ``frames`` row
CHUNK = 16  # frames copied per request: bounds the memory a long window takes at once
GRACE_S = 2.0  # after t + after, how long a camera may take to show a frame past the window


@dataclass
class _Camera:
    """One camera's part of a snapshot, in its service's clock."""

    name: str
    client: ServiceClient  # of the camera's service
    start: int
    end: int
    last_t: int | None = None  # the newest capture time looked at
    last: tuple[int, int] | None = None  # (generation, frame id) of the newest frame looked at
    missing: list[int] = field(default_factory=list)
    gone_ms: float = 0.0  # the window's start the ring no longer held
    period_ns: int = 0
    past_end: bool = False  # a frame after the window was seen: nothing more to come

    def new_rows(self, info: dict[str, Any]) -> list[list[int]]:  # the camera's frame_times entry
        self.period_ns = info.get("period_ns") or self.period_ns
        rows = info.get("frames") or []
        if self.last_t is None and rows and rows[0][T_CAPTURE] > self.start:  # the first look
            self.gone_ms = (min(rows[0][T_CAPTURE], self.end) - self.start) / 1e6
            self.missing += lost_to_ring(rows[0], self.start, self.end, self.period_ns)
        if rows and rows[-1][T_CAPTURE] > self.end:
            self.past_end = True
        fresh = [r for r in rows if self.start <= r[T_CAPTURE] <= self.end]
        fresh = [r for r in fresh if self.last_t is None or r[T_CAPTURE] > self.last_t]
        for row in fresh:  # ids the camera or the ring skipped inside the window
            if self.last is not None and self.last[0] == row[GENERATION]:
                self.missing += range(self.last[1] + 1, row[ID])
            self.last, self.last_t = (row[GENERATION], row[ID]), row[T_CAPTURE]
        return fresh


def lost_to_ring(oldest: list[int], start: int, end: int, period_ns: int) -> list[int]:
    """The ids of the window's frames older than the ring's ``oldest`` row: those a camera of
    this period captured in [start, end] before it (estimated: a camera that dropped frames
    meanwhile captured fewer)."""
    if period_ns <= 0:
        return []
    t0, id0 = oldest[T_CAPTURE], oldest[ID]
    first_k = max(1, -(-(t0 - end) // period_ns))  # k periods before the oldest: inside the window
    last_k = (t0 - start) // period_ns
    return [id0 - k for k in range(last_k, first_k - 1, -1) if id0 - k >= 0]


def take(
    owners: Mapping[str, ServiceClient],
    clock: Callable[[], int],
    out: str,
    at: int | None = None,
    before: float = 2.0,
    after: float = 1.0,
    encoding: str = codec.RAW,
    quality: int | None = None,
    clock_name: str | None = None,
    video: VideoSettings | None = None,
) -> dict[str, Any]:
    """The snapshot of the cameras ``owners`` names (camera -> the client of its service)
    around ``at`` (ns of ``clock``, whose name ``clock_name`` is; default now) into the bag
    ``out``; what it holds. ``out`` is None if the rings held no frame of the window (no
    bag is written then: an empty bag would say nothing and reads badly). ``video``: each
    camera's frames as video instead (as ``fxis record --codec`` writes it), the window's
    first frame a keyframe."""
    _check(at, before, after, out, encoding, quality, video)
    now = clock()
    t = now if at is None else at
    if t - now > ranges.WINDOW_S.highest * 1e9:
        raise InvalidArgument(
            f"at is {(t - now) / 1e9:.0f} s from now: a snapshot's t is at most {ranges.WINDOW_S.highest:g} s ahead"
        )
    _check_cameras(owners, before)
    plan = _video_plan(owners, video)  # before anything is made: bad settings leave nothing behind
    out = os.path.normpath(out)
    partial = out + ".partial"
    lock = _claim(partial, out)
    window = (t - round(before * 1e9), t + round(after * 1e9))
    try:
        cameras = {name: _Camera(name, c, *_in_service_clock(c, window)) for name, c in owners.items()}
        stamps = "header.stamp: capture time in that clock"
        custom: dict[str, object] = {"clock": _clock_words(clock_name), "stamps": stamps}
        custom.update(event_ns=t, before_s=before, after_s=after, window_ns=f"{window[0]} {window[1]}")
        custom.update(cameras=",".join(cameras), encoding=video.codec if video else encoding)
        custom.update(missing="", gone_before_ms="", ended="")
        bag = BagWriter(partial, custom, file_stem=os.path.basename(out))
    except BaseException:
        _release(lock, partial, remove=True)  # nothing written yet: the folder made in this run goes
        raise
    writer = _Writer(bag, time.time_ns() - clock(), encoding, quality, plan)  # MCAP log times: wall-clock
    stopped: BaseException | None = None
    try:
        _follow(cameras, writer, clock, window[1] + round(GRACE_S * 1e9))
    except BaseException as exc:  # Ctrl-C, a service gone: what was copied is kept all the same
        stopped = exc
    try:
        writer.finish()
        summary = _summary(cameras, writer.written)
        bag.custom_data.update({key: json.dumps({n: s[key] for n, s in summary.items()}) for key in KEYS})
        bag.custom_data["ended"] = _ended(stopped)
        bag.close()
    except DiskFull as exc:
        raise _disk_full(exc, lock, partial, out) from None
    except KeyboardInterrupt:  # a second Ctrl-C while the bag was being closed: left as it is
        os.close(lock)
        raise Interrupted(
            f"interrupted while the bag was being closed: it stays unfinished in {partial}; "
            f"fxis snapshot --recover {partial} makes it the bag {out}",
            {"out": None, "event_ns": t, "window_ns": window, "cameras": _summary(cameras, writer.written)},
        ) from None
    except BaseException as exc:
        os.close(lock)
        raise FxisError(
            f"the snapshot's bag {partial} could not be finished ({exc!r}): "
            f"fxis snapshot --recover {partial} keeps what it holds"
        ) from exc
    kept = sum(writer.written.values())
    _release(lock, partial, remove=not kept)
    if kept:
        _move(partial, out)
    result = {"out": out if kept else None, "event_ns": t, "window_ns": window, "cameras": summary}
    if stopped is None:
        return result
    said = f"the snapshot kept {_kept_words(summary)} in {out}, a valid bag" if kept else "no frame was kept"
    if isinstance(stopped, KeyboardInterrupt):
        raise Interrupted(f"{_ended(stopped)}: {said}", result) from None
    if sys.version_info >= (3, 11):  # before, an exception has no notes
        stopped.add_note(said)
    raise stopped


KEYS = ("missing", "gone_before_ms")  # per camera, in the bag's metadata as JSON


class Interrupted(KeyboardInterrupt):
    """A snapshot stopped by Ctrl-C (KeyboardInterrupt; ``fxis snapshot`` makes SIGTERM one
    too): ``result`` is what ``take`` returns, its ``out`` a valid bag of every frame copied
    until then (its metadata's ``ended`` says it was interrupted), or None if none was."""

    def __init__(self, message: str, result: dict[str, Any]):
        super().__init__(message)
        self.result = result


def interrupted_by(exc: KeyboardInterrupt) -> str:
    """The signal a KeyboardInterrupt stands for: SIGTERM if a command raised it for one
    (its argument), else SIGINT (Ctrl-C)."""
    name = exc.args[0] if exc.args and isinstance(exc.args[0], str) else ""
    return name if name.startswith("SIG") else "SIGINT"


def _ended(stopped: BaseException | None) -> str:
    if stopped is None:
        return "complete"
    if isinstance(stopped, KeyboardInterrupt):
        return f"interrupted by {interrupted_by(stopped)}"
    return f"stopped by an error: {stopped}"


def _follow(cameras: dict[str, _Camera], writer: _Writer, clock: Callable[[], int], give_up: int) -> None:
    while True:  # at least one look: a window long past is taken from the rings at once
        began = time.monotonic()
        for cam in cameras.values():
            _poll(cam, writer)
        if all(c.past_end for c in cameras.values()) or clock() >= give_up:
            return
        time.sleep(max(0.0, _poll_s(cameras) - (time.monotonic() - began)))


def _summary(cameras: dict[str, _Camera], written: Counter[str]) -> dict[str, dict[str, Any]]:
    return {
        name: {
            "frames": written[name],
            "missing": sorted(c.missing),
            "gone_before_ms": round(c.gone_ms, 3),
            "complete": c.past_end,
        }
        for name, c in cameras.items()
    }


def _in_service_clock(client: ServiceClient, window: tuple[int, int]) -> tuple[int, int]:
    to_service = client.clock_estimate().to_service
    return to_service(window[0]), to_service(window[1])


def _kept_words(summary: dict[str, dict[str, Any]]) -> str:
    return ", ".join(f"{name} {kept['frames']} frames" for name, kept in summary.items())


def _clock_words(name: str | None) -> str:
    if name is None:
        return "the caller's own clock function (Client(clock=fn)): not one of the named clocks"
    return timebase.WIRE_NAMES[name]


def _claim(partial: str, out: str) -> int:
    """The snapshot's own ``partial`` folder, made here (never one found: it may hold an
    earlier snapshot's frames, or another's being written) and locked while it is written."""
    try:
        os.mkdir(partial)
    except FileExistsError:
        state = "another snapshot is writing it now" if _locked(partial) else "one that was stopped (killed?) left it"
        raise InvalidArgument(
            f"{partial} holds an unfinished snapshot ({state}); nothing was changed: "
            f"`fxis snapshot --recover {partial}` makes it the bag {out}, or remove it"
        ) from None
    except OSError as exc:
        raise InvalidArgument(f"out {out}: cannot make {partial}: {exc.strerror}") from None
    lock = os.open(partial, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the folder itself: the bag holds nothing else
    return lock


def _locked(partial: str) -> bool:
    try:
        fd = os.open(partial, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def _release(lock: int, partial: str, remove: bool) -> None:
    """Unlock; ``remove``: the folder too, if it holds nothing but what this run wrote and no frame."""
    os.close(lock)
    if remove:
        for name in os.listdir(partial):  # the empty bag's own files (this run's)
            os.remove(os.path.join(partial, name))
        os.rmdir(partial)


def _move(partial: str, out: str) -> None:
    try:
        os.rename(partial, out)  # onto nothing, or onto an empty folder
    except OSError as exc:
        raise FxisError(f"{out}: {exc.strerror}: the snapshot is kept, whole, in {partial}") from None


def _disk_full(exc: DiskFull, lock: int, partial: str, out: str) -> DiskFull:
    _release(lock, partial, remove=False)
    if not exc.valid:  # the bag could not be closed: it stays unfinished, for --recover
        return DiskFull(f"{exc} (the snapshot's bag: {partial})", **{k: getattr(exc, k) for k in DISK_FULL_FIELDS})
    _move(partial, out)  # the bag was closed whole up to its last message
    kept = ", ".join(f"{topic} {n}" for topic, n in exc.kept.items())
    return DiskFull(
        f"{exc.reason or 'the disk is full'}: the snapshot stopped and kept {kept} in {out}, a valid bag",
        **{**{k: getattr(exc, k) for k in DISK_FULL_FIELDS}, "folder": out},
    )


DISK_FULL_FIELDS = ("folder", "reason", "kept", "seconds", "file_bytes", "valid")


def _video_plan(owners: Mapping[str, ServiceClient], video: VideoSettings | None) -> VideoPlan | None:
    if video is None:
        return None
    return VideoPlan.make(video, {name: c.status()["cameras"][name] for name, c in owners.items()})


def _check(
    at: int | None,
    before: float,
    after: float,
    out: str,
    encoding: str,
    quality: int | None,
    video: VideoSettings | None,
) -> None:
    for name, value in (("before", before), ("after", after)):
        ranges.WINDOW_S.check(value, name)
    if before + after <= 0:
        raise InvalidArgument("a snapshot needs a window: before + after must be > 0")
    if at is not None:
        ranges.AT_NS.check(at, "at")
    if encoding not in (codec.RAW, codec.JPEG):
        raise InvalidArgument(f"encoding must be raw or jpeg (images) or h264, h265, av1 (video), got {encoding!r}")
    if video is not None and (encoding != codec.RAW or quality is not None):
        raise InvalidArgument(f"codec {video.codec} writes video: it takes no encoding {encoding} or quality")
    check_out_folder(out)


def _check_cameras(owners: Mapping[str, ServiceClient], before: float) -> None:
    """UnknownCamera for a camera its service lacks; InvalidArgument if ``before`` is longer
    than any of the cameras' rings holds (their ``history_s``, as their services' status
    says: O(1), before a frame is looked at)."""
    held: dict[str, float] = {}
    for client in {id(c): c for c in owners.values()}.values():
        cameras = client.status()["cameras"]
        unknown = [name for name, owner in owners.items() if owner is client and name not in cameras]
        if unknown:  # before the bag is begun: nothing made, one line
            raise UnknownCamera(Code.UNKNOWN_CAMERA, f"unknown camera(s) {unknown}; known: {sorted(cameras)}")
        held.update({name: cameras[name]["history_s"] for name in owners if cameras.get(name, {}).get("history_s")})
    if held and before > max(held.values()):
        rings = ", ".join(f"{name} {seconds:g} s" for name, seconds in held.items())
        raise InvalidArgument(
            f"before {before:g} s: the rings hold at most {max(held.values()):g} s ({rings}); give a shorter "
            "before, or run the service with a longer --history"
        )


def _poll_s(cameras: dict[str, _Camera]) -> float:
    """About half the shortest frame period, within 5 ms .. 100 ms."""
    periods = [c.period_ns / 1e9 for c in cameras.values() if c.period_ns > 0]
    return min(0.1, max(0.005, min(periods, default=0.1) / 2))


class _Writer:
    """Writes the copied frames into the bag in a thread of its own, so that copying the
    window's past out of every camera's ring never waits for the disk (or an encoder): each
    ring is emptied of the window's frames within milliseconds, long before it comes round.
    With a video ``plan``, each camera's frames go through an encoder of its own, every one
    of them (a snapshot skips none), its first a keyframe."""

    def __init__(self, bag: BagWriter, to_realtime: int, encoding: str, quality: int | None, plan: VideoPlan | None):
        self.bag, self.to_realtime, self.encoding, self.quality = bag, to_realtime, encoding, quality
        self.plan = plan
        self._encoders: dict[str, StreamEncoder] = {}
        self._frames: queue.Queue[Frame | None] = queue.Queue()
        self._error: BaseException | None = None
        # counted here, once in the bag: a frame put just before Ctrl-C is still written, and counted
        self.written: Counter[str] = Counter()
        self._thread = threading.Thread(target=self._run, name="snapshot-writer", daemon=True)
        self._thread.start()

    def put(self, frame: Frame) -> None:
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
                    self._write(frame)
                self.written[frame.camera] += 1
            except BaseException as exc:  # a full disk: the snapshot stops and says so
                self._error = exc
        if self.plan is not None and self._error is None:
            try:  # the encoders' last frames
                for cam, encoder in self._encoders.items():
                    write_packets(self.bag, cam, self.plan.choice.codec, encoder.finish(), self.to_realtime)
            except BaseException as exc:
                self._error = exc

    def _write(self, frame: Frame) -> None:
        if self.plan is None:
            topic, msgtype, message, size = rosmsgs.frame_message(frame, frame.t_capture, self.encoding, self.quality)
            self.bag.write(topic, msgtype, message, frame.t_capture + self.to_realtime, size)
            return
        if frame.camera not in self._encoders:
            self._encoders[frame.camera] = self.plan.stream_encoder(frame.camera)
        packets = self._encoders[frame.camera].encode(frame.image, frame.t_capture, frame.frame_id, frame.generation)
        write_packets(self.bag, frame.camera, self.plan.choice.codec, packets, self.to_realtime)


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
