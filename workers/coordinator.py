"""The coordinator process: serves requests from every camera's ring."""

from __future__ import annotations

import threading

from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.coordinator import Coordinator

from ._child import Ready, child_main


def run(spec: CoordinatorSpec, ready: Ready, stop: threading.Event) -> None:
    Coordinator(spec).serve(stop, on_ready=ready.ok)


def main() -> None:
    """``python -m fxis_shm.workers.coordinator '<json spec>' READY_FD``, or a fork of the supervisor."""
    child_main(CoordinatorSpec, run)


if __name__ == "__main__":
    main()
