"""Ctrl-C while the client waits for a reply or a message ends the wait at once, even when the
signal is not delivered into the wait itself.

A signal that lands just before a blocking receive (or in another thread) does not interrupt
it: Python's C handler only flags it, and the handler runs when the receive returns. With one
long receive `fxis status` ignored a SIGINT for its whole timeout (make test run 29:
test_cli_errors' Ctrl-C test, 1 time in some thousands). Here the signal is delivered to
another thread of the process while the main thread sleeps in ZeroMQ's poll, which makes that
case certain: the wait must end within a slice, not at the timeout."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.integration

# The main thread waits on a silent peer with a 60 s timeout; a second thread waits until
# the main one sleeps in poll/ppoll, then sends SIGINT to itself (not to the main thread).
PROGRAM = """
import os, signal, socket, sys, threading, time
from fxis_shm.client.pubsub import Subscriber
from fxis_shm.client.single import SingleClient

POLLS = {"x86_64": ("7", "271"), "aarch64": ("73",)}[os.uname().machine]
listener = socket.socket()
listener.bind(("127.0.0.1", 0))
listener.listen(1)
endpoint = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
main = threading.get_native_id()
waiting = threading.Event()

def interrupt_when_waiting():
    waiting.wait()
    while True:
        with open(f"/proc/self/task/{main}/syscall") as f:
            if f.read().split()[0] in POLLS:
                break
    signal.pthread_kill(threading.get_ident(), signal.SIGINT)

threading.Thread(target=interrupt_when_waiting, daemon=True).start()
if sys.argv[1] == "reply":
    client = SingleClient(endpoint, timeout=60.0)
    waiting.set()
    wait = client.status
else:
    subscriber = Subscriber(endpoint, timeout=60.0)
    subscriber.topic("frames/cam0|")
    waiting.set()
    wait = subscriber.receive
try:
    wait()
except KeyboardInterrupt:
    print("interrupted")
"""


@pytest.mark.skipif(os.uname().machine not in ("x86_64", "aarch64"), reason="poll's syscall numbers known here")
@pytest.mark.parametrize("wait", ["reply", "message"])
def test_a_signal_flagged_outside_the_wait_still_ends_it(wait):
    try:
        done = subprocess.run(
            [sys.executable, "-c", PROGRAM, wait],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
            # Ctrl-C's default, as a terminal's foreground command has it: a suite started in the
            # background has SIGINT ignored, a child inherits that, and Python then keeps ignoring
            # it (make test run 42: both cases held it 30 s; test_cli_errors does the same)
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"the wait for a {wait} held Ctrl-C for 30 s (its timeout is 60 s)")
    assert done.stdout.strip() == "interrupted", done.stderr
