"""A client flooding ``settings`` beside a good client (issue 42, finding 4).

Launches a service (2 synthetic cameras, 20 fps, 640x480). A good client asks camera a's
``latest`` every --interval-ms over the network path (no shared memory), for --seconds in each
phase: without a flood; beside the issue's flood (a client sending ``set: {gain: 1}`` in a
loop, each after the answer to the last); and beside a pipelined flood (a DEALER keeping
--depth settings requests in flight on camera a, changes of gain to 1 and 2 by turns and reads
alternating, as fast as the service answers). Each flooder is a process of its own. Prints the
good client's ``latest`` p50/p99 and its CAMERA_DOWN count per phase, what the flooder's
requests got (ok, BUSY, other: mostly replies the service dropped because the flooder did not
read them fast enough), camera a's frames stored and dropped, the host's load, and the target:
p99 beside each flood within 2x of p99 without. Writes settings_flood.json.
"""

from __future__ import annotations

import collections
import json
import multiprocessing
import os
import sys
import threading
import time

import zmq

if not __package__:  # run as a script (python bench/endurance/settings_flood.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import Client, FxisError
from fxis_shm.errors import Code
from fxis_shm.service.launch import ServiceProcess
from fxis_shm.wire import protocol

TARGET_RATIO = 2.0  # the flood's p99 against the quiet one's (issue 42, "What to build" 3)


