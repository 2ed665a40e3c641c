"""What the dashboard reads from the service, through the public client API only.

Two clients, each used by one thread of its own (a ZeroMQ socket is not shared between
threads): one brings pictures (``latest`` without copying: on this host a view of the
ring slot, so the cameras never wait for a viewer), the other samples the service twice a
second (status, frame times, one synchronized tuple for its skew). The web side
(fxis_shm.viewers.dashboard) awaits these on the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import logging
import time
import zipfile
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from fxis_shm.client.client import Client
from fxis_shm.client.syncsampler import Row, row_of, samples_of
from fxis_shm.core import syncstats
from fxis_shm.errors import CameraDown, Code, FxisError, UnknownCamera
from fxis_shm.formats.tuplefiles import tuple_files
from fxis_shm.service.childspec import ViewerSpec
from fxis_shm.viewers.cellclient import CellClient, CellProbe
from fxis_shm.viewers.preview import EncodedCache, RateMeter, SkewHistory, frame_intervals_ms, preview_jpeg, preview_key
from fxis_shm.wire.security import ClientKeys

log = logging.getLogger("dashboard")

SAMPLE_PERIOD_S = 0.5  # status, rates and plots refresh this often
REQUEST_TIMEOUT_S = 1.5  # a service silent this long is shown as gone
INTERVALS_SHOWN = 60  # frame intervals plotted per camera
SYNC_WINDOW = 120  # the sampled tuples the live sync figures are of: a minute at two a second
GRID_LAG_NS = 5_000_000  # a sampled tuple's t* is a period and this far back: its frames are stored
SKEW_BOUND_MS = syncstats.DEFAULT_THRESHOLD_MS  # the skew plot's bound: a tuple within it counts as synced
T = TypeVar("T")


def feed_for(spec: ViewerSpec) -> LiveFeed:
    """The feed of a viewer process (the dashboard, the Foxglove server) from its spec. With
    CurveZMQ it connects with the service's own pair: its public key must be among the clients'."""
    return LiveFeed(spec.endpoint, spec.cameras, keys=spec.client_keys())


class LiveFeed:
    """Pictures and figures of one service, or of a cell of several (``endpoint`` a list: the
    cameras of all of them through ``Client([...])``), for every viewer of the dashboard."""

    def __init__(
        self,
        endpoint: str | list[str],
        cameras: dict[str, dict] | None = None,
        keys: ClientKeys | None = None,
        timeout: float = REQUEST_TIMEOUT_S,
    ):
        self.endpoint, self.keys = endpoint, keys
        self.cell = isinstance(endpoint, list)
        self._pictures = ThreadPoolExecutor(1, thread_name_prefix="dashboard-pictures")
        self._sampler = ThreadPoolExecutor(1, thread_name_prefix="dashboard-sampler")
        if isinstance(endpoint, list):  # a cell, some of it perhaps down: fxis_shm.viewers.cellclient
            self._probe = CellProbe(endpoint, timeout, keys)
            self._picture_cell, self._sample_cell = CellClient(timeout, keys), CellClient(timeout, keys)
        else:
            self._picture_client = Client(endpoint, timeout=timeout, keys=keys)
            self._sample_client = Client(endpoint, timeout=timeout, keys=keys)
        # name -> {"kind", "fps" (configured, or None)[, "service"]}; a cell's as its services answer
        self.cameras: dict[str, dict] = {}
        self._rates: dict[str, RateMeter] = {}
        self._learn(cameras or {})
        if self.cell:
            with contextlib.suppress(FxisError):  # those that answer now; the others when they come
                self._learn(self._probe.status()["cameras"])
        self.cache = EncodedCache()
        self._skews = SkewHistory()
        self._tuples: deque[tuple[int, Row | None]] = deque(maxlen=SYNC_WINDOW)  # (t*, its row or None)
        self._grid_origin: int | None = None  # where the sampled tuples' grid of t* starts
        self.started = time.monotonic()
        self.view: dict = {"service_ok": False, "error": "not sampled yet", "status": None}

    def _learn(self, cameras: dict[str, dict]) -> None:
        """Adds the cameras not known yet (a cell's service that came); the page's threads read
        ``cameras`` meanwhile, so a new dict replaces it rather than it changing under them."""
        known = dict(self.cameras)
        for name, cam in cameras.items():
            if name not in known or known[name].get("service") != cam.get("service"):
                known[name] = {"kind": cam.get("kind"), "fps": cam.get("fps")}
                if cam.get("service"):
                    known[name]["service"] = cam["service"]
                self._rates.setdefault(name, RateMeter())
        if known != self.cameras:
            self.cameras = known

    def close(self) -> None:
        for pool in (self._pictures, self._sampler):  # queued looks are dropped: each may wait out a timeout
            pool.shutdown(wait=True, cancel_futures=True)
        if self.cell:
            for closing in (self._probe, self._picture_cell, self._sample_cell):
                closing.close()
        else:
            self._picture_client.close()
            self._sample_client.close()

    def _pictures_client(self) -> Any:
        """The pictures' client (in their thread): a cell's over the services that answer."""
        return self._picture_cell.over_services(self._probe.up) if self.cell else self._picture_client

    def _gone(self, camera: str) -> str | None:
        """Why a cell's camera cannot be asked now: its service did not answer the last look."""
        service = self.cameras.get(camera, {}).get("service")
        return f"its service {service} does not answer" if self.cell and service not in self._probe.up else None

    def check_camera(self, camera: str) -> None:
        if camera not in self.cameras:
            raise UnknownCamera(
                Code.UNKNOWN_CAMERA, f"no camera {camera!r} in this service; known: {', '.join(sorted(self.cameras))}"
            )

    # ---- pictures ----

    async def latest(self, camera: str, make: Callable[..., T], torn: Callable[[T], None] | None = None) -> T:
        """``make(frame)`` of the newest frame of ``camera``, read without a copy where it can
        (a view of the ring slot: the camera never waits for a viewer). If the ring came round
        while ``make`` read the pixels, ``torn(result)`` is told and the newest frame is read
        again, copied. Raises the client's errors (CameraDown, RequestTimeout, ...)."""
        self.check_camera(camera)
        return await asyncio.get_running_loop().run_in_executor(self._pictures, self._latest, camera, make, torn)

    def _latest(self, camera: str, make: Callable[..., T], torn: Callable[[T], None] | None) -> T:
        gone = self._gone(camera)
        if gone:
            raise CameraDown(Code.CAMERA_DOWN, f"camera {camera!r}: {gone}")
        for copy in (False, True):
            with self._pictures_client().latest([camera], copy=copy) as frames:
                frame = frames[camera]
                result = make(frame)
                if frame.still_valid():
                    return result
                if torn:
                    torn(result)
        raise FxisError(f"the frames of {camera!r} were overwritten while being read twice")

    async def latest_jpeg(self, camera: str, width: int) -> tuple[bytes, tuple]:
        """The newest frame of ``camera`` as a preview JPEG and its cache key (a new key:
        a new frame)."""

        def make(frame) -> tuple[bytes, tuple]:
            key = preview_key(camera, frame.generation, frame.frame_id, width)
            return self.cache.get(key, lambda: preview_jpeg(frame.image, width)), key

        return await self.latest(camera, make, torn=lambda result: self.cache.discard(result[1]))

    async def tuple_zip(self) -> tuple[bytes, str]:
        """One synchronized tuple of the cameras that are up, as a zip of PNGs and tuple.json
        (what ``fxis grab`` writes), and a file name for it."""
        return await asyncio.get_running_loop().run_in_executor(self._pictures, self._tuple_zip)

    def _tuple_zip(self) -> tuple[bytes, str]:
        with self._pictures_client().tuple(partial=True) as frames:
            # a cell's cameras whose service is gone are missing from the tuple as a down camera is
            frames.missing = [*frames.missing, *(n for n in self.cameras if self._gone(n) and n not in frames)]
            files = tuple_files(frames)
            name = f"fxis-tuple-{frames.t_request}.zip"
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:  # PNGs are compressed
            for file_name, data in files.items():
                archive.writestr(file_name, data)
        return buffer.getvalue(), name

    # ---- figures ----

    async def status(self) -> dict:
        """The service's ``status`` reply now (what ``fxis status --json`` prints)."""
        status = self._probe.status if self.cell else self._sample_client.status
        return await asyncio.get_running_loop().run_in_executor(self._sampler, status)

    async def sample(self) -> dict:
        """Look at the service once; ``view`` holds what the page shows until the next look."""
        self.view = await asyncio.get_running_loop().run_in_executor(self._sampler, self._sample)
        return self.view

    def _sample(self) -> dict:
        try:
            status = self._probe.status() if self.cell else self._sample_client.status()
        except FxisError as exc:
            log.debug("status failed: %s", exc)
            return {
                **self.view,
                "service_ok": False,
                "error": f"the service at {self.endpoint} does not answer ({exc})",
            }
        self._learn(status["cameras"])
        cameras = {}
        for name, cam in status["cameras"].items():
            config = self.cameras.get(name, {})
            measured = (
                self._rates[name].add(status["now"], cam.get("frames_stored") or 0) if name in self._rates else None
            )
            cameras[name] = {"configured_fps": config.get("fps"), "measured_fps": measured, "intervals_ms": []}
        try:
            client = self._sample_cell.over_services(self._probe.up) if self.cell else self._sample_client
            times = client.frame_times(list(cameras)) if cameras else {"cameras": {}}  # of services that answer
            for name, info in times["cameras"].items():
                cameras[name]["intervals_ms"] = frame_intervals_ms(info["frames"], times["columns"], INTERVALS_SHOWN)
            asked = self._sample_time(client.clock())
            try:
                with client.tuple(partial=True, copy=False, at=asked) as tup:
                    if len(tup) > 1:  # one camera has no skew to show
                        self._skews.add(time.monotonic() - self.started, tup.skew_ns)
                    self._tuples.append((tup.t_request, row_of(tup)))
            except FxisError:
                self._tuples.append((asked, None))  # no tuple: dropped, in the sync figures
                raise
        except FxisError as exc:  # e.g. every camera down: the status still says why
            log.debug("sampling frames failed: %s", exc)
        view = {
            "service_ok": True,
            "error": None,
            "status": status,
            "cameras": cameras,
            "skew_ms": self._skews.points(time.monotonic() - self.started),
            "skew_bound_ms": SKEW_BOUND_MS,
            "sync": self._sync_view(list(status["cameras"])),
            "sampled": time.time(),
        }
        if self.cell:
            view["services"] = services_view(status, self._probe.clocks)
        return view

    def _sample_time(self, now: int) -> int:
        """The t* of the sampled tuple: a point of a grid of the slowest camera's period, one period
        back (its frames are stored: no wait). Samples a whole number of periods apart are what
        the sync figures judge frame ids by (fxis_shm.core.syncstats: a whole number of periods
        between two tuples, that many new frames), whenever the sampler's thread gets to run."""
        periods = [1e9 / cam["fps"] for cam in self.cameras.values() if cam.get("fps")]
        if not periods:
            return now
        slowest = max(periods)
        if self._grid_origin is None:
            self._grid_origin = now
        return self._grid_origin + int((now - self._grid_origin - slowest - GRID_LAG_NS) // slowest * slowest)

    def _sync_view(self, cameras: list[str]) -> dict | None:
        """``fxis sync-report``'s figures (librealsense's criteria, default limits) over the
        tuples sampled in the last minute: the skew of each, and whether one was missing a
        camera or repeated or skipped a frame (fxis_shm.core.syncstats)."""
        tuples = list(self._tuples)
        if not tuples or not cameras:
            return None
        slots = [t for t, _ in tuples]
        periods = {n: 1e9 / fps for n in cameras if (fps := self.cameras.get(n, {}).get("fps"))}
        figures = syncstats.figures(samples_of(cameras, slots, [row for _, row in tuples]), None, periods)
        return {"window_s": round((slots[-1] - slots[0]) / 1e9, 1), **figures.as_dict()}


def services_view(status: dict, clocks: dict) -> dict:
    """What the page shows of each service of a cell: whether it answers (and why not), its
    name and uptime, and its clock against the dashboard's (offset, uncertainty, how known;
    None for a service that does not answer: its clock is not known now)."""
    services = {}
    for endpoint, answer in status["services"].items():
        clock = clocks.get(endpoint) if answer.get("ok") is not False else None
        services[endpoint] = {
            "ok": answer.get("ok", False),
            "error": answer.get("error"),
            "service": answer.get("service"),
            "uptime_s": answer.get("uptime_s"),
            "cameras": sorted(answer.get("cameras", {})),
            "clock": None
            if clock is None
            else {
                "offset_ms": clock.offset_ns / 1e6,
                "uncertainty_ms": clock.uncertainty_ns / 1e6,
                "method": clock.method,
            },
        }
    return services
