"""The Foxglove live view (fxis run --foxglove): the cameras served to the Foxglove app over
its WebSocket protocol, through the foxglove-sdk package (the "foxglove" extra).

    /NAME/image    foxglove.RawImage of camera NAME (protobuf): timestamp = capture time
                   on the service's CLOCK_MONOTONIC, frame_id = NAME, the frame's own pixels
    /fxis/status   JSON, what the dashboard's /dashboard.json holds (status, rates, skews)

It runs in a process of its own (workers/foxglove_server.py) reading through fxis_shm.Client
(fxis_shm.viewers.livefeed), like the dashboard: a camera's channel gets its newest frame at most
``rate_hz`` times a second, only while some client subscribes to it, each frame once; a
frame is read from the ring without a copy and copied once into the message. The rate is a
setting (--foxglove-rate) and a parameter the app can change live (``rate_hz``). Where a token
or TLS is asked for, the SDK's server listens on loopback behind an authenticating front
(fxis_shm.viewers.wsfront) on the address asked for.
"""

from __future__ import annotations

import asyncio
import logging
import threading

import foxglove
import numpy as np
from foxglove import Capability, Parameter, ParameterType, StatusLevel
from foxglove.channels import RawImageChannel
from foxglove.messages import RawImage, Timestamp
from foxglove.websocket import ServerListener

from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.service.config import check_foxglove_rate
from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.viewers.livefeed import SAMPLE_PERIOD_S, LiveFeed
from fxis_shm.viewers.preview import displayable
from fxis_shm.viewers.wsfront import BACKEND_HOST, start_front

log = logging.getLogger("foxglove")

RATE_PARAMETER = "rate_hz"
STATUS_TOPIC = "/fxis/status"
BACKLOG_MESSAGES = 16  # per client: a slow one loses its oldest pictures; memory stays bounded
TICK_S = 0.05  # the longest the loop sleeps: how soon a stop or a new rate is seen
ENCODINGS = {
    (np.dtype(np.uint8), 1): "mono8",
    (np.dtype(np.uint8), 3): "bgr8",
    (np.dtype(np.uint8), 4): "bgra8",
    (np.dtype(np.uint16), 1): "mono16",
}


def image_topic(camera: str) -> str:
    return f"/{camera}/image"


def raw_pixels(image: np.ndarray) -> tuple[np.ndarray, str]:
    """The frame as RawImage carries it and the name of its encoding: 8-bit mono, BGR and
    BGRA and 16-bit mono as they are (16-bit little-endian), anything else made displayable."""
    channels = 1 if image.ndim == 2 else image.shape[2]
    encoding = ENCODINGS.get((image.dtype.newbyteorder("="), channels))  # either byte order
    if encoding is None:
        image = displayable(image)
        encoding = ENCODINGS[(image.dtype, 1 if image.ndim == 2 else image.shape[2])]
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    return image.astype(image.dtype.newbyteorder("<"), copy=False), encoding


def raw_image(camera: str, image: np.ndarray, t_capture_ns: int) -> RawImage:
    pixels, encoding = raw_pixels(image)
    height, width = pixels.shape[:2]
    return RawImage(
        timestamp=Timestamp(*divmod(t_capture_ns, 1_000_000_000)),
        frame_id=camera,
        width=width,
        height=height,
        encoding=encoding,
        step=width * pixels.itemsize * (1 if pixels.ndim == 2 else pixels.shape[2]),
        data=pixels.tobytes(),
    )


