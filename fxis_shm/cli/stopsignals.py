"""SIGTERM as Ctrl-C, for the commands that keep what they did when stopped (``snapshot``,
``record``, ``grab``): both raise KeyboardInterrupt naming the signal (its argument), so that
one ``except KeyboardInterrupt`` closes the bag or the files and the command exits 130
(exitcodes.INTERRUPTED) saying what it kept. Without it SIGTERM would end the process
where it stood, leaving a bag without its end."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

from fxis_shm.cli import exitcodes

SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _raise(signum: int, frame) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def as_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM raise KeyboardInterrupt("SIGINT" / "SIGTERM") while inside."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _raise) for sig in SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def interrupted(command: str, words: str) -> int:
    """The one line an interrupted command ends on (stderr), and its exit code."""
    print(f"fxis {command}: {words}", file=sys.stderr)
    return exitcodes.INTERRUPTED
