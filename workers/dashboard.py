"""The dashboard process: the live web page of the service (fxis_shm.viewers.dashboard), a client
of the coordinator and of the rings like any other, supervised and restarted like the
camera workers and the coordinator."""

from __future__ import annotations

import asyncio
import threading

from fxis_shm.service.childspec import DashboardSpec
from fxis_shm.service.config import http_address
from fxis_shm.service.viewertokens import ViewerAccess

from ._child import Ready, child_main


def run(spec: DashboardSpec, ready: Ready, stop: threading.Event) -> None:
    from fxis_shm.viewers.dashboard import serve
    from fxis_shm.viewers.livefeed import feed_for

    host, port = http_address(spec.http)
    access = ViewerAccess.from_environment()  # the token: from the environment, never from argv
    feed = feed_for(spec)
    try:
        asyncio.run(serve(feed, host, port, stop, on_ready=ready.ok, access=access))
    finally:
        feed.close()


if __name__ == "__main__":
    child_main(DashboardSpec, run)
