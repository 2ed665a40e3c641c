"""What every child process of the supervisor shares: its spec from argv, logging,
the readiness handshake, and stopping on SIGTERM or when the supervisor dies."""
from __future__ import annotations

import json
import logging
import os
import signal
import sys
import threading
from typing import Callable

from fxis_shm import timebase
from fxis_shm.tether import die_with_parent

class Ready:
    """The readiness pipe: one line, ``ok`` or ``error <message>``, then closed."""

    def __init__(self, fd: int | None):
        self._fd = fd

    def _send(self, line: str) -> None:
        if self._fd is None:
            return
        try:
            os.write(self._fd, (line.replace("\n", " ") + "\n").encode())
            os.close(self._fd)
        except OSError:
            pass
        self._fd = None

    def ok(self) -> None:
        self._send("ok")

    def fail(self, message: str) -> None:
        self._send("error " + message)


def child_main(role: str, run: Callable[[dict, Ready, threading.Event], None]) -> None:
    """Entry point of a child: ``python -m fxis_shm.workers.X '<json spec>'``."""
    spec = json.loads(sys.argv[1])
    logging.basicConfig(
        level=spec.get("log_level", "INFO"),
        format=f"%(asctime)s {role} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    log = logging.getLogger(role)
    timebase.use(spec.get("clock", timebase.DEFAULT))  # before any frame or request is stamped
    stop = threading.Event()
    parent = os.getppid()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the supervisor's to handle
    die_with_parent()  # even after kill -9 of the supervisor
    if os.getppid() != parent:
        return
    ready = Ready(spec.get("ready_fd"))
    try:
        run(spec, ready, stop)
    except Exception as exc:  # report any start-up failure through the handshake
        ready.fail(f"{type(exc).__name__}: {exc}")
        log.exception("%s failed", role)
        sys.exit(1)
