"""What every child process of the supervisor shares: its typed spec from argv
(fxis_shm.service.childspec), logging, the readiness handshake, and stopping on SIGTERM
or when the supervisor dies."""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import TypeVar

from fxis_shm.core import timebase
from fxis_shm.errors import SpecError
from fxis_shm.service.childspec import ChildSpec
from fxis_shm.service.stopsignals import stop_on
from fxis_shm.service.tether import die_with_parent

S = TypeVar("S", bound=ChildSpec)


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


def child_main(spec_class: type[S], run: Callable[[S, Ready, threading.Event], None]) -> None:
    """Entry point of a child: ``python -m MODULE '<json spec>' READY_FD``."""
    role = spec_class.ROLE
    ready = Ready(int(sys.argv[2]) if len(sys.argv) > 2 else None)
    try:
        spec = spec_class.from_json(sys.argv[1] if len(sys.argv) > 1 else "")
    except SpecError as exc:
        ready.fail(str(exc))
        print(f"fxis {role}: {exc}", file=sys.stderr)
        sys.exit(2)
    logging.basicConfig(
        level=spec.log_level,
        format=f"%(asctime)s {role} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    log = logging.getLogger(role)
    timebase.use(spec.clock)  # before any frame or request is stamped
    stop = threading.Event()
    parent = os.getppid()
    stop_on((signal.SIGTERM,), stop)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the supervisor's to handle
    die_with_parent()  # even after kill -9 of the supervisor
    if os.getppid() != parent:
        return
    try:
        run(spec, ready, stop)
    except Exception as exc:  # report any start-up failure through the handshake
        ready.fail(f"{type(exc).__name__}: {exc}")
        log.exception("%s failed", role)
        sys.exit(1)
