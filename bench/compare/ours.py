"""fxis's contenders in bench/compare/peers.py, and the two phases that time them against the others.

tcp phase: one service on tcp loopback; timed interleaved: its tuples over the network path
(local="off"), the same-host client's answers from the rings (local="require": tuple and
latest, each copied or as zero-copy views), the `time` round trip to the coordinator, and
imagezmq, the ZeroMQ floor, mp.Queue and the two copy floors carrying frames taken from the
service once.
ipc phase: the same cameras served on an ipc endpoint: fxis tuple ipc and a plain copy.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import time

import numpy as np

from bench.compare import rivals
from bench.shared import common
from bench.shared.interleave import Contender, hot_loops, time_contenders
from fxis_shm import Client
from fxis_shm.service.launch import ServiceProcess, free_tcp_port

SCENARIOS = {"2x1360x1024": (2, 1360, 1024), "4x1360x1024": (4, 1360, 1024), "2x2048x2048": (2, 2048, 2048)}
FPS = 20.0
PAST_NS = 150_000_000  # t* of a timed tuple lies this far behind now: its frames are stored
SOURCE_TUPLES = 10

TCP, IPC = "fxis tuple tcp", "fxis tuple ipc"
LOCAL, LOCAL_VIEW = "fxis tuple local", "fxis tuple local zero-copy"
LATEST, LATEST_VIEW = "fxis latest local", "fxis latest local zero-copy"
TIME = "fxis time round trip (tcp)"


# ---- fxis's contenders -----------------------------------------------------------------------


def frames_contender(name: str, call, cameras: list[str], path: str, copy: bool = True) -> Contender:
    """``call()`` returns a FrameTuple; checked: the path asked for, every camera, the synthetic
    cameras' pixel stamps, and for zero-copy views that the slots were not overwritten meanwhile."""

    def check(t):
        if t.path != path:
            raise AssertionError(f"the tuple came by the {t.path!r} path, not {path!r} as asked")
        if sorted(t) != sorted(cameras):
            raise AssertionError(f"the tuple holds {sorted(t)}, not {sorted(cameras)}")
        bad = [c for c in cameras if not common.stamp_ok(t[c], "synthetic")]
        if not copy and not t.still_valid():
            raise AssertionError("the views' slots were overwritten before they were checked")
        if bad:
            raise AssertionError(f"pixel stamp does not match frame id for {bad}")
        t.release()

    return Contender(name, call, check)


def past_tuple(client: Client, copy: bool = True):
    return lambda: client.tuple(at=time.monotonic_ns() - PAST_NS, copy=copy)


def time_contender(client: Client) -> Contender:
    """The `time` op: the smallest round trip to the coordinator (no frame in it)."""

    def check(now):
        if not isinstance(now, int):
            raise AssertionError(f"time() returned {now!r}")

    return Contender(TIME, client.time, check)


def local_contenders(client: Client, cameras: list[str]) -> list[Contender]:
    """The same-host client answering from the rings: tuple and latest, copied and as views."""
    return [
        frames_contender(LOCAL, past_tuple(client), cameras, "local"),
        frames_contender(LOCAL_VIEW, past_tuple(client, copy=False), cameras, "local", copy=False),
        frames_contender(LATEST, client.latest, cameras, "local"),
        frames_contender(LATEST_VIEW, lambda: client.latest(copy=False), cameras, "local", copy=False),
    ]


# ---- the services ----------------------------------------------------------------------------


def run_args_of(scenario: str, slots: int) -> tuple[list[str], list[str]]:
    n, width, height = SCENARIOS[scenario]
    names = [f"cam{j}" for j in range(n)]
    return names, common.synthetic_camera_flags(names, FPS, width, height) + ["--slots", str(slots)]


@contextlib.contextmanager
def launched(run_args: list[str], log_path: str, endpoint: str | None = None):
    """A ServiceProcess (stopped on exit) once its cameras stream, and its status then."""
    with open(log_path, "wb") as log, ServiceProcess(run_args, endpoint=endpoint, stderr=log) as svc:
        with svc.client(timeout=2.0) as client:
            status = common.wait_until_streaming(client, min_frames=SOURCE_TUPLES + 6)
        yield svc, status


