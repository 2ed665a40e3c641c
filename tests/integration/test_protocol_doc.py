"""docs/protocol.md's examples against a live service, so the spec and the service cannot drift.

The document marks each JSON example by its fenced block's info string: ``json request`` and
``json event`` (sent to the service), ``json reply`` (the reply to the request or event just
before it) and ``json stream`` (a stream message's header). The service is started with the
``fxis run`` command the document gives. Each request goes over a raw ZeroMQ DEALER socket,
each event over a PUB socket, each stream is subscribed to with a SUB socket; the live reply
must have exactly the documented keys, nested alike, with the same JSON types, and the same
values for the keys that do not vary (``EXACT``). A documented list of rows (lists) may be
shorter than the live one: then every live row must look like the first documented one.

Times in a request (``TIME_FIELDS``) are moved onto the live clock by the amount that takes
the documented reply's ``timing.received`` to the live service's "now", so an example of
"120 ms before the request" stays one; ``local`` becomes this host's boot id.
"""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import zmq

from fxis_shm import read_stamp
from fxis_shm.service.launch import ServiceProcess
from fxis_shm.shm.localpath import boot_id

from .conftest import assert_nothing_left

pytestmark = pytest.mark.integration

DOC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"
ROLES = ("request", "event", "reply", "stream")
EXACT = {
    "v",
    "id",
    "ok",
    "op",
    "clock",
    "code",
    "camera",
    "shape",
    "dtype",
    "sync",
    "delivery",
    "columns",
    "settings",
    "groups",
    "buffer",
    "stream",
}
TIME_FIELDS = ("at", "t_call", "start", "end")
ITEMSIZE = {"uint8": 1, "uint16": 2, "float32": 4}
REPLY_S = 5.0  # seconds a reply may take beyond the wait a request asks for


@dataclass
class Block:
    role: str
    body: object
    line: int
    section: str


def _blocks() -> list[Block]:
    """Every ```json block of the document, with its role, in order."""
    text = DOC.read_text()
    blocks, section = [], "0"
    fence = re.compile(r"^```(\S*)[ \t]*(.*)$")
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        heading = re.match(r"^#{2,3} (\d+(?:\.\d+)?[a-z]?)\.? ", lines[i])
        if heading:
            section = heading.group(1)
        opened = fence.match(lines[i])
        if not opened:
            i += 1
            continue
        end = lines.index("```", i + 1)
        if opened.group(1) == "json":
            role = opened.group(2).strip()
            source = "\n".join(lines[i + 1 : end])
            try:
                body = json.loads(source)
            except ValueError as exc:
                raise AssertionError(f"{DOC.name}:{i + 1}: the json block is not JSON: {exc}") from None
            blocks.append(Block(role, body, i + 1, section))
        i = end + 1
    return blocks


def _pairs() -> list[tuple[Block, Block]]:
    """(request or event, its documented reply), in document order."""
    blocks = _blocks()
    pairs = []
    for first, second in zip(blocks, blocks[1:]):
        if first.role in ("request", "event") and second.role == "reply":
            pairs.append((first, second))
    return pairs


def _id(pair: tuple[Block, Block]) -> str:
    ask = pair[0]
    return f"{ask.section}-{ask.role}-{ask.body.get('op')}-L{ask.line}"


REQUESTS = [p for p in _pairs() if p[0].role == "request"]
EVENTS = [p for p in _pairs() if p[0].role == "event"]
STREAMS = [b for b in _blocks() if b.role == "stream"]


def _service_args() -> list[str]:
    """The arguments of the document's ``fxis run`` command, less those ServiceProcess sets."""
    text = DOC.read_text()
    found = re.search(r"^```sh[^\n]*\n(fxis run [^`]*?)```", text, re.M | re.S)
    assert found, f"{DOC.name} does not show the fxis run command its examples come from"
    words = shlex.split(found.group(1).replace("\\\n", " "))[2:]
    args, given = [], {}
    while words:
        word = words.pop(0)
        if word in ("--name", "--http"):
            given[word] = words.pop(0)
        else:
            args.append(word)
    # ServiceProcess runs without the dashboard, as the document's command must (the status
    # example lists the processes it starts)
    assert given.get("--http") == "off", f"{DOC.name}'s fxis run command must say --http off"
    return args


