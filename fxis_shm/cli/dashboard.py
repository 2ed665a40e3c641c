"""``fxis dashboard tcp://hostA:5555 tcp://hostB:5555``: one live page for a cell of several
services (the dashboard ``fxis run --http`` serves for one, over ``Client([...])``): every
camera of every service, each service's health and clock, the skew of tuples across hosts,
and "Save tuple" across hosts. It runs here, in the foreground, until Ctrl-C."""

from __future__ import annotations

import faulthandler
import signal
import sys
import threading

from fxis_shm.cli.options import add_key_options, client_keys_for, timeout_seconds
from fxis_shm.errors import ConfigError
from fxis_shm.service.config import http_address
from fxis_shm.service.stopsignals import stop_on
from fxis_shm.service.supervisor import link_host
from fxis_shm.service.viewertokens import ViewerAccess, check_viewer_files, read_token_file, viewer_token
from fxis_shm.wire.endpoints import check_endpoint, check_host_known
from fxis_shm.wire.security import is_loopback

DEFAULT_HTTP = "127.0.0.1:8080"


def access_for(args) -> ViewerAccess:
    """The token the page requires (a file's; a new one where other hosts reach it, unless
    --insecure-bind), and its TLS files; ConfigError for a bad one."""
    check_viewer_files(args.viewer_token_file, args.viewer_tls_cert, args.viewer_tls_key)
    exposed = not is_loopback(f"tcp://{http_address(args.http)[0]}")
    needs_token = bool(args.viewer_token_file) or (exposed and not args.insecure_bind)  # as ServiceConfig.token_viewers
    token = viewer_token(args.viewer_token_file) if needs_token else None
    operator = read_token_file(args.operator_token_file, "--operator-token-file") if args.operator_token_file else None
    if operator is not None and operator == token:
        raise ConfigError("--operator-token-file holds the viewer token: give the operators a token of their own")
    return ViewerAccess(token, args.viewer_tls_cert, args.viewer_tls_key, operator_token=operator)


def dashboard_command(args) -> int:
    # here, not at the top: every `fxis` command (and each service, `fxis run`) would import
    # aiohttp and the page's server, a third of a second, for this one command
    import asyncio

    from fxis_shm.viewers.dashboard import serve
    from fxis_shm.viewers.livefeed import LiveFeed

    if len(set(args.endpoints)) != len(args.endpoints):
        raise ConfigError(f"an endpoint is given twice: {args.endpoints}")
    for endpoint in args.endpoints:  # a mistyped one: a line now, not a service that never answers
        check_host_known(check_endpoint(endpoint, "ENDPOINT"), "ENDPOINT")
    access = access_for(args)
    host, port = http_address(args.http)
    feed = LiveFeed(list(args.endpoints), keys=client_keys_for(args), timeout=args.timeout)
    stop = threading.Event()
    stop_on((signal.SIGINT, signal.SIGTERM), stop)

    def ready() -> None:
        scheme = "https" if access.tls_cert else "http"
        print(f"cell dashboard of {', '.join(args.endpoints)} on {scheme}://{host}:{port}/", flush=True)
        if access.token:
            shown = f"<the token in {args.viewer_token_file}>" if args.viewer_token_file else access.token
            print(f"  it requires a token: open {scheme}://{link_host(args.http, 'http')}/?token={shown}", flush=True)
        elif not is_loopback(f"tcp://{host}"):
            print("  WARNING: other hosts reach it WITHOUT a token (--insecure-bind)", file=sys.stderr, flush=True)

    try:
        asyncio.run(serve(feed, host, port, stop, on_ready=ready, access=access))
    except OSError as exc:
        raise ConfigError(f"--http {args.http}: {exc.strerror or exc}") from None
    finally:
        # a look still waiting on a service that went away must not keep Ctrl-C from ending it:
        # past 10 s, the threads' stacks go to stderr (why it hung) and the process exits
        faulthandler.dump_traceback_later(10, exit=True)
        feed.close()
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser(
        "dashboard",
        help="one live dashboard for a cell of several services",
        description="Serve the live dashboard over several services at once: every camera of every service, "
        "each service's health and clock against this host's, the skew of tuples across hosts, and 'Save tuple' "
        "across hosts. On an address other hosts reach it requires a token (printed as a link at start). "
        "Runs until Ctrl-C. For one service, fxis run --http serves the same page.",
    )
    p.add_argument("endpoints", nargs="+", metavar="ENDPOINT", help="the services' request endpoints (tcp://HOST:5555)")
    p.add_argument(
        "--http", default=DEFAULT_HTTP, metavar="ADDR", help=f"where to serve the page (default {DEFAULT_HTTP})"
    )
    p.add_argument(
        "--timeout", type=timeout_seconds, default=1.5, help="seconds a service may take to answer (default 1.5)"
    )
    add_key_options(p)
    p.add_argument("--viewer-token-file", metavar="FILE", help="the token the page requires (default: a new one)")
    p.add_argument(
        "--operator-token-file",
        metavar="FILE",
        help="the token the page requires to change camera settings (give it where --client-key is an operator's)",
    )
    p.add_argument("--viewer-tls-cert", metavar="FILE", help="serve https with this certificate (PEM)")
    p.add_argument("--viewer-tls-key", metavar="FILE", help="... and this key (PEM)")
    p.add_argument(
        "--insecure-bind", action="store_true", help="serve other hosts without a token (warns; anyone may look)"
    )
    p.set_defaults(func=dashboard_command)
