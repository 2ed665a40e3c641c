"""Stopping on SIGTERM/SIGINT without hanging.

A Python signal handler runs in the main thread between two bytecodes, which may be inside
``threading.Event.wait`` while that thread holds the event's lock. A handler that called
``Event.set`` would take the same lock there and wait on itself for ever (a supervisor seen
hanging on SIGTERM; a main loop polling ``stop.wait(0)`` hangs on one signal in two). Two ways
around it:

- ``stop_on``, for a process whose threads wait on a ``threading.Event``: the handler only
  writes a byte to a pipe, and a thread of its own sets the event.
- ``StopSignals``, for the supervisor, which forks its children and so must have no thread (a
  fork copies only the forking thread, and any lock another thread held stays locked for ever
  in the child): the main loop waits on the pipe ``signal.set_wakeup_fd`` writes to, and the
  handler only sets a flag. Nothing takes a lock.
"""

from __future__ import annotations

import os
import select
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


class StopSignals:
    """``signals`` noted without a thread (call from the main thread): ``wait`` sleeps until
    one arrives or the timeout passes, and says whether one has arrived since ``clear``."""

    def __init__(self, signals: Iterable[signal.Signals]):
        self._read_fd, write_fd = os.pipe()
        for fd in (self._read_fd, write_fd):
            os.set_blocking(fd, False)
        self._write_fd = write_fd
        self.received = False
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)  # a full pipe has a byte to wake on already
        for sig in signals:
            signal.signal(sig, self._note)

    def _note(self, signum: int, frame: object) -> None:
        self.received = True  # a plain store: no lock to wait on wherever the main thread is

    def wait(self, timeout: float) -> bool:
        """Sleep up to ``timeout`` s, less if a signal arrives (its byte wakes ``select``, also one
        that came just before it); returns ``received``."""
        if not self.received:
            select.select([self._read_fd], [], [], timeout)
        try:
            while os.read(self._read_fd, 512):
                pass
        except BlockingIOError:
            pass
        return self.received

    def clear(self) -> None:
        self.received = False
