"""The live dashboard: a small web server (aiohttp) showing what every camera sees.

    /                              the page (docs/dashboard.md)
    /status.json                   the service's status, as ``fxis status --json`` prints it
    /dashboard.json                what the page draws: status, measured rates, intervals, skews
    /cameras/NAME/latest.jpg       the newest frame, scaled down (?width=, default 640)
    /cameras/NAME/stream.mjpg      MJPEG (?fps=, default 5; ?width=)
    /tuple.zip                     one synchronized tuple: NAME.png per camera + tuple.json
    /cameras/NAME/settings.json    GET: the camera's settings and limits, and who may change them
                                   here; POST {"key": value, ...}: change them (docs/protocol.md
                                   7.8), 400/403 with the refusal

It runs in a process of its own (workers/dashboard.py) and reads through fxis_shm.Client
(fxis_shm.viewers.livefeed). A slow viewer gets fewer frames, never a queue: each stream sends the
newest frame when it is ready for one. Bad parameters get 400, unknown cameras 404, a camera
down or a silent service 503, each with a message in plain text. Where a token is required
(fxis_shm.viewers.access), a request without it gets 401 before anything else is looked at;
then fxis_shm.viewers.guard refuses other sites, other addresses and, where settings are
kept to operators, changes without the operator token.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
from importlib import resources

from aiohttp import web

from fxis_shm.errors import Code, FxisError, InvalidArgument, ServiceError, UnknownCamera
from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.viewers.access import middlewares, ssl_context
from fxis_shm.viewers.guard import changes, guard_middleware
from fxis_shm.viewers.livefeed import SAMPLE_PERIOD_S, LiveFeed
from fxis_shm.viewers.preview import parse_fps, parse_width
from fxis_shm.viewers.tuningfeed import CameraTuning

log = logging.getLogger("dashboard")

BOUNDARY = "fxisframe"
NOT_READY_RETRY_S = 0.2  # a stream whose camera is down looks again this often
FEED = web.AppKey("feed", LiveFeed)
TUNING = web.AppKey("tuning", CameraTuning)
CHANGES = web.AppKey("changes", dict)  # who may change settings here (fxis_shm.viewers.guard.changes)
FRAME_HEADER = "X-Fxis-Frame"  # GENERATION:FRAME_ID of the frame a picture shows


def _page() -> bytes:
    return resources.files("fxis_shm.viewers").joinpath("dashboard.html").read_bytes()


def _error(exc: Exception) -> web.Response:
    """The HTTP answer to an error of a request: 400, 404 or 503 with a readable message."""
    if isinstance(exc, InvalidArgument) or getattr(exc, "code", None) == Code.SETTING_REFUSED:
        status = 400
    elif getattr(exc, "code", None) == Code.FORBIDDEN:
        status = 403
    elif isinstance(exc, UnknownCamera):
        status = 404
    else:  # CameraDown, RequestTimeout, a service gone: worth trying again later
        status = 503
    return web.Response(status=status, text=f"{exc}\n", headers={"Cache-Control": "no-store"})


async def _index(request: web.Request) -> web.Response:
    return web.Response(body=_page(), content_type="text/html", charset="utf-8")


async def _status(request: web.Request) -> web.Response:
    try:
        status = await request.app[FEED].status()
    except FxisError as exc:
        return _error(exc)
    return web.json_response(status, dumps=lambda o: json.dumps(o, indent=2))


async def _dashboard(request: web.Request) -> web.Response:
    feed = request.app[FEED]
    return web.json_response(
        {**feed.view, "endpoint": feed.endpoint, "configured": feed.cameras, "previews_encoded": feed.cache.encoded},
        headers={"Cache-Control": "no-store"},
    )


async def _latest(request: web.Request) -> web.Response:
    try:
        width = parse_width(request.query.get("width"))
        data, key = await request.app[FEED].latest_jpeg(request.match_info["name"], width)
    except FxisError as exc:
        return _error(exc)
    _, generation, frame_id, _ = key
    return web.Response(
        body=data,
        content_type="image/jpeg",
        headers={"Cache-Control": "no-store", FRAME_HEADER: f"{generation}:{frame_id}"},
    )


async def _stream(request: web.Request) -> web.StreamResponse:
    feed, camera = request.app[FEED], request.match_info["name"]
    try:
        width = parse_width(request.query.get("width"))
        period = 1.0 / parse_fps(request.query.get("fps"))
        feed.check_camera(camera)
    except FxisError as exc:
        return _error(exc)
    response = web.StreamResponse(
        headers={"Content-Type": f"multipart/x-mixed-replace; boundary={BOUNDARY}", "Cache-Control": "no-store"}
    )
    await response.prepare(request)
    loop = asyncio.get_running_loop()
    sent_key, due = None, loop.time()
    with contextlib.suppress(ConnectionError, asyncio.CancelledError):
        while True:
            try:
                data, key = await feed.latest_jpeg(camera, width)
            except FxisError as exc:  # a camera down, the service silent: keep the viewer, try again
                log.debug("stream of %s: %s", camera, exc)
                await asyncio.sleep(max(period, NOT_READY_RETRY_S))
                continue
            if key != sent_key:
                # write() waits while the viewer's socket buffer is full: a slow viewer holds up
                # only its own stream, which then skips to the newest frame
                await response.write(
                    f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(data)}\r\n\r\n".encode()
                    + data
                    + b"\r\n"
                )
                sent_key = key
            due = max(due + period, loop.time())  # behind schedule: drop, never catch up
            await asyncio.sleep(due - loop.time())
    return response


async def _settings(request: web.Request) -> web.Response:
    camera = request.match_info["name"]
    try:
        request.app[FEED].check_camera(camera)
        if request.method == "POST":
            try:
                values = await request.json()
            except ValueError:
                values = None
            if not isinstance(values, dict) or not values:
                raise InvalidArgument('POST a JSON object of settings, e.g. {"exposure_us": 5000}')
            answer = await request.app[TUNING].configure(camera, values)
        else:
            answer = {**await request.app[TUNING].settings(camera), "dashboard": request.app[CHANGES]}
    except (FxisError, ServiceError) as exc:
        return _error(exc)
    return web.json_response(answer, headers={"Cache-Control": "no-store"})


async def _tuple_zip(request: web.Request) -> web.Response:
    try:
        data, name = await request.app[FEED].tuple_zip()
    except FxisError as exc:
        return _error(exc)
    return web.Response(
        body=data,
        content_type="application/zip",
        headers={"Content-Disposition": f'attachment; filename="{name}"', "Cache-Control": "no-store"},
    )


async def _sample_forever(app: web.Application) -> None:
    feed = app[FEED]
    while True:
        await feed.sample()
        await asyncio.sleep(SAMPLE_PERIOD_S)


def make_app(feed: LiveFeed, access: ViewerAccess, host: str, port: int) -> web.Application:
    """The dashboard's web app serving ``host``:``port``; with ``access.token``, every path
    requires it (the cookie's name has the ``port`` in it)."""
    app = web.Application(middlewares=[*middlewares(access, port), guard_middleware(access, host, port)])
    app[FEED], app[CHANGES] = feed, changes(access)
    app.router.add_get("/", _index)
    app.router.add_get("/status.json", _status)
    app.router.add_get("/dashboard.json", _dashboard)
    app.router.add_get("/cameras/{name}/latest.jpg", _latest)
    app.router.add_get("/cameras/{name}/stream.mjpg", _stream)
    app.router.add_get("/tuple.zip", _tuple_zip)
    app.router.add_get("/cameras/{name}/settings.json", _settings)
    app.router.add_post("/cameras/{name}/settings.json", _settings)
    app[TUNING] = CameraTuning(feed.endpoint, feed.keys)

    async def sampler(app: web.Application):
        task = asyncio.create_task(_sample_forever(app))
        yield
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    app.cleanup_ctx.append(sampler)
    app.on_cleanup.append(lambda app: asyncio.get_running_loop().run_in_executor(None, app[TUNING].close))
    return app


async def serve(
    feed: LiveFeed, host: str, port: int, stop: threading.Event, on_ready, access: ViewerAccess | None = None
) -> None:
    """Serve until ``stop`` is set; ``on_ready`` once listening (a port in use raises OSError).
    ``access``: the token it requires and its TLS files (default: neither)."""
    access = access or ViewerAccess()
    runner = web.AppRunner(make_app(feed, access, host, port), access_log=None, handle_signals=False)
    await runner.setup()
    try:
        tls = ssl_context(access)
        await web.TCPSite(runner, host, port, shutdown_timeout=1.0, ssl_context=tls).start()
        on_ready()
        scheme, needs = "https" if tls else "http", " (token required)" if access.token else ""
        log.info("dashboard on %s://%s:%d/%s", scheme, host, port, needs)
        while not stop.is_set():
            await asyncio.sleep(0.1)
    finally:
        await runner.cleanup()
