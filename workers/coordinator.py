"""The coordinator process: serves requests from every camera's ring."""

from __future__ import annotations

import logging
import threading

from fxis_shm.service import realtime, rtpolicy
from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.coordinator import Coordinator

from ._child import Ready, child_main

log = logging.getLogger("coordinator")


def run(spec: CoordinatorSpec, ready: Ready, stop: threading.Event) -> None:
    def on_ready() -> None:  # in the loop's thread, its sockets' I/O threads started
        if spec.realtime is not None:
            failed = realtime.raise_threads(rtpolicy.coordinator_thread_role, spec.realtime)
            for line in filter(None, [realtime.lock_memory(), *failed]):
                log.warning("--realtime: %s", line)
        ready.ok()

    Coordinator(spec).serve(stop, on_ready=on_ready)


def main() -> None:
    """``python -m fxis_shm.workers.coordinator '<json spec>' READY_FD``, or a fork of the supervisor."""
    child_main(CoordinatorSpec, run)


if __name__ == "__main__":
    main()
