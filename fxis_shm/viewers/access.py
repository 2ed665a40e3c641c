"""Who may look: the token and TLS of the dashboard and the Foxglove server (docs/security.md).

A viewer that requires a token (fxis_shm.service.config.ServiceConfig.token_viewers) lets a
request in that carries it in one of three places:

    ?token=TOKEN                   the link printed at start; a page visit then stores it in a
                                   cookie and goes on to the same address without it
    Authorization: Bearer TOKEN    (or ``token TOKEN``) for scripts
    cookie fxis-token-PORT         HttpOnly, SameSite=Strict, Secure over TLS; one per port, so
                                   two services on one host keep their tokens apart

Anything else gets 401 with a message that names nothing of the service, whatever the path
(an unknown path too: the answer does not tell what exists). Tokens are compared in constant
time (hmac.compare_digest).
"""

from __future__ import annotations

import hmac
import html
import ssl
from urllib.parse import urlencode

from aiohttp import hdrs, web

from fxis_shm.service.viewertokens import ViewerAccess

TOKEN_PARAMETER = "token"
COOKIE_PREFIX = "fxis-token-"
COOKIE_MAX_AGE_S = 30 * 24 * 3600  # a month, as Jupyter's login cookie; a new random token ends it sooner
AUTH_SCHEMES = ("bearer", "token")
UNAUTHORIZED = "401 Unauthorized: this address needs a token (open it with the ?token= link printed at start)\n"
NO_STORE = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"}


def cookie_name(port: int) -> str:
    return f"{COOKIE_PREFIX}{port}"


def token_matches(candidate: str | None, token: str) -> bool:
    """Whether ``candidate`` is the token, in time that does not depend on where they differ."""
    return candidate is not None and hmac.compare_digest(candidate.encode(), token.encode())


def header_token(value: str | None) -> str | None:
    """The token of an ``Authorization: Bearer TOKEN`` (or ``token TOKEN``) header, else None."""
    scheme, _, credentials = (value or "").strip().partition(" ")
    return (credentials.strip() or None) if scheme.lower() in AUTH_SCHEMES else None


def without_token(path: str, query: list[tuple[str, str]]) -> str:
    """The address to go on to once the token is in the cookie: the same path and query without
    ``token``, never another host (a path starting ``//`` would name one)."""
    rest = [(k, v) for k, v in query if k != TOKEN_PARAMETER]
    return "/" + path.lstrip("/") + (f"?{urlencode(rest)}" if rest else "")


def unauthorized() -> web.Response:
    return web.Response(status=401, text=UNAUTHORIZED, headers={**NO_STORE, "WWW-Authenticate": "Bearer"})


def is_websocket(request: web.Request) -> bool:
    return request.headers.get(hdrs.UPGRADE, "").lower() == "websocket"


def token_middleware(token: str, cookie: str, secure: bool):
    """The aiohttp middleware that lets only requests with the token through (module doc)."""

    @web.middleware
    async def require_token(request: web.Request, handler):
        if token_matches(request.query.get(TOKEN_PARAMETER), token):
            if request.method in ("GET", "HEAD") and not is_websocket(request):
                return _store_and_go_on(request, token, cookie, secure)
            return await handler(request)
        if token_matches(header_token(request.headers.get(hdrs.AUTHORIZATION)), token) or token_matches(
            request.cookies.get(cookie), token
        ):
            return await handler(request)
        return unauthorized()

    return require_token


def _store_and_go_on(request: web.Request, token: str, cookie: str, secure: bool) -> web.Response:
    """The token into the cookie, and on to the address without it (out of the address bar, the
    history and the Referer). A browser sends a SameSite=Strict cookie along a redirect only
    when the visit began on this site: a link followed from another site (Sec-Fetch-Site:
    cross-site) gets a page that goes on by itself, a visit this site begins."""
    target = without_token(request.raw_path.split("?", 1)[0], list(request.query.items()))
    if request.headers.get("Sec-Fetch-Site") == "cross-site":
        link = html.escape(target, quote=True)
        response = web.Response(
            text=f'<!doctype html><meta http-equiv="refresh" content="0; url={link}"><a href="{link}">continue</a>\n',
            content_type="text/html",
            headers=NO_STORE,
        )
    else:
        response = web.Response(status=303, headers={**NO_STORE, hdrs.LOCATION: target})
    response.set_cookie(
        cookie, token, max_age=COOKIE_MAX_AGE_S, path="/", httponly=True, samesite="Strict", secure=secure
    )
    return response


def middlewares(access: ViewerAccess, port: int) -> list:
    """The middlewares of a viewer's web app: the token check where one is required."""
    if not access.token:
        return []
    return [token_middleware(access.token, cookie_name(port), secure=bool(access.tls_cert))]


def ssl_context(access: ViewerAccess) -> ssl.SSLContext | None:
    """The server's TLS context from the certificate and key files (None: plain http and ws)."""
    if not access.tls_cert:
        return None
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(access.tls_cert, access.tls_key, password=lambda: b"")
    return context
