"""What the dashboard lets through besides the viewer token (fxis_shm.viewers.access): the
requests of its own page, not those of another site or another user (docs/security.md).

- Every request names in ``Host`` an address the dashboard serves (403 else): a page of
  another site whose name was made to point at this host (DNS rebinding) names its own.
  Bound to loopback: ``localhost`` or a loopback address; to one address: that address or
  this host's names; to every interface: any IP address or this host's names.
- A request that changes something (POST) comes from the page itself: its ``Origin``, when
  there is one, is this address (403 else), and its body is ``application/json`` (415 else),
  which a form or a plain ``fetch`` of another site cannot send without asking first (CORS).
- Who may change settings: where the dashboard has an operator token (``--operator-token-file``),
  whoever sends it in ``X-Fxis-Operator-Token``; else nobody where it is read only
  (``--curve-operators`` named), else whoever may look (fxis_shm.service.changers).

Each refusal is logged, one line per kind and address at most every LOG_PERIOD_S with the
count of the ones in between: a page retrying in a loop cannot fill the log.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import time
from urllib.parse import urlsplit

from aiohttp import hdrs, web

from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.viewers.access import NO_STORE, token_matches

log = logging.getLogger("dashboard")

OPERATOR_HEADER = "X-Fxis-Operator-Token"
SAFE_METHODS = ("GET", "HEAD")
WILDCARDS = ("", "0.0.0.0", "::", "*")
LOG_PERIOD_S = 10.0
READ_ONLY = (
    "this dashboard only shows settings: the service names --curve-operators and no --operator-token-file; "
    "change them with an operator's key (fxis set)"
)
NEEDS_OPERATOR = f"changing settings needs the operator token (header {OPERATOR_HEADER}, or the page's #operator= link)"


def split_host(value: str | None) -> tuple[str, int | None] | None:
    """(host, port or None) of a ``Host`` header or an origin's authority; None if malformed."""
    if not value:
        return None
    try:
        parts = urlsplit(f"//{value}")
        return (parts.hostname or "").rstrip("."), parts.port
    except ValueError:  # a port that is not a number, a broken [v6]
        return None


def _ip(name: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(name)
    except ValueError:
        return None


def host_names() -> set[str]:
    """The names of this host a browser on the cell may use."""
    return {"localhost", socket.gethostname().lower(), socket.getfqdn().lower()}


def host_allowed(value: str | None, bound: str, port: int, tls: bool, names: set[str] | None = None) -> bool:
    """Whether a ``Host`` header names the dashboard bound to ``bound``:``port`` (module doc)."""
    parsed = split_host(value)
    if parsed is None:
        return False
    host, given_port = parsed
    if (given_port or (443 if tls else 80)) != port:
        return False
    host, names = host.lower(), host_names() if names is None else names
    ip = _ip(host)
    if bound in WILDCARDS:
        return ip is not None or host in names
    bound_ip = _ip(bound.strip("[]"))
    if bound_ip is not None and bound_ip.is_loopback:
        return host == "localhost" or (ip is not None and ip.is_loopback)
    return host == bound.strip("[]").lower() or (ip is not None and ip == bound_ip) or host in names


def same_origin(origin: str, host: str, tls: bool) -> bool:
    """Whether an ``Origin`` header is the page's own: this scheme and the request's own Host."""
    scheme, _, authority = origin.partition("://")
    ours, theirs = split_host(host), split_host(authority)
    default = 443 if tls else 80
    return (
        scheme == ("https" if tls else "http")
        and not any(c in authority for c in "/?#@")  # an origin is scheme://host[:port], nothing more
        and ours is not None
        and theirs is not None
        and (ours[0].lower(), ours[1] or default) == (theirs[0].lower(), theirs[1] or default)
    )


class RefusalLog:
    """One log line per (kind, peer) at most every ``period`` s, with the count since the last."""

    def __init__(self, period: float = LOG_PERIOD_S, clock=time.monotonic):
        self.period, self.clock = period, clock
        self._last: dict[tuple[str, str], tuple[float, int]] = {}

    def refused(self, kind: str, peer: str, why: str) -> bool:
        """Count a refusal; log it unless one of its kind from ``peer`` was logged lately (True: logged)."""
        now = self.clock()
        last, held = self._last.get((kind, peer), (None, 0))
        if last is not None and now - last < self.period:
            self._last[(kind, peer)] = (last, held + 1)
            return False
        more = f" (and {held} more like it since the last line)" if held else ""
        log.warning("refused a request from %s: %s%s", peer, why, more)
        self._last[(kind, peer)] = (now, 0)
        return True


def guard_middleware(access: ViewerAccess, bound: str, port: int, names: set[str] | None = None):
    """The aiohttp middleware holding the rules of the module doc."""
    tls, refusals = bool(access.tls_cert), RefusalLog()

    def refuse(request: web.Request, status: int, kind: str, why: str) -> web.Response:
        refusals.refused(kind, request.remote or "?", why)
        return web.Response(status=status, text=f"{status}: {why}\n", headers=NO_STORE)

    @web.middleware
    async def guard(request: web.Request, handler):
        host = request.headers.get(hdrs.HOST)
        if not host_allowed(host, bound, port, tls, names):
            return refuse(request, 403, "host", f"Host {host!r} is not an address this dashboard serves")
        if request.method in SAFE_METHODS:
            return await handler(request)
        origin = request.headers.get(hdrs.ORIGIN)
        if origin is not None and not same_origin(origin, host or "", tls):
            return refuse(request, 403, "origin", f"a request of another site ({origin}) may not change anything here")
        if request.content_type != "application/json":
            return refuse(request, 415, "content type", "send changes as Content-Type: application/json")
        if access.operator_token:
            if not token_matches(request.headers.get(OPERATOR_HEADER), access.operator_token):
                return refuse(request, 403, "operator", NEEDS_OPERATOR)
        elif access.read_only:
            return refuse(request, 403, "read only", READ_ONLY)
        return await handler(request)

    return guard


def changes(access: ViewerAccess) -> dict[str, str]:
    """What the page is told of who may change settings here: ``open``, ``operator token`` or
    ``read only``, and why."""
    if access.operator_token:
        return {"mode": "operator token", "why": NEEDS_OPERATOR}
    if access.read_only:
        return {"mode": "read only", "why": READ_ONLY}
    return {"mode": "open", "why": ""}
