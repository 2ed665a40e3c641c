"""No client can starve a camera through ``settings`` (issue 42, finding 4): reads are answered
by the coordinator from the worker's last report, changes wait at most 8 a camera (beyond:
BUSY) and the worker applies one between two frames; the flooder's refusals are logged once an
interval with a count. Real service, real sockets; bench/endurance/settings_flood.py measures
the good client's latency beside the flood."""

import json
import os
import signal
import time

import pytest
import zmq

from bench.endurance.settings_flood import Flooder, good_client
from fxis_shm.errors import Code
from fxis_shm.wire import protocol

from ..conftest import wait_until
from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration


def test_a_settings_flood_costs_the_flooder_not_the_frames(start_service, tmp_path):
    began = time.monotonic()
    svc = start_service("--camera", f"a=synthetic:fps=20,{SMALL}", "--camera", f"b=synthetic:fps=20,{SMALL}")
    with svc.client(timeout=5) as client:
        wait_until(lambda: client.status()["cameras"]["a"]["frames_stored"] >= 3, what="camera a streaming")
        stored = client.status()["cameras"]["a"]["frames_stored"]
        flooder = Flooder(svc.endpoint, "a")
        flooder.start()
        try:
            wait_until(lambda: flooder.replies[Code.BUSY] and flooder.replies["ok"], what="BUSY and answers")
            good = good_client(svc.endpoint, "a", seconds=3.0, interval_s=0.05)
        finally:
            flooder.stop.set()
            flooder.join()
        assert good["errors"] == {} and good["ms"], good["errors"]  # no CAMERA_DOWN, nor anything else
        assert flooder.replies[Code.BUSY] > 0 and flooder.replies["ok"] > 0, flooder.replies
        assert set(flooder.replies) <= {"ok", Code.BUSY, "unanswered"}, flooder.replies
        status = client.status()["cameras"]["a"]
        assert status["alive"] and status["frames_stored"] > stored
        assert client.settings("a")["values"]["gain"] in (1.0, 2.0)  # its changes were applied
    svc.stop()
    intervals = int((time.monotonic() - began) // 10) + 1  # the log's counting interval is 10 s
    log = (tmp_path / "service0.log").read_text()
    busy_lines = [line for line in log.splitlines() if "changes waiting for its worker" in line]
    assert 1 <= len(busy_lines) <= 2 * intervals, busy_lines  # thousands of BUSY, a line an interval


def test_a_read_is_answered_while_the_worker_is_busy_with_a_change(start_service):
    """The camera's worker stopped (SIGSTOP) with a change waiting for it: a read sent after
    the change is answered first, from what the worker last reported."""
    svc = start_service("--camera", f"a=synthetic:fps=20,{SMALL}")
    with svc.client(timeout=5) as client:
        generation = client.settings("a")["generation"]
        (pid,) = child_pids(svc, "camera")
        ctx = zmq.Context()
        sock = ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(svc.endpoint)
        os.kill(pid, signal.SIGSTOP)
        try:
            sock.send_multipart([b"", *protocol.encode_request("settings", id=1, camera="a", set={"gain": 5})])
            sock.send_multipart([b"", *protocol.encode_request("settings", id=2, camera="a")])
            assert sock.poll(5000), "no answer to the read"
            first = json.loads(sock.recv_multipart()[1])
        finally:
            os.kill(pid, signal.SIGCONT)
        assert first["id"] == 2 and first["ok"], first
        assert first["values"]["gain"] == 0.0 and first["generation"] == generation  # before the change
        assert sock.poll(15000), "no answer to the change"
        second = json.loads(sock.recv_multipart()[1])
        assert second["id"] == 1 and second["ok"] and second["changed"] == {"gain": 5.0}, second
        sock.close()
        ctx.term()
        assert client.settings("a")["values"]["gain"] == 5.0  # the report of the change, kept
