"""The dashboard process: the live web page of the service (fxis_shm.dashboard), a client
of the coordinator and of the rings like any other, supervised and restarted like the
camera workers and the coordinator."""
from __future__ import annotations

import asyncio
import threading

from fxis_shm.childspec import DashboardSpec
from fxis_shm.config import http_address
from fxis_shm.security import ClientKeys, load_pair

from ._child import Ready, child_main


def run(spec: DashboardSpec, ready: Ready, stop: threading.Event) -> None:
    from fxis_shm.dashboard import serve
    from fxis_shm.livefeed import LiveFeed

    keys = None
    if spec.curve_secret:  # the service's own pair (its public key must be among the clients')
        public, secret = load_pair(spec.curve_secret)
        keys = ClientKeys(public, public, secret)
    host, port = http_address(spec.http)
    feed = LiveFeed(spec.endpoint, spec.cameras, keys=keys)
    try:
        asyncio.run(serve(feed, host, port, stop, on_ready=ready.ok))
    finally:
        feed.close()


if __name__ == "__main__":
    child_main(DashboardSpec, run)