class Raw:
    """A DEALER socket speaking docs/protocol.md, nothing of fxis_shm."""

    def __init__(self, endpoint: str):
        self.sock = zmq.Context.instance().socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.connect(endpoint)

    def call(self, header: dict, wait_s: float = 0.0) -> tuple[dict, list[bytes]]:
        self.sock.send_multipart([b"", json.dumps(header).encode()])
        deadline = time.monotonic() + REPLY_S + wait_s
        while True:
            left = deadline - time.monotonic()
            assert left > 0 and self.sock.poll(left * 1000), f"no reply to {header} within {REPLY_S + wait_s:.1f} s"
            frames = self.sock.recv_multipart()
            assert frames[0] == b"", f"a DEALER reply must start with the empty delimiter, got {frames[0][:40]!r}"
            reply = json.loads(frames[1])
            if reply.get("id") == header.get("id"):
                return reply, frames[2:]

    def now(self) -> int:
        return self.call({"v": 1, "op": "time", "id": "clock"})[0]["now"]

    def close(self) -> None:
        self.sock.close()


@pytest.fixture(scope="module")
def service():
    svc = ServiceProcess(_service_args(), name=f"docs{os.getpid()}", stderr=open(os.devnull, "w"))
    svc.start()
    raw = Raw(svc.endpoint)
    try:
        deadline = time.monotonic() + 20

        def warm(status: dict) -> bool:
            cams = status["cameras"].values()
            supervisor = status.get("supervisor") or {}
            return all(c["alive"] and c.get("fps") and c["frames_stored"] > c["ring_slots"] + 2 for c in cams) and all(
                p["state"] == "running" for p in supervisor.get("processes", {}).values()
            )

        while not warm(status := raw.call({"v": 1, "op": "status", "id": "warm"})[0]):
            assert time.monotonic() < deadline, f"the service did not fill its rings within 20 s: {status}"
            time.sleep(0.05)
        yield svc, raw
    finally:
        raw.close()
        svc.stop()
        assert_nothing_left(svc.name)


# ---- comparing a live message with the documented one ----