class RateParameter(ServerListener):
    """The picture rate, a parameter the app reads and sets (its Parameters panel); the
    SDK calls these methods from its own threads. A bad value is refused with a status
    message in the app, and the rate stays as it was."""

    def __init__(self, hz: float):
        self.hz = check_foxglove_rate(hz)
        self.server: foxglove.WebSocketServer | None = None

    def parameter(self) -> Parameter:
        return Parameter(RATE_PARAMETER, value=self.hz, type=ParameterType.Float64)

    def on_get_parameters(self, client, param_names: list[str], request_id=None) -> list[Parameter]:
        return [self.parameter()] if not param_names or RATE_PARAMETER in param_names else []

    def on_set_parameters(self, client, parameters: list[Parameter], request_id=None) -> list[Parameter]:
        for p in parameters:
            if p.name != RATE_PARAMETER:
                continue
            try:
                self.hz = check_foxglove_rate(p.get_value(), RATE_PARAMETER)
                log.info("rate set to %g pictures a second per camera", self.hz)
            except ConfigError as exc:
                log.warning("%s", exc)
                if self.server is not None:
                    self.server.publish_status(str(exc), StatusLevel.Warning)
        return [self.parameter()]


async def publish(
    feed: LiveFeed,
    cameras: dict[str, RawImageChannel],
    status: foxglove.Channel,
    rate: RateParameter,
    stop: threading.Event,
) -> None:
    """Until ``stop``: each subscribed camera's newest frame not yet sent, at ``rate.hz``;
    the status twice a second while someone subscribes to it."""
    loop = asyncio.get_running_loop()
    sent: dict[str, tuple[int, int]] = {}  # camera -> (generation, frame_id) last sent
    pictures_due = status_due = loop.time()
    while not stop.is_set():
        now = loop.time()
        if now >= pictures_due:
            for camera, channel in cameras.items():
                if channel.has_sinks():
                    await _send_newest(feed, camera, channel, sent)
            pictures_due = max(pictures_due + 1.0 / rate.hz, now)  # behind: skip, never catch up
        if now >= status_due and status.has_sinks():
            status.log(await feed.sample())
            status_due = now + SAMPLE_PERIOD_S
        await asyncio.sleep(max(0.0, min(pictures_due, loop.time() + TICK_S) - loop.time()))


async def _send_newest(feed: LiveFeed, camera: str, channel: RawImageChannel, sent: dict[str, tuple[int, int]]) -> None:
    def make(frame):
        key = (frame.generation, frame.frame_id)
        return key, None if key == sent.get(camera) else raw_image(camera, frame.image, frame.t_capture)

    try:
        key, message = await feed.latest(camera, make)
    except FxisError as exc:  # a camera down: nothing new to show (the status says why)
        log.debug("no picture of %s: %s", camera, exc)
        return
    if message is not None:
        channel.log(message)
        sent[camera] = key


def serve(
    feed: LiveFeed,
    host: str,
    port: int,
    rate_hz: float,
    stop: threading.Event,
    on_ready,
    name: str = "fxis",
    access: ViewerAccess | None = None,
) -> None:
    """Serve until ``stop`` is set; ``on_ready`` once listening (a port in use raises).
    ``access``: the token it requires and its TLS files (default: neither); with either, the
    SDK's server listens on loopback behind the front (fxis_shm.viewers.wsfront)."""
    access = access or ViewerAccess()
    front = bool(access.token or access.tls_cert)
    context = foxglove.Context()  # this server's channels only, not the SDK's global ones
    cameras = {camera: RawImageChannel(image_topic(camera), context=context) for camera in feed.cameras}
    status = foxglove.Channel(STATUS_TOPIC, context=context)
    rate = RateParameter(rate_hz)
    server = foxglove.start_server(
        name=name,
        host=BACKEND_HOST if front else host,
        port=0 if front else port,  # behind the front: a port the system picks
        capabilities=[Capability.Parameters],
        server_listener=rate,
        context=context,
        message_backlog_size=BACKLOG_MESSAGES,
    )
    rate.server = server

    async def run() -> None:
        runner = await start_front(host, port, server.port, access) if front else None
        try:
            on_ready()
            scheme, needs = "wss" if access.tls_cert else "ws", " (token required)" if access.token else ""
            log.info(
                "Foxglove WebSocket server on %s://%s:%d%s (%g pictures/s per camera)",
                scheme,
                host,
                port,
                needs,
                rate.hz,
            )
            await publish(feed, cameras, status, rate, stop)
        finally:
            if runner is not None:
                await runner.cleanup()

    try:
        asyncio.run(run())
    finally:
        server.stop()
