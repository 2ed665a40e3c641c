"""What the sections of bench/scale/scaling.py share: the transports a client can use, timed
past-tuple requests and their summary, one service log per section, list-valued flags.

Not a public module: scaling.py's sections import it as ``bench.scale.timing``.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import os
import random
import time

from bench.shared import common
from fxis_shm import Client
from fxis_shm.service.launch import ServiceProcess

PATHS = ("network", "local")
LOCAL_OPTION = {"network": "off", "local": "require"}  # Client(local=...) per transport
PAST_NS = 150_000_000  # a past tuple's t* lies this far behind now
MB = 1e6


# ---- list-valued flags -----------------------------------------------------------------------

int_list = common.int_list  # the scaling modules take every list type from this module


def positive_int_list(text: str) -> list[int]:
    values = int_list(text)
    if min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 1, got {text!r}")
    return values


def float_list(text: str) -> list[float]:
    values = [common.positive_float(v) for v in text.split(",") if v.strip()]
    if not values:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers > 0, got {text!r}")
    return values


def size_list(text: str) -> list[tuple[int, int]]:
    sizes = []
    for item in (v.strip() for v in text.split(",") if v.strip()):
        try:
            w, h = (int(x) for x in item.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {item!r}") from None
        if w < 1 or h < 1:
            raise argparse.ArgumentTypeError(f"a size must be at least 1x1, got {item!r}")
        sizes.append((w, h))
    if not sizes:
        raise argparse.ArgumentTypeError("no size given")
    return sizes


name_list = common.name_list


# ---- clients and requests --------------------------------------------------------------------


def local_supported() -> bool:
    """Whether this Client can choose its transport (the local= keyword)."""
    return "local" in inspect.signature(Client.__init__).parameters  # (Client's __new__ takes **kwargs)


def make_client(endpoint: str, timeout: float, path: str) -> Client:
    """A client on transport ``path`` (network or local)."""
    if local_supported():
        return Client(endpoint, timeout=timeout, local=LOCAL_OPTION[path])
    if path != "network":
        raise ValueError("this Client has no local= keyword: only the network path is available")
    return Client(endpoint, timeout=timeout)


def past_tuple(client: Client):
    return client.tuple(at=time.monotonic_ns() - PAST_NS)


def tuple_now(client: Client):
    return client.tuple()


def timed(client: Client, request=past_tuple) -> dict:
    """One request: round trip, the service's own time, the bytes and transport of the reply;
    a failure is recorded with its error, not raised."""
    t_send = time.monotonic_ns()
    try:
        reply = request(client)
    except common.REQUEST_ERRORS as exc:
        return {"t_send": t_send, "rtt_ns": time.monotonic_ns() - t_send, "error": common.describe_error(exc)}
    rtt = time.monotonic_ns() - t_send
    timing = reply.timing or {}
    return {
        "t_send": t_send,
        "rtt_ns": rtt,
        "error": None,
        "service_ns": timing["sent"] - timing["received"] if "sent" in timing and "received" in timing else None,
        "waited_ns": timing["waited"] - timing["received"] if "waited" in timing and "received" in timing else None,
        "bytes": sum(f.image.nbytes for f in reply.values()),
        "frames": len(reply),
        "path": getattr(reply, "path", None),
    }


def time_requests(
    client: Client, n: int, rng: random.Random, sleep_max_ms: float, warmup: int, desc: str, request=past_tuple
) -> list[dict]:
    """``warmup`` unrecorded then ``n`` timed requests, each after a random sleep."""
    for _ in range(warmup):
        timed(client, request)
    records = []
    with common.progress(n, desc) as bar:
        for _ in range(n):
            common.sleep_ms(rng.uniform(0.0, sleep_max_ms))
            records.append(timed(client, request))
            bar.update(1)
    return records


def latency_summary(records: list[dict]) -> dict:
    """Round trip and service time (ms), failures, bytes per reply, transports seen."""
    ok = [r for r in records if r["error"] is None]
    paths = {}
    for r in ok:
        paths[str(r.get("path"))] = paths.get(str(r.get("path")), 0) + 1
    return {
        "requests": len(records),
        "failed": len(records) - len(ok),
        "rtt_ms": common.summary(common.ms(r["rtt_ns"]) for r in ok),
        "service_ms": common.summary(common.ms(r["service_ns"]) for r in ok if r.get("service_ns") is not None),
        "waited": sum(1 for r in ok if (r.get("waited_ns") or 0) > 1_000_000),
        "bytes": max((r["bytes"] for r in ok), default=None),
        "paths": paths,
        "errors": sorted({r["error"] for r in records if r["error"]})[:5],
    }


# ---- services ----------------------------------------------------------------------------------


class Logs:
    """One log file per section; every service of the section appends to it."""

    def __init__(self, out: str):
        self.out = out

    def path(self, section: str) -> str:
        return os.path.join(self.out, f"scaling.{section}.service.log")

    def start(self, section: str) -> None:
        open(self.path(section), "wb").close()

    @contextlib.contextmanager
    def service(self, section: str, run_args: list[str], timeout: float):
        """A launched service (stopped on exit) and its status once every camera streams."""
        with open(self.path(section), "ab") as log:
            log.write(f"==== fxis run {' '.join(run_args)}\n".encode())
            log.flush()
            with ServiceProcess(run_args, stderr=log) as svc, svc.client(timeout=timeout) as client:
                status = common.wait_until_streaming(client, timeout=30.0)
                yield svc, status


def camera_args(n: int, fps: float, width: int, height: int, slots: int) -> list[str]:
    names = [f"cam{j}" for j in range(n)]
    return common.synthetic_camera_flags(names, fps, width, height) + ["--slots", str(slots)]


def measure_paths(args, endpoint: str, rng: random.Random, desc: str) -> dict:
    """-n past tuples per transport of --paths: path -> {summary, records}."""
    out = {}
    for path in usable_paths(args.paths):
        with make_client(endpoint, args.timeout, path) as client:
            records = time_requests(client, args.requests, rng, args.sleep_max_ms, args.warmup, f"{desc} {path}")
        out[path] = {"summary": latency_summary(records), "records": records}
    return out


def usable_paths(paths: list[str]) -> list[str]:
    return [p for p in paths if p == "network" or local_supported()]


def sanity_line(points: list[dict]) -> str:
    """Past tuples should never wait, and each reply should come on the transport asked for."""
    summaries = [(path, m["summary"]) for p in points for path, m in p["paths"].items()]
    waited = sum(s["waited"] for _, s in summaries)
    total = sum(s["requests"] - s["failed"] for _, s in summaries)
    other = sum(n for path, s in summaries for seen, n in s["paths"].items() if seen not in (path, "None"))
    return (
        f"past tuples that waited > 1 ms for a frame: {waited} of {total}; "
        f"replies on another transport than asked: {other}"
    )


# ---- figures -------------------------------------------------------------------------------


def plain_numbers(*axes_of) -> None:
    """Tick labels 2, 10, 64 rather than 2^1, 10^1 on log-scaled axes."""
    from matplotlib import ticker

    for axis in axes_of:
        axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(ticker.NullFormatter())