def _json_type(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "number with a fraction"
    if isinstance(value, str):
        return "string"
    return "list" if isinstance(value, list) else "object"


def assert_like(documented, live, path: str) -> None:
    if isinstance(documented, dict):
        assert isinstance(live, dict), f"{path}: documented an object, the service sent {live!r}"
        unsent, undocumented = documented.keys() - live.keys(), live.keys() - documented.keys()
        assert not unsent and not undocumented, (
            f"{path}: documented but not sent: {sorted(unsent)}; sent but not documented: {sorted(undocumented)}"
        )
        for key, value in documented.items():
            if key in EXACT:
                assert live[key] == value, f"{path}.{key}: documented {value!r}, the service sent {live[key]!r}"
            else:
                assert_like(value, live[key], f"{path}.{key}")
    elif isinstance(documented, list):
        assert isinstance(live, list), f"{path}: documented a list, the service sent {live!r}"
        if len(documented) == len(live):
            for i, (d, v) in enumerate(zip(documented, live)):
                assert_like(d, v, f"{path}[{i}]")
        else:
            rows = documented and live and all(isinstance(d, list) for d in documented)
            assert rows, f"{path}: documented {len(documented)} items, the service sent {len(live)}: {live!r}"
            for i, v in enumerate(live):
                assert_like(documented[0], v, f"{path}[{i}]")
    else:
        assert _json_type(documented) == _json_type(live), (
            f"{path}: documented as {_json_type(documented)} ({documented!r}), the service sent {live!r}"
        )


def stamp_as_documented(buf: bytes, shape: list[int], dtype: str) -> int | None:
    """The frame id of docs/protocol.md section 17's byte stamp, read as it says."""
    row_bytes = math.prod(shape[1:]) * ITEMSIZE[dtype]
    last = (shape[0] - 1) * row_bytes
    ident, inverse = int.from_bytes(buf[0:8], "little"), int.from_bytes(buf[8:16], "little")
    if buf[0:16] != buf[last : last + 16] or inverse != ident ^ (2**64 - 1):
        return None
    return ident


def assert_buffers(reply: dict, buffers: list[bytes], where: str) -> None:
    """One raw buffer per frame with a ``buffer`` index, of the documented size and stamp."""
    metas = [m for m in reply.get("frames", []) if isinstance(m, dict) and "buffer" in m]
    assert sorted(m["buffer"] for m in metas) == list(range(len(buffers))), (
        f"{where}: buffer indices {[m['buffer'] for m in metas]} for {len(buffers)} buffer frames"
    )
    for meta in metas:
        buf = buffers[meta["buffer"]]
        assert len(buf) == math.prod(meta["shape"]) * ITEMSIZE[meta["dtype"]], f"{where}: {meta} got {len(buf)} bytes"
        stamp = stamp_as_documented(buf, meta["shape"], meta["dtype"])
        assert stamp == meta["frame_id"], f"{where}: the pixels of {meta} carry the stamp {stamp}"
        image = np.frombuffer(buf, np.dtype(meta["dtype"]).newbyteorder("<")).reshape(meta["shape"])
        assert read_stamp(image) == stamp, f"{where}: read_stamp disagrees with section 17"


def _moved(ask: dict, documented_reply: dict, live_now: int) -> dict:
    """The documented request with its times moved onto the live clock, and our boot id."""
    ask = dict(ask)
    received = (documented_reply.get("timing") or {}).get("received")
    if received is not None:
        for field in TIME_FIELDS:
            if isinstance(ask.get(field), int):
                ask[field] += live_now - received
    if "local" in ask:
        ask["local"] = boot_id()
    return ask


def _wait_s(ask: dict, live_now: int) -> float:
    future = max((ask[f] - live_now for f in ("at", "end") if isinstance(ask.get(f), int)), default=0)
    return max(0, future) / 1e9 + ask.get("timeout_ms", 1000) / 1e3


# ---- the document's shape ----


def test_every_json_example_is_marked_and_paired():
    blocks = _blocks()
    assert len(blocks) >= 20, f"{DOC.name} has only {len(blocks)} json examples"
    for block in blocks:
        assert block.role in ROLES, (
            f"{DOC.name}:{block.line}: a json block must say what it is (```json request|event|reply|stream),"
            f" not {block.role!r}"
        )
    for before, block in zip([None, *blocks], blocks):
        if block.role == "reply":
            assert before is not None and before.role in ("request", "event"), (
                f"{DOC.name}:{block.line}: a reply example must follow its request or event"
            )
    for block, after in zip(blocks, [*blocks[1:], None]):
        if block.role in ("request", "event"):
            assert after is not None and after.role == "reply", f"{DOC.name}:{block.line}: its reply is not shown"
    documented_ops = {p[0].body["op"] for p in REQUESTS}
    assert documented_ops >= {"time", "status", "image", "tuple", "latest", "frames", "sequence"}


def test_the_documented_ops_are_the_services(service):
    """Section 5's op row and section 7's table name exactly the ops UNKNOWN_OP lists."""
    _, raw = service
    reply, _ = raw.call({"v": 1, "op": "no-such-op", "id": "ops"})
    assert reply["error"]["code"] == "UNKNOWN_OP"
    known = set(re.findall(r"'([a-z_]+)'", reply["error"]["message"].split("known:", 1)[1]))
    text = DOC.read_text()
    op_row = re.search(r"^\| `op` \| string \|.*$", text, re.M)
    assert op_row, "section 5 has no row for the field op"
    assert set(re.findall(r"`([a-z_]+)`", op_row.group(0))) - {"op"} == known, op_row.group(0)
    table = set(re.findall(r"^\| `([a-z_]+)` \(\[7\.", text, re.M))
    assert table == known, f"section 7's table lists {sorted(table)}, the service knows {sorted(known)}"


# ---- requests, events and streams ----


@pytest.mark.parametrize("pair", REQUESTS, ids=[_id(p) for p in REQUESTS])
def test_request_example(service, pair):
    svc, raw = service
    ask, documented = pair
    live_now = raw.now()
    request = _moved(ask.body, documented.body, live_now)
    reply, buffers = raw.call(request, _wait_s(request, live_now))
    where = f"{DOC.name}:{documented.line}"
    assert_like(documented.body, reply, where)
    assert_buffers(reply, buffers, where)
    if reply.get("delivery") == "local":  # instance: a uint64 as a decimal string, the ring's own
        status, _ = raw.call({"v": 1, "op": "status", "id": "instance"})
        for meta in reply["frames"]:
            assert re.fullmatch(r"[0-9]+", meta["instance"]) and int(meta["instance"]) < 2**64, meta
            assert meta["instance"] == status["cameras"][meta["camera"]]["instance"], meta


@pytest.mark.parametrize("pair", EVENTS, ids=[_id(p) for p in EVENTS])
def test_event_example(service, pair):
    svc, raw = service
    ask, documented = pair
    topic = ask.body["reply_topic"].encode()
    ctx = zmq.Context.instance()
    sub, pub = ctx.socket(zmq.SUB), ctx.socket(zmq.PUB)
    try:
        for sock in (sub, pub):
            sock.setsockopt(zmq.LINGER, 0)
        sub.connect(svc.pub)
        sub.setsockopt(zmq.SUBSCRIBE, topic)
        pub.connect(svc.events)
        deadline = time.monotonic() + 10  # PUB/SUB connect asynchronously: the handshake of section 15
        hello = json.dumps({"v": 1, "op": "time", "id": "hello", "reply_topic": topic.decode()}).encode()
        while True:
            pub.send_multipart([b"fxis.request", hello])
            if sub.poll(100):
                break
            assert time.monotonic() < deadline, "no answer to a time event within 10 s"
        live_now = raw.now()
        event = _moved(ask.body, documented.body, live_now)
        pub.send_multipart([b"fxis.request", json.dumps(event).encode()])
        deadline = time.monotonic() + REPLY_S + _wait_s(event, live_now)
        while True:
            left = deadline - time.monotonic()
            assert left > 0 and sub.poll(left * 1000), f"no answer to the event {event}"
            frames = sub.recv_multipart()
            assert frames[0] == topic, f"an answer on topic {frames[0]!r}"
            reply = json.loads(frames[1])
            if reply.get("id") == event["id"]:
                break
    finally:
        sub.close()
        pub.close()
    where = f"{DOC.name}:{documented.line}"
    assert_like(documented.body, reply, where)
    assert_buffers(reply, frames[2:], where)


@pytest.mark.parametrize("block", STREAMS, ids=[f"{b.body['stream']}-L{b.line}" for b in STREAMS])
def test_stream_example(service, block):
    svc, _ = service
    topic = (block.body["stream"] + "|").encode()
    sub = zmq.Context.instance().socket(zmq.SUB)
    try:
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(svc.pub)
        sub.setsockopt(zmq.SUBSCRIBE, topic)
        assert sub.poll(10_000), f"nothing on the stream {topic!r} within 10 s"
        frames = sub.recv_multipart()
    finally:
        sub.close()
    assert frames[0] == topic
    where = f"{DOC.name}:{block.line}"
    assert_like(block.body, json.loads(frames[1]), where)
    assert_buffers(json.loads(frames[1]), frames[2:], where)