class Flooder(threading.Thread):
    """Keeps ``depth`` settings requests on ``camera`` in flight until ``stop`` is set, then
    collects the answers still due (for at most ``drain_s``: a reply the service dropped
    because this client's queue was full never comes); ``replies`` counts them by ok or
    error code, and "unanswered"."""

    def __init__(self, endpoint: str, camera: str, depth: int = 64, mixed: bool = True, drain_s: float = 2.0):
        """``mixed``: changes (gain 1 and 2 by turns) and reads alternating; else ``set:
        {gain: 1}`` each time (issue 42's flood, with ``depth`` 1)."""
        super().__init__(daemon=True, name="flooder")
        self.endpoint, self.camera, self.depth, self.drain_s = endpoint, camera, depth, drain_s
        self.mixed = mixed
        self.stop = threading.Event()
        self.replies: collections.Counter[str] = collections.Counter()
        self.sent = 0

    def _request(self) -> list[bytes]:
        n = self.sent
        if not self.mixed:
            return protocol.encode_request("settings", id=n, camera=self.camera, set={"gain": 1})
        change = {"set": {"gain": 1 + n // 2 % 2}} if n % 2 == 0 else {}
        return protocol.encode_request("settings", id=n, camera=self.camera, **change)

    def run(self) -> None:
        ctx = zmq.Context()
        sock = ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(self.endpoint)
        try:
            while not self.stop.is_set():
                while self.sent - sum(self.replies.values()) < self.depth:
                    sock.send_multipart([b"", *self._request()])
                    self.sent += 1
                if sock.poll(100):
                    self._receive(sock)
            deadline = time.monotonic() + self.drain_s
            while self.sent > sum(self.replies.values()) and time.monotonic() < deadline:
                if sock.poll(100):
                    self._receive(sock)
            self.replies["unanswered"] = self.sent - sum(self.replies.values())
        finally:
            sock.close()
            ctx.term()

    def _receive(self, sock: zmq.Socket) -> None:
        while sock.poll(0):
            header = json.loads(sock.recv_multipart()[1])
            self.replies["ok" if header["ok"] else header["error"]["code"]] += 1


def _flood_in_a_process(endpoint: str, camera: str, depth: int, mixed: bool, stop, results) -> None:
    """A Flooder in a process of its own (a thread beside the good client would take its
    interpreter's lock from it, and the bench would measure that), until ``stop`` is set."""
    flooder = Flooder(endpoint, camera, depth, mixed)
    flooder.start()
    stop.wait()
    flooder.stop.set()
    flooder.join()
    results.put(dict(flooder.replies))


def good_client(endpoint: str, camera: str, seconds: float, interval_s: float) -> dict:
    """``latest`` of ``camera`` every ``interval_s`` for ``seconds`` over the network path:
    each call's ms, and the errors by code (CAMERA_DOWN among them)."""
    took, errors = [], collections.Counter()
    with Client(endpoint, timeout=10, local="off") as client:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            began = time.perf_counter()
            try:
                client.latest([camera])
                took.append((time.perf_counter() - began) * 1e3)
            except FxisError as exc:
                errors[getattr(exc, "code", None) or type(exc).__name__] += 1
            time.sleep(max(0.0, interval_s - (time.perf_counter() - began)))
    return {"ms": took, "errors": dict(errors)}


def _frames(client: Client, camera: str) -> tuple[int, int]:
    info = client.status()["cameras"][camera]
    return info["frames_stored"], info["frames_dropped"]


# phase -> the flooder's (depth, mixed), None: no flood
PHASES = {"no flood": None, "issue's loop": (1, False), "pipelined": (None, True)}


def phase(svc: ServiceProcess, client: Client, args, name: str) -> dict:
    spawn = multiprocessing.get_context("spawn")
    stop, results = spawn.Event(), spawn.Queue()
    flooder = None
    if PHASES[name] is not None:
        depth, mixed = PHASES[name]
        flood = (svc.endpoint, "a", depth or args.depth, mixed, stop, results)
        flooder = spawn.Process(target=_flood_in_a_process, args=flood)
    stored, dropped = _frames(client, "a")
    load = os.getloadavg()[0]
    if flooder is not None:
        flooder.start()
        time.sleep(1.0)  # the flood under way
    good = good_client(svc.endpoint, "a", args.seconds, args.interval_ms / 1e3)
    replies = None
    if flooder is not None:
        stop.set()
        replies = results.get(timeout=60)
        flooder.join()
    after = _frames(client, "a")
    return {
        **good,
        "flooder": replies,
        "frames_stored": after[0] - stored,
        "frames_dropped": after[1] - dropped,
        "load": round(max(load, os.getloadavg()[0]), 1),
    }


def main(argv: list[str] | None = None) -> int:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--seconds", type=common.positive_float, default=8.0, help="of each phase")
    p.add_argument("--interval-ms", type=common.positive_float, default=50.0, help="between the good client's calls")
    p.add_argument("--depth", type=common.positive_int, default=64, help="the flooder's requests in flight")
    p.add_argument("--out", default=common.DEFAULT_OUT)
    args = p.parse_args(argv)
    out = common.ensure_dir(args.out)
    flags = common.synthetic_camera_flags(["a", "b"], 20.0, 640, 480)
    with (
        open(os.path.join(out, "settings_flood.service.log"), "wb") as log,
        ServiceProcess(flags, stderr=log) as svc,
        svc.client(timeout=5) as client,
    ):
        common.wait_until_streaming(client)
        results = {name: phase(svc, client, args, name) for name in PHASES}
    rows = []
    for name, r in results.items():
        s = common.summary(r["ms"])
        replies = r["flooder"] or {}
        rows.append(
            [
                name,
                s["n"],
                s["median"],
                s["p99"],
                r["errors"].get(Code.CAMERA_DOWN, 0),
                sum(n for code, n in r["errors"].items() if code != Code.CAMERA_DOWN),
                replies.get("ok", "-"),
                replies.get(Code.BUSY, "-"),
                sum(n for code, n in replies.items() if code not in ("ok", Code.BUSY)) if replies else "-",
                r["frames_stored"],
                r["frames_dropped"],
                r["load"],
            ]
        )
    header = ["phase", "latest n", "p50 ms", "p99 ms", "CAMERA_DOWN", "other errors"]
    header += ["flooder ok", "flooder BUSY", "flooder other", "a stored", "a dropped", "load"]
    print(common.table(header, rows, digits=2, title=f"the good client's latest('a') every {args.interval_ms:g} ms"))
    quiet = common.summary(results["no flood"]["ms"])["p99"]
    ratios = {}
    for name in [n for n, flood in PHASES.items() if flood is not None]:
        flooded = common.summary(results[name]["ms"])["p99"]
        ratios[name] = ratio = flooded / quiet if quiet and flooded else None
        passed = None if ratio is None else ratio <= TARGET_RATIO and not results[name]["errors"]
        print(
            f"target ({name}): p99 beside the flood within {TARGET_RATIO:g}x of without, no CAMERA_DOWN: "
            f"{common.fmt(ratio)}x {common.verdict(passed)}"
        )
    common.write_json(
        os.path.join(out, "settings_flood.json"),
        {"results": results, "ratios": ratios, "host": common.host_info(), "code": common.code_version()},
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
