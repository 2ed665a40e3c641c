"""Stopping on SIGTERM/SIGINT without hanging: the handler a process installs with ``stop_on``.

A Python signal handler runs in the main thread between two bytecodes, which may be inside
``threading.Event.wait`` while that thread holds the event's lock. A handler that called
``Event.set`` would take the same lock there and wait on itself for ever (a supervisor seen
hanging on SIGTERM; a main loop polling ``stop.wait(0)`` hangs on one signal in two). So the
handler only writes a byte to a pipe, and a thread of its own sets the event.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterable


def stop_on(signals: Iterable[signal.Signals], stop: threading.Event) -> None:
    """Set ``stop`` when one of ``signals`` arrives (call from the main thread)."""
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)

    def relay() -> None:
        while os.read(read_fd, 1):  # every signal sets it (again, if someone cleared it)
            stop.set()

    def handler(signum: int, frame: object) -> None:
        try:
            os.write(write_fd, b"\0")
        except BlockingIOError:  # the pipe is full: the relay has a byte to wake on already
            pass

    threading.Thread(target=relay, name="stop-on-signal", daemon=True).start()
    for sig in signals:
        signal.signal(sig, handler)
