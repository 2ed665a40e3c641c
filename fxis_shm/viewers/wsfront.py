"""The front of a WebSocket server that cannot refuse a client itself: the foxglove-sdk server
(0.30) takes TLS files but has no hook to look at a connection before it accepts it. Where
the Foxglove server requires a token or TLS, the SDK's server listens on a loopback port the
system picks, and this front listens on the address asked for: it checks the token
(fxis_shm.viewers.access: ``?token=`` in the URL the app connects to, the header or the cookie),
terminates TLS, and relays every message both ways unchanged, the subprotocol the SDK chose
(``foxglove.sdk.v1``) included. One message at a time: a slow viewer stops the front
reading from the SDK, whose per-client backlog then drops the oldest pictures, as without a
front; the cameras never wait.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

import aiohttp
from aiohttp import WSMsgType, hdrs, web

from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.viewers.access import is_websocket, middlewares, ssl_context

log = logging.getLogger("foxglove")

BACKEND_HOST = "127.0.0.1"  # where the SDK's own server listens behind the front
CLIENT_MESSAGE_LIMIT = 4 * 1024 * 1024  # what a viewer may send (subscriptions, parameters): small
BACKEND = web.AppKey("backend", str)
SESSION = web.AppKey("session", aiohttp.ClientSession)


def offered_protocols(header: str | None) -> list[str]:
    """The subprotocols a client offers (``Sec-WebSocket-Protocol: a, b``), in its order."""
    return [p.strip() for p in (header or "").split(",") if p.strip()]


async def _relay(request: web.Request) -> web.StreamResponse:
    if not is_websocket(request):
        return web.Response(status=400, text="a WebSocket server: connect to it with the Foxglove app\n")
    try:  # no token to the server behind: it needs none
        backend = await request.app[SESSION].ws_connect(
            request.app[BACKEND],
            protocols=offered_protocols(request.headers.get(hdrs.SEC_WEBSOCKET_PROTOCOL)),
            max_msg_size=0,  # whole pictures
            compress=0,
        )
    except aiohttp.WSServerHandshakeError as exc:  # e.g. no subprotocol it speaks
        return web.Response(status=exc.status, text=f"WebSocket handshake refused ({exc.status})\n")
    viewer = web.WebSocketResponse(
        protocols=[backend.protocol] if backend.protocol else (), compress=False, max_msg_size=CLIENT_MESSAGE_LIMIT
    )
    try:
        await viewer.prepare(request)
        pumps = [asyncio.create_task(_pump(backend, viewer)), asyncio.create_task(_pump(viewer, backend))]
        try:
            await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for pump in pumps:
                pump.cancel()
            await asyncio.gather(*pumps, return_exceptions=True)
    finally:
        await backend.close()
        await viewer.close()
    return viewer


async def _pump(source, sink) -> None:
    """Every text and binary message of ``source`` to ``sink`` until either closes; each send
    waits for the sink's socket to drain."""
    with contextlib.suppress(ConnectionError):
        async for message in source:
            if message.type == WSMsgType.TEXT:
                await sink.send_str(message.data)
            elif message.type == WSMsgType.BINARY:
                await sink.send_bytes(message.data)
            else:  # an error: the connection is gone
                break


def make_front(backend_port: int, access: ViewerAccess, port: int) -> web.Application:
    """The front's web app: every path, the access check, then the relay to the backend."""
    app = web.Application(middlewares=middlewares(access, port))
    app[BACKEND] = f"ws://{BACKEND_HOST}:{backend_port}/"
    app.router.add_get("/{tail:.*}", _relay)

    async def session(app: web.Application):
        app[SESSION] = aiohttp.ClientSession()
        yield
        await app[SESSION].close()

    app.cleanup_ctx.append(session)
    return app


async def start_front(host: str, port: int, backend_port: int, access: ViewerAccess) -> web.AppRunner:
    """The front listening on ``host:port`` (a port in use raises OSError); clean up the runner."""
    runner = web.AppRunner(make_front(backend_port, access, port), access_log=None, handle_signals=False)
    await runner.setup()
    try:
        await web.TCPSite(runner, host, port, shutdown_timeout=1.0, ssl_context=ssl_context(access)).start()
    except BaseException:
        await runner.cleanup()
        raise
    return runner
