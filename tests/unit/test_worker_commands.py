"""The camera worker's command inbox (fxis_shm.workers.commands) over its real ipc socket: at
most INBOX_LIMIT commands wait (beyond: BUSY at once), and the capture loop applies one a
call of serve_pending, skipping those whose deadline passed."""

import json
import os
import shutil
import threading

import pytest
import zmq

from fxis_shm.core import timebase
from fxis_shm.shm import naming
from fxis_shm.wire import commands
from fxis_shm.workers.commands import INBOX_LIMIT, CommandServer, serve_pending

from ..conftest import wait_until


@pytest.fixture
def server():
    service = f"cmdtest{os.getpid()}"
    served = CommandServer(service, "cam", threading.Event())
    ctx = zmq.Context()
    dealer = ctx.socket(zmq.DEALER)
    dealer.setsockopt(zmq.LINGER, 0)
    dealer.connect(served.endpoint)
    try:
        yield served, dealer
    finally:
        dealer.close()
        ctx.term()
        served.close()
        shutil.rmtree(naming.commands_dir(service), ignore_errors=True)


def _send(dealer, command_id: int, deadline: int | None = None) -> None:
    fields = {"deadline": deadline} if deadline is not None else {}
    dealer.send_multipart([b"", commands.encode_command(command_id, commands.SETTINGS, set={"gain": 1}, **fields)])


def _replies(dealer, count: int) -> list[dict]:
    replies = []
    while len(replies) < count:
        assert dealer.poll(5000), f"{len(replies)} of {count} replies"
        replies.append(json.loads(dealer.recv_multipart()[-1]))
    return replies


def test_beyond_the_limit_a_command_is_busy_and_one_is_applied_a_call(server):
    served, dealer = server
    for i in range(INBOX_LIMIT + 4):
        _send(dealer, i)
    busy = _replies(dealer, 4)  # answered by the worker's thread while the loop takes none
    assert [r["id"] for r in busy] == list(range(INBOX_LIMIT, INBOX_LIMIT + 4))
    assert all(r["code"] == "BUSY" and "applies one a frame" in r["error"] for r in busy)
    applied = []
    serve_pending(served, lambda command: applied.append(command.body["id"]) or {"gain": 1.0})
    assert applied == [0] and _replies(dealer, 1)[0] == {"id": 0, "ok": True, "result": {"gain": 1.0}}
    for _ in range(INBOX_LIMIT):  # one more call than commands waiting
        serve_pending(served, lambda command: applied.append(command.body["id"]) or {})
    assert applied == list(range(INBOX_LIMIT))
    assert [r["id"] for r in _replies(dealer, INBOX_LIMIT - 1)] == list(range(1, INBOX_LIMIT))


def test_a_command_past_its_deadline_is_dropped_and_the_next_applied(server):
    served, dealer = server
    _send(dealer, 1, deadline=timebase.now() - 1)
    _send(dealer, 2, deadline=timebase.now() + 10**10)
    applied = []
    wait_until(lambda: served._inbox.qsize() == 2, what="both commands waiting")
    serve_pending(served, lambda command: applied.append(command.body["id"]) or {})
    assert applied == [2] and _replies(dealer, 1)[0]["id"] == 2
