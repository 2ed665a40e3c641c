"""The restart limit counts the crashes of a recent window (issue 42, finding 6): with
``--restart-limit 1 --restart-window 6`` a camera worker killed, then killed again after the
window, is restarted both times (it used to be left down at the second); a third crash within
the window of the second leaves it down. The decision itself is tests/unit/test_restarts.py's."""

import json
import os
import signal
import time

import pytest

from fxis_shm.shm import naming

from .conftest import SMALL

pytestmark = pytest.mark.integration

WINDOW_S = 6


def supervisor_state(svc) -> dict:
    with open(naming.supervisor_state_path(svc.name)) as f:
        return json.load(f)


def camera_a(svc) -> dict:
    return supervisor_state(svc)["processes"]["camera:a"]


def crash_times_ns(svc) -> list[int]:
    """When the supervisor saw camera a exit (its clock: CLOCK_MONOTONIC, this process's too)."""
    events = supervisor_state(svc)["events"]
    return [e["t"] for e in events if e["process"] == "camera:a" and e["what"].startswith("exited")]


def kill_camera_a(svc, wait) -> None:
    """kill -9 of camera a's running worker, once the supervisor saw it exit."""
    before = len(crash_times_ns(svc))
    pid = wait(lambda: camera_a(svc)["state"] == "running" and camera_a(svc)["pid"], what="camera a running")
    os.kill(pid, signal.SIGKILL)
    wait(lambda: len(crash_times_ns(svc)) > before, what="the supervisor to see camera a exit")


def test_a_crash_after_a_quiet_window_is_restarted_and_a_crash_loop_is_left_down(start_service, wait):
    svc = start_service(
        "--camera", f"a=synthetic:fps=50,{SMALL}", "--restart-limit", "1", "--restart-window", str(WINDOW_S)
    )
    kill_camera_a(svc, wait)
    wait(lambda: camera_a(svc)["restarts"] == 1 and camera_a(svc)["state"] == "running", what="the first restart")
    first = crash_times_ns(svc)[-1]
    # the first crash leaves the window: a condition on the clock, not a guess at a duration
    wait(lambda: time.monotonic_ns() > first + WINDOW_S * 10**9, timeout=WINDOW_S + 5, what="the window to pass")
    kill_camera_a(svc, wait)
    wait(lambda: camera_a(svc)["restarts"] == 2 and camera_a(svc)["state"] == "running", timeout=20, what="restart 2")
    kill_camera_a(svc, wait)  # within the window of the second: two crashes there, one restart allowed
    second, third = crash_times_ns(svc)[-2:]
    assert third - second < WINDOW_S * 10**9, "the third crash came too late to test the limit"
    state = wait(lambda: (a := camera_a(svc))["state"] == "given up" and a, what="camera a left down")
    assert state["restarts"] == 2
    with svc.client() as client:
        assert not client.status()["cameras"]["a"]["alive"]
