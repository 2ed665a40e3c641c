"""One client over several services: the cameras of all of them as one set, and tuples
chosen across hosts with the same joint selection and wait policy as on one.

For each request the client asks every service concerned for its cameras' frame times
(the ``frames`` op: no pixels), moves them into the caller's clock, runs the request
engine (fxis_shm.core.engine) over them itself, and then fetches the chosen frames from all
services at once. Waiting for frames still to come is done here too: the client sleeps
until the next frame of a camera it waits for is due, and looks again.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

from fxis_shm.client import snapshot
from fxis_shm.client.frames import FrameTuple, frames_of, sequence_of, tuple_of
from fxis_shm.client.localreads import settled
from fxis_shm.client.single import SingleClient
from fxis_shm.client.sockets import wire_timeout_ms
from fxis_shm.core.engine import Reply, RequestEngine
from fxis_shm.core.remotecamera import RemoteCamera
from fxis_shm.errors import Code, ConfigError, FxisError, Overwritten, RequestTimeout, ServiceError
from fxis_shm.wire import protocol

LOOK_AGAIN_NS = 1_000_000  # after a frame was due, look for it this often
SILENT_FOR_S = 1.0  # a service that did not answer counts as down this long before it is asked again


class MultiClient:
    """``MultiClient(["tcp://hostA:5555", "tcp://hostB:5555"])``: ``image``, ``tuple``,
    ``latest`` and ``sequence`` over the cameras of every service. Camera names must be
    unique across the services. Times are in the caller's clock (``clock``)."""

    def __init__(
        self,
        endpoints: Sequence[str],
        *,
        timeout: float = 2.0,
        clock: Callable[[], int] | str | None = None,
        **client_options,
    ):
        if not endpoints:
            raise ConfigError("a client over several services needs at least one endpoint")
        self.timeout = timeout
        self.clients = [SingleClient(e, timeout=timeout, clock=clock, **client_options) for e in endpoints]
        self.clock = self.clients[0].clock
        self._pool = ThreadPoolExecutor(max_workers=len(self.clients), thread_name_prefix="fxis-multi")
        try:
            self.owner: dict[str, SingleClient] = {}
            self._silent: dict[SingleClient, float] = {}  # services that did not answer, until when they count as down
            for client in self.clients:
                self._learn(client)
        except BaseException:
            self.close()
            raise
        self.cameras = {name: RemoteCamera(name, c.endpoint) for name, c in self.owner.items()}
        self.engine = RequestEngine(self.cameras)

    def _learn(self, client: SingleClient) -> None:
        status = client.status()
        for name in status["cameras"]:
            if name in self.owner:
                raise ConfigError(
                    f"camera {name!r} is served by both {self.owner[name].endpoint} and "
                    f"{client.endpoint}: camera names must be unique across services"
                )
            self.owner[name] = client
        client.clock_estimate()  # the first estimate now, not in the first request

    @property
    def clocks(self) -> dict:
        """Each service's clock against the caller's (see ``Client.clocks``)."""
        return {c.endpoint: c.clock_estimate() for c in self.clients}

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        for client in self.clients:
            client.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ---- operations (as Client's, over every service) ----

    def snapshot(
        self,
        at: int | None = None,
        before: float = 2.0,
        after: float = 1.0,
        out: str = "snapshot",
        cameras: list[str] | None = None,
        encoding: str = "raw",
        quality: int | None = None,
    ) -> dict:
        """As ``Client.snapshot``, the cameras of every service into one bag, every stamp in
        the caller's clock."""
        names = cameras or list(self.owner)
        unknown = [n for n in names if n not in self.owner]
        if unknown:
            raise ConfigError(f"unknown camera(s) {unknown}; the services have {sorted(self.owner)}")
        owners = {name: self.owner[name] for name in names}
        return snapshot.take(owners, self.clock, out, at, before, after, encoding, quality)

    def image(self, camera: str, *, at: int | None = None, wait: str | None = None, timeout: float | None = None):
        return frames_of(
            *self._answer("image", camera=camera, at=at, wait=wait, timeout_ms=wire_timeout_ms(timeout, None))
        )[0]

    def tuple(
        self,
        cameras: list[str] | None = None,
        *,
        at: int | None = None,
        sync: str | None = None,
        wait: str | None = None,
        max_skew_ms: float | None = None,
        timeout: float | None = None,
        partial: bool = False,
    ) -> FrameTuple:
        return tuple_of(
            *self._answer(
                "tuple",
                cameras=cameras,
                at=at,
                sync=sync,
                wait=wait,
                max_skew_ms=max_skew_ms,
                timeout_ms=wire_timeout_ms(timeout, None),
                partial=partial or None,
            )
        )

    def latest(self, cameras: list[str] | None = None) -> FrameTuple:
        return tuple_of(*self._answer("latest", cameras=cameras))

    def sequence(
        self,
        kind: str,
        *,
        camera: str | None = None,
        cameras: list[str] | None = None,
        timeout: float | None = None,
        **fields,
    ) -> list:
        """As ``Client.sequence`` (``count``, ``direction``, ``interval_ms``, ``start``, ``end``, ``at``, ``sync``)."""
        header, images = self._answer(
            "sequence", kind=kind, camera=camera, cameras=cameras, timeout_ms=wire_timeout_ms(timeout, None), **fields
        )
        return sequence_of(header, images, single=camera is not None)

    # ---- one request ----

    def _answer(self, op: str, **fields) -> tuple[dict, list]:
        request = protocol.request_of(op, id=None, **fields)
        asked = self.clock()  # "now" is when the caller asked, not when the services answered
        names = self._names(request)
        self._describe(names)  # bounded by each client's timeout; a silent service is down
        now = self.clock()
        wait_s = max(self.timeout, (request.get("timeout_ms") or 0) / 1e3)
        if request.get("at") is not None:
            wait_s += max(0, request["at"] - now) / 1e9
        deadline = now + int(wait_s * 1e9)
        actions = self.engine.submit(request, asked, ticket=op)
        while True:
            reply = settled(actions)
            if reply is not None:
                try:
                    return self._fetch(reply)
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

    def _names(self, request: dict) -> list[str]:
        """The cameras the request reads (those unknown are the engine's to refuse)."""
        names = request.get("cameras") or ([request["camera"]] if request.get("camera") else list(self.cameras))
        return [n for n in names if n in self.cameras]

    def _describe(self, names) -> None:
        """Ask every service concerned, at once, for its cameras' frame times."""
        by_client: dict[SingleClient, list[str]] = {}
        now = time.monotonic()
        for name in names:
            client = self.owner[name]
            if self._silent.get(client, 0.0) <= now:  # a silent service is asked again after a while
                by_client.setdefault(client, []).append(name)
        for client, described in zip(by_client, self._pool.map(_frame_times, by_client, by_client.values())):
            if isinstance(described, Exception):
                # Its cameras are down for a moment: waiting for it again in every retry and every
                # request would let the other services' chosen frames leave their rings meanwhile.
                self._silent[client] = time.monotonic() + SILENT_FOR_S
            else:
                self._silent.pop(client, None)
            for name in by_client[client]:
                if isinstance(described, Exception):
                    self.cameras[name].unreachable(f"at {client.endpoint} does not answer ({described})")
                else:
                    now = self.clock()  # the offset now: over a ring's span, drift moves it by microseconds
                    self.cameras[name].describe(
                        described["cameras"][name], described["columns"], client.clock_estimate().to_service(now) - now
                    )

    def _fetch(self, reply: Reply) -> tuple[dict, list]:
        """The reply header and images of a plan: each chosen frame fetched from its service,
        the services at once (each client by one thread: a socket is not shared)."""
        picks = list(dict.fromkeys(reply.plan.picks))  # each distinct frame once
        by_client: dict[SingleClient, list[tuple[str, dict]]] = {}
        for cam, i in picks:
            by_client.setdefault(self.owner[cam], []).append((cam, self.cameras[cam].service_row(i)))
        fetched = {}
        for group in self._pool.map(_fetch_frames, by_client, by_client.values()):
            fetched.update(group)
        frames, images = [], []
        for k, (cam, i) in enumerate(picks):
            frame = fetched[cam, self.cameras[cam].service_row(i)["frame_id"]]
            meta = protocol.frame_meta(
                cam,
                frame.frame_id,
                frame.t_capture,
                frame.t_stored,
                frame.generation,
                frame.image,
                k,
                frame.t_available,
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
            images.append(frame.image)
        position = {pick: k for k, pick in enumerate(picks)}
        header = {
            **reply.plan.body,
            "frames": frames,
            "timing": {"received": reply.pending.t_received, "waited": reply.t_decided},
        }
        if reply.plan.groups is not None:
            header["groups"] = [[position[pick] for pick in group] for group in reply.plan.groups]
        return header, images


def _fetch_frames(client: SingleClient, wanted: list[tuple[str, dict]]) -> dict:
    """The frames ``wanted`` of one service, by (camera, frame id); Overwritten if one is gone."""
    fetched = {}
    for cam, row in wanted:
        try:
            frame = client.image(cam, at=row["t_capture"], wait="none")
        except ServiceError as exc:
            if exc.code != Code.OUT_OF_RANGE:
                raise
            raise Overwritten(f"frame {row['frame_id']} of {cam!r} left its ring before it could be fetched") from None
        if frame.frame_id != row["frame_id"] or frame.generation != row["generation"]:
            raise Overwritten(f"frame {row['frame_id']} of {cam!r} left its ring before it could be fetched")
        fetched[cam, frame.frame_id] = frame
    return fetched


def _frame_times(client: SingleClient, names: list[str]) -> dict | Exception:
    try:
        return client.frame_times(names)
    except FxisError as exc:
        return exc
