"""A process stops on SIGTERM whenever the signal lands (fxis_shm.service.stopsignals): also
while its main thread is inside ``Event.wait``, where a handler that set the event itself
would wait on the event's own lock for ever; and the supervisor's way, with no thread, sees
every signal whether it lands in its wait or between two."""

import os
import select
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.integration

ROUNDS = 200
# Polls stop.wait(0), so that its main thread holds the event's lock most of the time: a
# signal landing there is the case that hangs a handler calling stop.set() (one round in two).
CHILD = f"""
import signal, sys, threading
from fxis_shm.service.stopsignals import stop_on
stop = threading.Event()
stop_on((signal.SIGTERM,), stop)
print("ready", threading.active_count(), flush=True)
for k in range({ROUNDS}):
    while not stop.wait(0):
        pass
    stop.clear()
    print("stopped", k, flush=True)
"""


# The supervisor's loop (StopSignals): no thread, a wait on the wakeup pipe; here polled with no
# timeout, and with a timeout, so that signals land both inside select and between two calls.
WAKER = f"""
import signal, threading
from fxis_shm.service.stopsignals import StopSignals
stops = StopSignals((signal.SIGTERM,))
print("ready", threading.active_count(), flush=True)
for k in range({ROUNDS}):
    while not stops.wait(0.05 if k % 2 else 0):
        pass
    stops.clear()
    print("stopped", k, flush=True)
"""


def read_line(proc: subprocess.Popen, timeout: float) -> str:
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    assert ready, f"no line from the child within {timeout} s"
    return proc.stdout.readline().strip()


@pytest.mark.parametrize("child, threads", [(CHILD, None), (WAKER, "1")], ids=["stop_on", "StopSignals"])
def test_sigterm_stops_a_main_loop_waiting_on_the_event_wherever_it_lands(child, threads):
    proc = subprocess.Popen([sys.executable, "-c", child], stdout=subprocess.PIPE, text=True)
    try:
        first = read_line(proc, 30).split()
        assert first[0] == "ready" and (threads is None or first[1] == threads)
        for k in range(ROUNDS):
            time.sleep((k % 7) * 0.0003)  # the signal lands at ever other points of the loop
            os.kill(proc.pid, signal.SIGTERM)
            assert read_line(proc, 5) == f"stopped {k}"
        assert proc.wait(5) == 0
    finally:
        proc.kill()
        proc.wait()