def take_source(client: Client, cameras: list[str]) -> tuple[list[list[np.ndarray]], list[dict]]:
    """SOURCE_TUPLES consecutive stored tuples, each frame copied into its own array, and
    their frame ids."""
    tuples = client.sequence("consecutive", count=SOURCE_TUPLES, at=time.monotonic_ns() - PAST_NS)
    return (
        [[np.array(t[c].image, copy=True) for c in cameras] for t in tuples],
        [{c: t[c].frame_id for c in cameras} for t in tuples],
    )


# ---- the phases ------------------------------------------------------------------------------


def timed(contenders: list[Contender], args, rng, desc: str) -> None:
    """The interleaved samples with sleeps, then (unless --hot-calls 0) the hot loop."""
    time_contenders(contenders, args.samples, args.warmup, rng, args.sleep_max_ms, desc)
    if args.hot_calls > 0:
        hot_loops(contenders, args.hot_calls, rng, f"{desc}, hot loop")


def tcp_phase(args, scenario: str, rng, out: str) -> tuple[list[Contender], dict, list]:
    """The service on tcp: every contender but ipc, interleaved. Returns the contenders, facts
    about the service and the source (for the ipc phase's control)."""
    cameras, run_args = run_args_of(scenario, args.slots)
    ctx = multiprocessing.get_context("spawn")  # no child inherits a ZeroMQ context
    log = os.path.join(out, f"compare.{scenario}.tcp.service.log")
    with contextlib.ExitStack() as stack:
        svc, status = stack.enter_context(launched(run_args, log))
        net = stack.enter_context(Client(svc.endpoint, timeout=args.timeout, local="off"))
        loc = stack.enter_context(Client(svc.endpoint, timeout=args.timeout, local="require"))
        source, source_ids = take_source(net, cameras)
        hub_address = f"tcp://127.0.0.1:{free_tcp_port()}"
        stack.enter_context(rivals.child(ctx, rivals.hub_main, hub_address))
        requests, replies = ctx.Queue(), ctx.Queue()
        stack.enter_context(rivals.child(ctx, rivals.queue_server_main, source, requests, replies))
        sender = rivals.TimedSender(hub_address, args.timeout)
        stack.callback(sender.close)
        floor_address = f"tcp://127.0.0.1:{free_tcp_port()}"
        stack.enter_context(rivals.child(ctx, rivals.floor_main, floor_address, source))
        contenders = [
            frames_contender(TCP, past_tuple(net), cameras, "network"),
            time_contender(net),
            *local_contenders(loc, cameras),
            *rivals.imagezmq_contenders(sender, source),
            rivals.floor_contender(floor_address, source, args.timeout),
            rivals.queue_contender(rivals.QueueClient(requests, replies, args.timeout), source),
            *rivals.copy_contenders(source),
        ]
        timed(contenders, args, rng, f"{scenario} tcp phase")
        info = {
            "endpoint": svc.endpoint,
            "log": log,
            "run_args": run_args,
            "status": status,
            "source_frame_ids": source_ids,
            "local_client_paths": dict(loc.paths),
        }
        requests.put(None)
    return contenders, info, source


def ipc_phase(args, scenario: str, rng, out: str, source) -> tuple[list[Contender], dict]:
    """The same cameras served on an ipc endpoint: fxis tuple ipc and the plain-copy control."""
    cameras, run_args = run_args_of(scenario, args.slots)
    sock_path = f"/tmp/fxis-compare-{os.getpid()}.sock"
    log = os.path.join(out, f"compare.{scenario}.ipc.service.log")
    try:
        with (
            launched(run_args, log, endpoint=f"ipc://{sock_path}") as (svc, status),
            Client(svc.endpoint, timeout=args.timeout, local="off") as client,
        ):
            contenders = [
                frames_contender(IPC, past_tuple(client), cameras, "network"),
                rivals.copy_contenders(source, rivals.COPY_CONTROL)[0],
            ]
            timed(contenders, args, rng, f"{scenario} ipc phase")
            return contenders, {"endpoint": svc.endpoint, "log": log, "status": status}
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(sock_path)
