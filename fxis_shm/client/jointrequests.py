"""Requests answered across several services: the cameras of all of them as one set, frames
chosen with the same request engine, joint selection and wait policy as on one service.

For each request the client asks every service concerned for its cameras' frame times
(the ``frames`` op: no pixels), moves them into the caller's clock, runs the request
engine (fxis_shm.core.engine) over them itself, and then fetches the chosen frames from all
services at once. Waiting for frames still to come is done here too: the client sleeps
until the next frame of a camera it waits for is due, and looks again. A software-triggered
camera is fired by its own service (a request for it there), and the frames that request
brings are kept for the fetch.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, cast

from fxis_shm.client.frames import LOCAL, NETWORK, Answer, Frame, Validity
from fxis_shm.client.localreads import settled
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.client.single import SingleClient
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.core.engine import Reply, RequestEngine, Trigger
from fxis_shm.core.remotecamera import RemoteCamera
from fxis_shm.errors import Code, FxisError, Overwritten, RequestTimeout, ServiceError
from fxis_shm.wire import framemeta, protocol
from fxis_shm.wire.headers import FrameMeta, ReplyHeader

LOOK_AGAIN_NS = 1_000_000  # after a frame was due, look for it this often
SILENT_FOR_S = 1.0  # a service that did not answer is probed this often until it answers again
PROBE_TIMEOUT_S = 1.0  # a probe's own timeout: closing the client waits for a probe at most this long

Fetched = dict[tuple[str, int], Frame]  # (camera, frame id) -> the frame as its service sent it


class JointRequests:
    """The engine over the cameras of ``owner`` (camera -> the client of its service)."""

    def __init__(self, owner: dict[str, SingleClient], clock: Callable[[], int], timeout: float):
        self.owner, self.clock, self.timeout = owner, clock, timeout
        self.clients = list(dict.fromkeys(owner.values()))
        self.cameras = {name: RemoteCamera(name, c.endpoint) for name, c in owner.items()}
        self.engine = RequestEngine(self.cameras)
        self._pool = ThreadPoolExecutor(max_workers=max(1, len(self.clients)), thread_name_prefix="fxis-multi")
        self._silent: dict[SingleClient, Future[bool]] = {}  # services that did not answer: the probe asking again
        self._probes = ThreadPoolExecutor(max_workers=max(1, len(self.clients)), thread_name_prefix="fxis-probe")
        self._twins: dict[SingleClient, SingleClient] = {}

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        self._probes.shutdown(wait=True, cancel_futures=True)  # a probe ends within PROBE_TIMEOUT_S
        for twin in self._twins.values():
            twin.close()

    def answer(self, op: str, options: RequestOptions, **fields: Any) -> Answer:
        """The reply header (times in the caller's clock), images and validity check of one request."""
        request = protocol.request_of(op, id=None, timeout_ms=options.timeout_ms, **fields)
        if request.get("capture"):
            return self._captured(request, options)
        asked = self.clock()  # "now" is when the caller asked, not when the services answered
        names = self._names(request)
        self._describe(names)  # bounded by each client's timeout; a silent service is down
        now = self.clock()
        wait_s = max(self.timeout, (request.get("timeout_ms") or 0) / 1e3)
        if request.get("at") is not None:
            wait_s += max(0, request["at"] - now) / 1e9
        deadline = now + int(wait_s * 1e9)
        fetch = _Fetch(options)
        actions = self.engine.submit(request, asked, ticket=op)
        while True:
            self._fire([a for a in actions if isinstance(a, Trigger)], fetch)
            reply = settled(actions)
            if reply is not None:
                try:
                    return self._fetch(reply, fetch)
                except Overwritten:  # the engine plans again, a few times at most
                    self._describe(names)
                    actions = self.engine.retry(reply, self.clock())
                    continue
            now = self.clock()
            if now >= deadline:
                self.engine.cancel_all()
                raise RequestTimeout(f"no answer to {op!r} from {len(self.clients)} services within the timeout")
            waiting = {c for p in self.engine.pending for c in p.cameras}
            due = [self.cameras[c].next_stored() for c in waiting]
            wake = min(
                [deadline, self.engine.next_wake() or deadline, *(t + LOOK_AGAIN_NS for t in due if t is not None)]
            )
            time.sleep(max(0, wake - now) / 1e9)
            self._describe(waiting)
            actions = self.engine.on_frames(waiting, self.clock())

    def _names(self, request: protocol.Request) -> list[str]:
        """The cameras the request reads (those unknown are the engine's to refuse)."""
        names = request.get("cameras") or ([request["camera"]] if request.get("camera") else list(self.cameras))
        return [n for n in names if n in self.cameras]

    def _describe(self, names: Iterable[str]) -> None:
        """Ask every service concerned, at once, for its cameras' frame times. A service that
        did not answer is left out (its cameras down) until a probe of its own finds it back:
        waiting for it in every request would let the other services' frames leave their
        rings meanwhile, and hold a tuple stream up by a timeout at every look."""
        by_client: dict[SingleClient, list[str]] = {}
        for name in names:
            client = self.owner[name]
            if self._answers_again(client):
                by_client.setdefault(client, []).append(name)
        for client, described in zip(by_client, self._pool.map(_frame_times, by_client, by_client.values())):
            if isinstance(described, Exception):
                self._silent[client] = self._probes.submit(_probe, self._twin(client))
            for name in by_client[client]:
                if isinstance(described, Exception):
                    self.cameras[name].unreachable(f"at {client.endpoint} does not answer ({described})")
                else:
                    times, estimate = described
                    now = self.clock()  # the offset now: over a ring's span, drift moves it by microseconds
                    self.cameras[name].describe(
                        times["cameras"][name], times["columns"], estimate.to_service(now) - now
                    )

    def _answers_again(self, client: SingleClient) -> bool:
        """False while ``client``'s service is silent (its probe, started again when it fails, has
        not had an answer yet)."""
        probe = self._silent.get(client)
        if probe is None:
            return True
        if not probe.done():
            return False
        if probe.result():
            del self._silent[client]
            return True
        self._silent[client] = self._probes.submit(_probe, self._twin(client))
        return False

    def _twin(self, client: SingleClient) -> SingleClient:
        """A client of the same service for probes only (a socket is used by one thread)."""
        if client not in self._twins:
            self._twins[client] = SingleClient(
                client.endpoint,
                PROBE_TIMEOUT_S,
                client._context,
                client._keys,
                "off",
                clock=client.clock,
            )
        return self._twins[client]

    def _fire(self, triggers: list[Trigger], fetch: _Fetch) -> None:
        """Fire software triggers: each service a request for its triggered cameras, all at
        once; the triggered frames it answers are kept for the fetch. The engine then sees
        them stored after the trigger, as on one service."""
        by_client: dict[SingleClient, list[str]] = {}
        for trigger in triggers:
            for cam in trigger.cameras:
                by_client.setdefault(self.owner[cam], []).append(cam)
        for group in self._pool.map(fetch.triggered, by_client, by_client.values()):
            if isinstance(group, FxisError):
                raise group
            fetch.kept.update(group)
        if by_client:
            self._describe([c for cams in by_client.values() for c in cams])

    def _fetch(self, reply: Reply, fetch: _Fetch) -> Answer:
        """The reply header, images and validity check of a plan: each chosen frame fetched
        from its service, the services at once (each client by one thread: a socket is not shared)."""
        picks = list(dict.fromkeys(reply.plan.picks))  # each distinct frame once
        by_client: dict[SingleClient, list[tuple[str, dict[str, int]]]] = {}
        for cam, i in picks:
            row = self.cameras[cam].service_row(i)
            if (cam, row["frame_id"]) not in fetch.kept:
                by_client.setdefault(self.owner[cam], []).append((cam, row))
        for group in self._pool.map(fetch.chosen, by_client, by_client.values()):
            fetch.kept.update(group)
        chosen = [fetch.kept[cam, self.cameras[cam].service_row(i)["frame_id"]] for cam, i in picks]
        position = {pick: k for k, pick in enumerate(picks)}
        # the plan's body is the engine's JSON-bound dict: the fields of a reply (docs/protocol.md 7)
        header = cast(
            ReplyHeader,
            {**reply.plan.body, "timing": {"received": reply.pending.t_received, "waited": reply.t_decided}},
        )
        if reply.plan.groups is not None:
            header["groups"] = [[position[pick] for pick in group] for group in reply.plan.groups]
        return _joined(header, chosen)

    def _captured(self, request: protocol.Request, options: RequestOptions) -> Answer:
        """A capture at T (``request["at"]``, the caller's clock) on several services: each service
        triggers its cameras that can be triggered for T, in its own clock, and answers for the
        others with their frames nearest T; the services are asked at once."""
        asked = self.clock()
        names = self._names(request)
        by_client: dict[SingleClient, list[str]] = {}
        for name in names:
            by_client.setdefault(self.owner[name], []).append(name)
        tuples = list(
            self._pool.map(
                lambda client, cams: client.tuple(
                    cams,
                    at=request["at"],
                    capture=True,
                    timeout=options.timeout,
                    copy=options.copy,
                    encoding=options.encoding,
                    quality=options.quality,
                ),
                by_client,
                by_client.values(),
            )
        )
        frames = [t[name] for t, cams in zip(tuples, by_client.values()) for name in cams]
        # a reply the client makes itself: no envelope (v, id, ok), only what frames_of reads
        header = cast(ReplyHeader, {"op": request["op"], "t_request": request["at"]})
        if request["op"] == "tuple":
            times = [f.t_capture for f in frames]
            header["skew_ns"] = max(times) - min(times)
            header["sync"] = request.get("sync") or "joint"
        header["timing"] = {"received": asked, "waited": self.clock()}
        return _joined(header, frames)


class _Fetch:
    """How one request's frames are fetched (copied or viewed, encoded), and those fetched so far."""

    def __init__(self, options: RequestOptions):
        self.options = options
        self.kept: Fetched = {}

    def chosen(self, client: SingleClient, wanted: list[tuple[str, dict[str, int]]]) -> Fetched:
        """The frames ``wanted`` of one service, by (camera, frame id); Overwritten if one is gone."""
        fetched: Fetched = {}
        o = self.options
        for cam, row in wanted:
            try:
                frame = client.image(
                    cam, at=row["t_capture"], wait="none", copy=o.copy, encoding=o.encoding, quality=o.quality
                )
            except ServiceError as exc:
                if exc.code != Code.OUT_OF_RANGE:
                    raise
                raise Overwritten(
                    f"frame {row['frame_id']} of {cam!r} left its ring before it could be fetched"
                ) from None
            if frame.frame_id != row["frame_id"] or frame.generation != row["generation"]:
                raise Overwritten(f"frame {row['frame_id']} of {cam!r} left its ring before it could be fetched")
            fetched[cam, frame.frame_id] = frame
        return fetched

    def triggered(self, client: SingleClient, cameras: list[str]) -> Fetched | FxisError:
        """Fire the triggers of ``cameras`` of one service (a tuple request without ``at``
        there) and keep the frames it answers."""
        try:
            o = self.options
            frames = client.tuple(cameras, copy=o.copy, encoding=o.encoding, quality=o.quality)
        except FxisError as exc:
            return exc
        return {(cam, f.frame_id): f for cam, f in frames.items()}


def _frame_times(client: SingleClient, names: list[str]) -> tuple[dict[str, Any], ClockEstimate] | Exception:
    """The service's frame times of ``names`` and its clock estimate (the first one asks the
    service too), or why it did not answer."""
    try:
        return client.frame_times(names), client.clock_estimate()
    except FxisError as exc:
        return exc


def _probe(twin: SingleClient) -> bool:
    """Whether a silent service answers again, asked after a pause."""
    time.sleep(SILENT_FOR_S)
    try:
        twin.status()
    except FxisError:
        return False
    return True


def _joined(header: ReplyHeader, chosen: list[Frame]) -> Answer:
    """The reply of frames fetched from their services: ``header`` with each frame's metadata (the
    caller's clock, the service's own times kept), the images, and a validity check for views."""
    frames: list[FrameMeta] = []
    for k, frame in enumerate(chosen):
        meta = framemeta.frame_meta(
            frame.camera,
            frame.frame_id,
            frame.t_capture,
            frame.t_stored,
            frame.generation,
            frame.image,
            k,
            frame.t_available,
            frame.t_target,
            frame.capture,
        )
        frames.append(
            {
                **meta,
                "encoding": frame.encoding,
                "service_t_capture": frame.service_t_capture,
                "service_t_stored": frame.service_t_stored,
                "service_t_available": frame.service_t_available,
            }
        )
    header = {
        **header,
        "frames": frames,
        "path": LOCAL if chosen and all(f.path == LOCAL for f in chosen) else NETWORK,
    }
    views = [f for f in chosen if f._still_valid is not None]
    check: Validity | None = (lambda: all(f.still_valid() for f in views)) if views else None
    return header, [f.image for f in chosen], check
