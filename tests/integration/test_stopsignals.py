"""A process stops on SIGTERM whenever the signal lands (fxis_shm.service.stopsignals): also
while its main thread is inside ``Event.wait``, where a handler that set the event itself
would wait on the event's own lock for ever."""

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
print("ready", flush=True)
for k in range({ROUNDS}):
    while not stop.wait(0):
        pass
    stop.clear()
    print("stopped", k, flush=True)
"""


def read_line(proc: subprocess.Popen, timeout: float) -> str:
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    assert ready, f"no line from the child within {timeout} s"
    return proc.stdout.readline().strip()


def test_sigterm_stops_a_main_loop_waiting_on_the_event_wherever_it_lands():
    proc = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    try:
        assert read_line(proc, 30) == "ready"
        for k in range(ROUNDS):
            time.sleep((k % 7) * 0.0003)  # the signal lands at ever other points of the loop
            os.kill(proc.pid, signal.SIGTERM)
            assert read_line(proc, 5) == f"stopped {k}"
        assert proc.wait(5) == 0
    finally:
        proc.kill()
        proc.wait()
