"""The Foxglove process: the cameras served to the Foxglove app (fxis_shm.viewers.foxglove_live), a
client of the coordinator and of the rings like any other, supervised and restarted like
the camera workers and the coordinator."""

from __future__ import annotations

import threading

from fxis_shm.service.childspec import FoxgloveSpec
from fxis_shm.service.config import http_address
from fxis_shm.service.viewertokens import ViewerAccess

from ._child import Ready, child_main


def run(spec: FoxgloveSpec, ready: Ready, stop: threading.Event) -> None:
    from fxis_shm.viewers.foxglove_live import serve
    from fxis_shm.viewers.livefeed import feed_for

    host, port = http_address(spec.foxglove, "foxglove")
    access = ViewerAccess.from_environment()  # the token: from the environment, never from argv
    feed = feed_for(spec)
    try:
        serve(feed, host, port, spec.rate_hz, stop, on_ready=ready.ok, name=f"fxis {spec.service}", access=access)
    finally:
        feed.close()


if __name__ == "__main__":
    child_main(FoxgloveSpec, run)
